//! FRMD export: turns a float student checkpoint into a baked int8 model for frmd-core.
//!
//! - [`QuantizedPolicy`]: the owned result of quantization (filled by the checkpoint quantizer);
//! - [`blob::write`]: the self-describing blob (format in [`frmd_core::blob`]);
//! - [`bake::write_module`]: a generated Rust module plus an aligned `weights.bin`.

pub mod bake;
pub mod blob;
pub mod quantized;

pub use quantized::{
    MemoryFigures, ProDmpTablesOwned, QuantizedLayer, QuantizedOutput, QuantizedPolicy,
};
