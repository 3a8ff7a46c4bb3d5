//! The MLP student's exporter: fold ([`FoldedMlp`]: per-step first-layer biases, input gains),
//! calibrate and quantize ([`calibrate()`], [`quantize()`]) into an owned [`QuantizedMlp`], then
//! write it as the `FRMD` blob ([`QuantizedMlp::blob`]) or the const-table baked module
//! ([`bake`]), and check it against a wide-integer model ([`reference`](mod@reference)). [`MlpExport`] is what
//! [`crate::export`] returns inside an [`ExportedStudent`](crate::ExportedStudent).

pub mod bake;
mod calibrate;
mod fold;
mod precision;
mod quantized;
pub mod reference;

pub use calibrate::{calibrate, input_gains, input_moments, quantize, Ranges};
pub use fold::{FoldedMlp, InputGains};
pub use precision::{ExportPrecision, WideModel};
pub use quantized::{QuantizedLayer, QuantizedMlp, QuantizedOutput};

use std::fmt;
use std::path::{Path, PathBuf};

use anyhow::Context;
use frmd_core::blob::BlobError;
use frmd_core::model::mlp::InputPrecision;
use frmd_core::policy::{Network, PolicyDims};
use frmd_formats::calibration::CalibrationSet;
use frmd_formats::checkpoint::{Checkpoint, Normalization};

use crate::backbone::{Activations, ExportOptions, ExportedNetwork};
use crate::bake::{write_files, BLOB_FILE};
use crate::calibrate::widen;
use crate::host::{HostScratch, MAX_WIDTH};
use crate::memory::MemoryFigures;
use crate::reference::KernelCheck;
use crate::rounding::WeightRounding;

/// An exported MLP student: the folded f32 model, its calibrated ranges and the quantized policy
/// with `P` activations.
#[derive(Clone, Debug)]
pub struct MlpExport<P: ExportPrecision = i8> {
    /// The folded f32 model (input gains applied).
    pub folded: FoldedMlp,
    /// The calibrated (int8) activation ranges.
    pub ranges: Ranges,
    /// The quantized policy.
    pub policy: QuantizedMlp<P>,
    /// The folded model's first-layer bias variants back to back (its f32 network's).
    f32_biases: Vec<f32>,
}

/// An exported MLP student of either activation precision.
#[derive(Clone, Debug)]
pub enum MlpExports {
    /// int8 activations.
    Int8(MlpExport<i8>),
    /// int16 activations.
    Int16(MlpExport<i16>),
}

impl MlpExports {
    /// The one that is exported.
    pub(crate) fn get(&self) -> &dyn ExportedNetwork {
        match self {
            MlpExports::Int8(mlp) => mlp,
            MlpExports::Int16(mlp) => mlp,
        }
    }
}

/// Folds `checkpoint`, calibrates on `set` and quantizes as `options` say, with `activations`.
pub(crate) fn export(
    checkpoint: &Checkpoint,
    options: &ExportOptions,
    activations: Activations,
    set: &CalibrationSet,
    norm: &Normalization,
) -> anyhow::Result<MlpExports> {
    Ok(match activations {
        Activations::Int8 => MlpExports::Int8(export_as(checkpoint, options, set, norm)?),
        Activations::Int16 => MlpExports::Int16(export_as(checkpoint, options, set, norm)?),
    })
}

/// [`export`] with `P` activations.
fn export_as<P: ExportPrecision>(
    checkpoint: &Checkpoint,
    options: &ExportOptions,
    set: &CalibrationSet,
    norm: &Normalization,
) -> anyhow::Result<MlpExport<P>> {
    let folded = FoldedMlp::new(checkpoint, options.steps)?;
    let folded = if options.balance_inputs {
        folded.with_input_gains(input_gains(&folded, set)?)?
    } else {
        folded
    };
    let mut ranges = calibrate(&folded, set, options.ranges)?;
    if options.input_precision != InputPrecision::Int8 {
        ranges.input = widen(ranges.input, options.input_headroom).context("input headroom")?;
    }
    // `export_checkpoint` resolved the backbone's default already.
    let rounding = options.weight_rounding.unwrap_or(WeightRounding::Gptq);
    let moments = match rounding {
        WeightRounding::Nearest => None,
        WeightRounding::Gptq => Some(input_moments(&folded, set)?),
    };
    let policy = quantize::<P>(
        &folded,
        &ranges,
        norm,
        options.input_precision,
        options.activation_headroom,
        (rounding, moments.as_deref()),
    )?;
    Ok(MlpExport {
        f32_biases: folded.flat_first_layer_biases(),
        folded,
        ranges,
        policy,
    })
}

impl<P: ExportPrecision> ExportedNetwork for MlpExport<P> {
    fn dims(&self) -> PolicyDims {
        self.policy.dims()
    }

    fn steps(&self) -> usize {
        self.policy.steps.len()
    }

    fn calibration_rows(&self) -> usize {
        self.ranges.rows
    }

    fn blob(&self, _: &Normalization) -> Result<Vec<u8>, BlobError> {
        self.policy.blob()
    }

    fn write_module(&self, blob: &[u8], dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
        let mut files = bake::write_module(&self.policy, dir)?;
        files.extend(write_files(dir, &[(BLOB_FILE, blob)])?);
        Ok(files)
    }

    fn memory(&self) -> MemoryFigures {
        self.policy.memory()
    }

    fn details(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (input, gains) = (self.policy.input, self.folded.gains);
        writeln!(
            f,
            "  input  int8 scale {:.5} (zero point {}, {:?}) over the whole input vector; segment gains: trajectory {:.4}, rate {:.4}",
            input.scale,
            input.zero_point,
            self.policy.input_precision,
            gains.traj_gain,
            gains.rate_gain
        )?;
        writeln!(f, "  hidden activations int{}", P::BITS)
    }

    fn sample_f32(
        &self,
        cond: &[f32],
        noise: &[f32],
        on_input: &mut dyn FnMut(usize, &[f32]),
    ) -> anyhow::Result<Vec<f32>> {
        self.folded.base.sample(cond, noise, |step, input| {
            on_input(step, input);
            self.folded.forward_observed(step, input, |_, _| {})
        })
    }

    fn check_kernels(&self, inputs: &[Vec<f32>]) -> anyhow::Result<KernelCheck> {
        reference::check_network::<P, MAX_WIDTH>(&self.policy, inputs)
    }

    fn with_f32_network(
        &self,
        _: &mut HostScratch,
        run: &mut dyn FnMut(&mut dyn Network) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        run(&mut self.folded.f32_network::<MAX_WIDTH>(&self.f32_biases)?)
    }
}
