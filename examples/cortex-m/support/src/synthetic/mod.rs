//! Deterministic synthetic networks with the firmware's shapes (std): generated from
//! `frmd_core::rng::Rng` and quantized the way the exporter quantizes, so that cost, memory and
//! host/firmware bit-equality can be measured without a trained checkpoint. build.rs bakes them
//! into the `mlp` and `transformer` images; the host tests rebuild them in memory.

pub mod mlp;
#[cfg(feature = "export")]
pub mod policy;
pub mod transformer;

/// Rust source of `values` as a comma-separated list of integer literals (build.rs code).
pub(crate) fn rust_ints(values: &[i32]) -> String {
    values
        .iter()
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Rust source of `values` as a comma-separated list of bit-exact `f32::from_bits` expressions.
pub(crate) fn rust_floats(values: &[f32]) -> String {
    values
        .iter()
        .map(|v| format!("f32::from_bits(0x{:08x})", v.to_bits()))
        .collect::<Vec<_>>()
        .join(", ")
}
