//! FRMD export: a float student checkpoint in, a calibrated int8 policy for frmd-core out, as a
//! self-describing blob or a baked Rust module, for every backbone through one call:
//!
//! ```no_run
//! # fn main() -> anyhow::Result<()> {
//! let dir = std::path::Path::new("runs/reach/student");
//! let student = frmd_export::export(dir, &frmd_export::ExportOptions::default(), None)?;
//! student.write_module(std::path::Path::new("baked"))?; // policy.rs + data files + policy.blob
//! println!("{student}"); // shape, calibration, RAM and flash
//! # Ok(())
//! # }
//! ```
//!
//! The crate has frmd-core's shape: what every backbone shares at the root, one folder per
//! backbone beside it.
//!
//! - [`export()`] / [`export_checkpoint`]: the entry point, returning an [`ExportedStudent`];
//!   [`ExportOptions`] its settings;
//! - [`fold`]: step table, noise embeddings, input layout, ProDMP tables and the host sampler of
//!   every folded student; [`calibrate`]: range methods and int8 weight/bias helpers;
//!   [`memory`]: RAM/flash figures; [`bake`]: what every generated module offers; [`reference`](mod@reference):
//!   the wide-integer checks' outcome and the requantization check; [`host`]: the capacities
//!   with which std programs run an exported policy;
//! - [`mlp`] and [`transformer`]: each backbone's fold, calibration, quantization, blob, baked
//!   module and kernel check.
//!
//! The files training shares (checkpoint schema, calibration rows, reproducible safetensors,
//! atomic artifacts) are the crate `frmd-formats` (`frmd-export/formats`), re-exported as
//! [`formats`].
#![warn(missing_docs)]

mod backbone;
pub mod bake;
pub mod calibrate;
mod export;
pub mod fold;
pub mod host;
pub mod memory;
pub mod mlp;
pub mod reference;
pub mod rounding;
pub mod transformer;

pub use backbone::{
    Activations, ExportOptions, DEFAULT_ACTIVATION_HEADROOM, DEFAULT_INPUT_HEADROOM,
};
pub use export::{export, export_checkpoint, ExportedStudent};
pub use frmd_formats as formats;
pub use rounding::WeightRounding;
