//! Checkpoint directory -> [`QuantizedPolicy`] in one call (usable from a firmware build.rs).
use crate::calibrate::{calibrate, input_gains, quantize, CalibrationSet, RangeMethod, Ranges};
use crate::checkpoint::{Checkpoint, CALIBRATION_FILE};
use crate::fold::FoldedMlp;
use crate::transformer::{FoldedTransformer, QuantizedTransformer, TransformerRanges};
use crate::QuantizedPolicy;
use anyhow::Context;
use std::path::Path;

/// Export settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExportOptions {
    /// Sampling steps baked into the step table (1..=4).
    pub steps: usize,
    pub ranges: RangeMethod,
    /// Balance the input segments' ranges with [`crate::fold::FoldedMlp::with_input_gains`].
    pub balance_inputs: bool,
}

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions { steps: 1, ranges: RangeMethod::MinMax, balance_inputs: true }
    }
}

/// Everything an export produced.
#[derive(Clone, Debug)]
pub struct Exported {
    pub checkpoint: Checkpoint,
    pub folded: FoldedMlp,
    pub ranges: Ranges,
    pub policy: QuantizedPolicy,
}

/// Reads `dir`, folds, calibrates on `calibration` (or `dir/calibration.safetensors` when
/// `None`) and quantizes.
pub fn export_checkpoint(dir: &Path, options: ExportOptions, calibration: Option<CalibrationSet>) -> anyhow::Result<Exported> {
    let checkpoint = Checkpoint::read(dir).with_context(|| format!("checkpoint {}", dir.display()))?;
    let folded = FoldedMlp::new(&checkpoint, options.steps).with_context(|| format!("cannot export {}", dir.display()))?;
    let norm = checkpoint.meta.normalization.clone().with_context(|| format!("{}: checkpoint has no normalization", dir.display()))?;
    let set = match calibration {
        Some(set) => set,
        None => crate::calibration_file::read(&dir.join(CALIBRATION_FILE), checkpoint.meta.model.cond_dim())
            .context("no calibration data given and the checkpoint's calibration file is unusable (pass --data)")?,
    };
    let folded = if options.balance_inputs { folded.with_input_gains(input_gains(&folded, &set)?)? } else { folded };
    let ranges = calibrate(&folded, &set, options.ranges)?;
    let policy = quantize(&folded, &ranges, &norm)?;
    Ok(Exported { checkpoint, folded, ranges, policy })
}

/// Everything a transformer export produced.
#[derive(Clone, Debug)]
pub struct ExportedTransformer {
    pub checkpoint: Checkpoint,
    pub ranges: TransformerRanges,
    /// The int8 model; its `folded` field is the f32 reference.
    pub model: QuantizedTransformer,
}

/// [`export_checkpoint`] for a transformer student: reads `dir`, folds the per-step noise tokens,
/// calibrates with the transformer probes on `calibration` (or `dir/calibration.safetensors`)
/// and quantizes. `options.balance_inputs` does not apply (each input layer has its own scale).
pub fn export_transformer_checkpoint(dir: &Path, options: ExportOptions, calibration: Option<CalibrationSet>) -> anyhow::Result<ExportedTransformer> {
    let checkpoint = Checkpoint::read(dir).with_context(|| format!("checkpoint {}", dir.display()))?;
    let folded = FoldedTransformer::new(&checkpoint, options.steps).with_context(|| format!("cannot export {}", dir.display()))?;
    let set = match calibration {
        Some(set) => set,
        None => crate::calibration_file::read(&dir.join(CALIBRATION_FILE), checkpoint.meta.model.cond_dim())
            .context("no calibration data given and the checkpoint's calibration file is unusable (pass --data)")?,
    };
    let ranges = crate::transformer::calibrate(&folded, &set, options.ranges)?;
    let model = crate::transformer::quantize(&folded, &ranges)?;
    Ok(ExportedTransformer { checkpoint, ranges, model })
}
