//! Forward passes of the firmware networks over borrowed (typically `&'static` baked) weights.

pub mod mlp;

#[cfg(test)]
mod mlp_tests;
