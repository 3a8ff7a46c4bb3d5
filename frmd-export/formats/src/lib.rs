//! The files FRMD's std tools share, with no model code: what training writes and the exporter,
//! the evaluator and the server read. Training depends on this crate, not on the exporter.
//!
//! - [`checkpoint`]: `frmd.json` (the one schema: roles, model config, normalization, expected
//!   tensors) and `model.safetensors` read as checked f32 tensors, without candle;
//! - [`calibration`]: the calibration rows an export quantizes with and their
//!   `calibration.safetensors` file beside a student;
//! - [`safetensors_bytes`]: safetensors files whose bytes do not depend on a `HashMap`'s order;
//! - [`artifact`]: atomic writes and the checks every command runs on its output paths first.
//!
//! Every reader names the file and field a bad value came from.
#![warn(missing_docs)]

pub mod artifact;
pub mod calibration;
pub mod checkpoint;
pub mod safetensors_bytes;
