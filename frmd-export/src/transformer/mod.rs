//! The transformer-lite student's exporter: fold ([`FoldedTransformer`]: per-step noise tokens),
//! calibrate with frmd-core's transformer probes and quantize ([`calibrate()`], [`quantize()`])
//! into an owned [`QuantizedTransformer`] (int8 weights; int8 or int16 activations) that views
//! as frmd-core's [`QuantTransformer`](frmd_core::model::transformer::QuantTransformer), then
//! write it as the
//! `FRMT` blob ([`QuantizedTransformer::blob`], the supported firmware form) or a module that
//! embeds that blob ([`bake`]), and check every quantized layer against a wide-integer model
//! ([`reference`](mod@reference)). [`TransformerExports`] is what [`crate::export`] returns
//! inside an [`ExportedStudent`](crate::ExportedStudent).

pub mod bake;
mod fold;
mod memory;
mod quantize;
pub mod reference;

use reference::WideCodes;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests16;

pub use fold::{FloatBlock, FloatNorm, FoldedTransformer};
pub use quantize::{
    calibrate, quantize, QuantizedBlock, QuantizedLinear, QuantizedTransformer, TransformerRanges,
};

use std::fmt;
use std::path::{Path, PathBuf};

use anyhow::bail;
use frmd_core::blob::BlobError;
use frmd_core::policy::{F32TransformerNetwork, Network, PolicyDims};
use frmd_formats::calibration::CalibrationSet;
use frmd_formats::checkpoint::{Checkpoint, Normalization};

use crate::backbone::{Activations, ExportOptions, ExportedNetwork};
use crate::host::HostScratch;
use crate::memory::MemoryFigures;
use crate::reference::KernelCheck;
use crate::rounding::WeightRounding;

/// Random input rows per layer of the exported transformer's check (d), besides its edge rows.
const CHECK_ROWS: usize = 16;
/// Seed of those rows.
const CHECK_SEED: u64 = 0x7f3e;

/// An exported transformer student: its calibrated ranges and the quantized model with `P`
/// activations (whose `folded` field is the f32 reference).
#[derive(Clone, Debug)]
pub struct TransformerExport<P: WideCodes = i8> {
    /// The calibrated (int8) activation parameters.
    pub ranges: TransformerRanges,
    /// The quantized model.
    pub model: QuantizedTransformer<P>,
    /// The folded model's noise tokens back to back (its f32 network's).
    noise_tokens: Vec<f32>,
}

/// An exported transformer student of either activation precision.
#[derive(Clone, Debug)]
pub enum TransformerExports {
    /// int8 activations.
    Int8(TransformerExport<i8>),
    /// int16 activations.
    Int16(TransformerExport<i16>),
}

impl TransformerExports {
    /// The one that is exported.
    pub(crate) fn get(&self) -> &dyn ExportedNetwork {
        match self {
            TransformerExports::Int8(transformer) => transformer,
            TransformerExports::Int16(transformer) => transformer,
        }
    }
}

/// Folds `checkpoint` (per-step noise tokens), calibrates on `set` with the transformer probes and
/// quantizes with `activations`. `options.balance_inputs` and `options.input_precision` do not
/// apply (each input layer has its own scale); `options.activation_headroom` widens the int16
/// ranges as it does for the MLP.
pub(crate) fn export(
    checkpoint: &Checkpoint,
    options: &ExportOptions,
    activations: Activations,
    set: &CalibrationSet,
) -> anyhow::Result<TransformerExports> {
    Ok(match activations {
        Activations::Int8 => TransformerExports::Int8(export_as(checkpoint, options, set)?),
        Activations::Int16 => TransformerExports::Int16(export_as(checkpoint, options, set)?),
    })
}

/// [`export`] with `P` activations.
fn export_as<P: WideCodes>(
    checkpoint: &Checkpoint,
    options: &ExportOptions,
    set: &CalibrationSet,
) -> anyhow::Result<TransformerExport<P>> {
    if let Some(rounding) = options
        .weight_rounding
        .filter(|r| *r != WeightRounding::Nearest)
    {
        bail!("weight rounding {rounding}: transformer-lite rounds its weights to nearest only");
    }
    let folded = FoldedTransformer::new(checkpoint, options.steps)?;
    let ranges = calibrate(&folded, set, options.ranges)?;
    let model = quantize::<P>(&folded, &ranges, options.activation_headroom)?;
    Ok(TransformerExport {
        noise_tokens: folded.flat_noise_tokens(),
        ranges,
        model,
    })
}

impl<P: WideCodes> ExportedNetwork for TransformerExport<P> {
    fn dims(&self) -> PolicyDims {
        self.model.dims()
    }

    fn steps(&self) -> usize {
        self.model.folded.base.steps.len()
    }

    fn calibration_rows(&self) -> usize {
        self.ranges.rows
    }

    fn blob(&self, norm: &Normalization) -> Result<Vec<u8>, BlobError> {
        self.model.blob(norm)
    }

    fn write_module(&self, blob: &[u8], dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
        bake::write_module(&self.model, blob, dir)
    }

    fn memory(&self) -> MemoryFigures {
        self.model.memory()
    }

    fn details(&self, _: &mut fmt::Formatter<'_>) -> fmt::Result {
        Ok(())
    }

    fn sample_f32(
        &self,
        cond: &[f32],
        noise: &[f32],
        on_input: &mut dyn FnMut(usize, &[f32]),
    ) -> anyhow::Result<Vec<f32>> {
        let folded = &self.model.folded;
        folded.base.sample(cond, noise, |step, input| {
            on_input(step, input);
            folded.forward_observed(step, input, |_, _| {})
        })
    }

    /// Every quantized linear layer on random and edge rows (its own inputs: the model inputs do
    /// not reach the inner layers as code rows).
    fn check_kernels(&self, _: &[Vec<f32>]) -> anyhow::Result<KernelCheck> {
        reference::check_layers(&self.model, CHECK_ROWS, CHECK_SEED)
    }

    fn with_f32_network(
        &self,
        scratch: &mut HostScratch,
        run: &mut dyn FnMut(&mut dyn Network) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        let folded = &self.model.folded;
        let blocks = folded.f32_blocks();
        let mut network = F32TransformerNetwork::new(
            folded.view(&blocks, 0)?,
            &folded.base.layout,
            &self.noise_tokens,
            scratch,
        )?;
        run(&mut network)
    }
}
