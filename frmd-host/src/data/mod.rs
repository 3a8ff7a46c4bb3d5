//! Demonstration datasets: the safetensors format of docs/design.md section 4, validation, training
//! windows and [-1, 1] normalization.
pub mod collect;
pub(crate) mod dataset;
pub mod lerobot;
pub(crate) mod perturb;
pub mod policy_rollouts;
pub mod toy;
pub(crate) mod windows;

#[cfg(test)]
mod tests;

pub use dataset::{ActionBeforeStart, Dataset};
pub use windows::{Normalization, Normalizer, WindowSet};
