//! FRMD export: turns a float student checkpoint into a baked int8 model for frmd-core.
//!
//! - [`artifact`]: atomic writes and the checks of output paths every command runs first;
//! - [`checkpoint`]: `frmd.json` schema (shared with frmd-host) and a candle-free reader;
//! - [`fold`]: the student folded for 1..=4 sampling steps, on frmd-core's f32 path;
//! - [`calibrate`]: activation ranges from that f32 path, then quantization;
//! - [`export`]: checkpoint directory -> [`QuantizedPolicy`] in one call (for build.rs);
//! - [`QuantizedPolicy`]: the owned result of quantization;
//! - [`blob::write`]: the self-describing blob (format in [`frmd_core::blob`]);
//! - [`bake::write_module`]: a generated Rust module plus an aligned `weights.bin`;
//! - [`safetensors_bytes`]: safetensors files whose bytes do not depend on a `HashMap`'s order;
//! - [`reference`]: independent wide-integer checks of the int8 kernels;
//! - [`transformer`]: the same pipeline for transformer-lite students (fold per-step noise
//!   tokens, calibrate with frmd-core's transformer probes, quantize, write the `FRMT` blob).

pub mod artifact;
pub mod bake;
pub mod blob;
pub mod calibrate;
pub mod calibration_file;
pub mod checkpoint;
pub mod export;
pub mod fold;
pub mod quantized;
pub mod reference;
pub mod safetensors_bytes;
pub mod transformer;

pub use quantized::{
    MemoryFigures, ProDmpTablesOwned, QuantizedLayer, QuantizedOutput, QuantizedPolicy,
};
