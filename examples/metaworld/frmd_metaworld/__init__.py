"""FRMD on MetaWorld: expert demonstrations in FRMD's dataset format and closed-loop evaluation of
policies served over the `frmd serve` protocol (docs/serve-protocol.md). The simulator-independent
client side is the shared package `frmd_client` (examples/frmd_client), which setup.sh installs;
a venv made before it existed finds it beside this package."""
import os as _os
import sys as _sys

try:
    import frmd_client as _frmd_client  # noqa: F401
except ImportError:
    _shared = _os.path.join(_os.path.dirname(_os.path.dirname(_os.path.dirname(_os.path.abspath(__file__)))),
                            "frmd_client")
    if not _os.path.isdir(_os.path.join(_shared, "frmd_client")):
        raise ImportError(f"frmd_metaworld needs the shared package frmd_client, expected at {_shared}; "
                          "run examples/metaworld/setup.sh") from None
    _sys.path.insert(0, _shared)
