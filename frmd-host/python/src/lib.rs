//! The `frmd` Python module (built by maturin with the `python` feature; see `pyproject.toml`):
//! an FRMD policy (int8 blob, baked export or float checkpoint) called in process, with the
//! loader, session rules and chunks of `frmd serve` ([`frmd_host::serve::LocalPolicy`]).
//!
//! - `frmd.Policy.load(path, ...)`; `reset(seed, init_action=None)`; `act(obs, executed=None)`
//!   returns a `(horizon, action_dim)` float64 array;
//! - `frmd.Policy.load(path, batch=n)`: `n` independent episodes for vectorized environments,
//!   `reset_batch(seeds)`, `act_batch(obs)` on `(n, obs_history, obs_dim)`;
//! - the HELLO_OK fields as attributes; every error a `frmd.FrmdError` (or `ValueError` for a
//!   wrongly shaped array) with the Rust message. `act` releases the GIL.
#[cfg(feature = "python")]
mod python;
