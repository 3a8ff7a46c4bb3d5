//! Deterministic synthetic networks with the firmware's shapes (std): generated from
//! `frmd_core::rng::Rng` and quantized the way the exporter quantizes, so that cost, memory and
//! host/firmware bit-equality can be measured without a trained checkpoint. build.rs bakes them
//! into the `mlp` and `transformer` images; the host tests rebuild them in memory.

pub mod mlp;
#[cfg(feature = "export")]
pub mod policy;
pub mod transformer;
