//! Forward passes of the firmware networks over borrowed (typically `&'static` baked) weights.

pub mod mlp;
pub mod transformer;

#[cfg(test)]
mod mlp_tests;
