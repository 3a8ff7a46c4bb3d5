//! Fixtures the FRMD tests share.
//!
//! - [`checkpoint`]: student checkpoints with random weights and calibration rows, written
//!   without candle;
//! - [`random_policy`]: a deterministic random exported MLP policy
//!   ([`frmd_export::mlp::QuantizedMlp`]) with valid parameters, of any shape.
//!
//! Blob bytes in aligned memory are `frmd_core::blob::AlignedBlob`.

pub mod checkpoint;
pub mod random_policy;
