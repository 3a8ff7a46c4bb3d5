"""FRMD on MetaWorld: expert demonstrations in FRMD's dataset format and closed-loop evaluation of
policies served over the `frmd serve` protocol (docs/serve-protocol.md)."""
