//! Experiments: manual measurements behind the design choices, kept runnable. Every test here is
//! `#[ignore]`d; those on trained checkpoints do nothing unless their inputs are named in the
//! environment (the toy sweeps need none):
//!
//! - `FRMD_CKPT`: a checkpoint directory (teacher, student or DP, as the experiment says);
//! - `FRMD_DATA`: the demonstrations it was trained on;
//! - `FRMD_TASK`, `FRMD_STEPS`, `FRMD_SOLVER`, `FRMD_SEED`, `FRMD_EPISODE`, `FRMD_GOAL_DIMS`: as
//!   each experiment documents.
//!
//! Run one with its measurements printed, e.g.
//! `FRMD_CKPT=runs/reach/dp FRMD_DATA=reach.safetensors cargo test -p frmd-host --test experiments
//! start_travel -- --ignored --nocapture`. What they found is logged in `docs/experiments.md`.
#![allow(clippy::needless_range_loop)]

mod dp_baseline;
mod float_policy;
mod toy_sweeps;

/// What the experiments share.
mod prelude {
    pub use candle_core::Device;
    pub use frmd_host::diffusion::samplers::{gaussian, Solver};
    pub use frmd_host::models::{Condition, OwnedNetwork};
    pub use frmd_host::policy::float::FloatPolicy;
    pub use frmd_host::tasks::{Policy, PolicyInput};
    pub use std::path::Path;

    /// The checkpoint directory and demonstrations named by `FRMD_CKPT` and `FRMD_DATA`; `None`
    /// (the experiment does nothing) when either variable is unset.
    pub fn diagnostic_inputs() -> Option<(String, frmd_host::data::Dataset)> {
        let (Ok(ckpt), Ok(data)) = (std::env::var("FRMD_CKPT"), std::env::var("FRMD_DATA")) else {
            return None;
        };
        let dataset = frmd_host::data::Dataset::load(Path::new(&data)).unwrap();
        Some((ckpt, dataset))
    }
}
