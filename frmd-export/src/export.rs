//! Checkpoint directory -> [`QuantizedPolicy`] in one call (usable from a firmware build.rs).
use crate::calibrate::{
    calibrate, input_gains, quantize, widen, CalibrationSet, RangeMethod, Ranges,
};
use crate::checkpoint::{Checkpoint, CALIBRATION_FILE};
use crate::fold::FoldedMlp;
use crate::transformer::{FoldedTransformer, QuantizedTransformer, TransformerRanges};
use crate::QuantizedPolicy;
use anyhow::Context;
use frmd_core::model::mlp::InputPrecision;
use std::path::Path;

/// Export settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExportOptions {
    /// Sampling steps baked into the step table (1..=4).
    pub steps: usize,
    pub ranges: RangeMethod,
    /// Balance the input segments' ranges with [`crate::fold::FoldedMlp::with_input_gains`].
    pub balance_inputs: bool,
    /// How the MLP's first layer takes the input: one 16-bit plane
    /// (`frmd_core::model::mlp::InputPrecision::Int16`, the default: about 16-bit input precision
    /// in one pass), two int8 planes (`TwoPlane`: the same precision in two passes) or one int8
    /// plane (`Int8`).
    pub input_precision: InputPrecision,
    /// With a 16-bit or two-plane input: the calibrated input range is widened by this factor
    /// (>= 1), so observations beyond the training range (closed-loop states the demonstrations
    /// never visited) reach the network instead of saturating; the fine grid keeps the resolution
    /// (`range / 2^16`). Ignored for plain int8 input.
    pub input_headroom: f32,
}

/// Default [`ExportOptions::input_headroom`]: the weaker built-in task policies reach normalized
/// observations of 3-16 in closed loop (training range +-1).
pub const DEFAULT_INPUT_HEADROOM: f32 = 8.0;

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions {
            steps: 1,
            ranges: RangeMethod::MinMax,
            balance_inputs: true,
            input_precision: InputPrecision::Int16,
            input_headroom: DEFAULT_INPUT_HEADROOM,
        }
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

fn read_checkpoint(dir: &Path) -> anyhow::Result<Checkpoint> {
    Checkpoint::read(dir).with_context(|| format!("checkpoint {}", dir.display()))
}

/// The calibration rows of an export: `calibration`, else the checkpoint's own
/// `dir/calibration.safetensors`.
fn calibration_rows(
    dir: &Path,
    checkpoint: &Checkpoint,
    calibration: Option<CalibrationSet>,
) -> anyhow::Result<CalibrationSet> {
    match calibration {
        Some(set) => Ok(set),
        None => crate::calibration_file::read(&dir.join(CALIBRATION_FILE), checkpoint.meta.model.cond_dim())
            .context("no calibration data given and the checkpoint's calibration file is unusable (pass --data)"),
    }
}

/// Reads `dir`, folds, calibrates on `calibration` (or `dir/calibration.safetensors` when
/// `None`) and quantizes.
pub fn export_checkpoint(
    dir: &Path,
    options: ExportOptions,
    calibration: Option<CalibrationSet>,
) -> anyhow::Result<Exported> {
    let checkpoint = read_checkpoint(dir)?;
    let folded = FoldedMlp::new(&checkpoint, options.steps)
        .with_context(|| format!("cannot export {}", dir.display()))?;
    let norm = checkpoint
        .meta
        .normalization
        .clone()
        .with_context(|| format!("{}: checkpoint has no normalization", dir.display()))?;
    let set = calibration_rows(dir, &checkpoint, calibration)?;
    let folded = if options.balance_inputs {
        folded.with_input_gains(input_gains(&folded, &set)?)?
    } else {
        folded
    };
    let mut ranges = calibrate(&folded, &set, options.ranges)?;
    if options.input_precision != InputPrecision::Int8 {
        ranges.input = widen(ranges.input, options.input_headroom).context("input headroom")?;
    }
    let policy = quantize(&folded, &ranges, &norm, options.input_precision)?;
    Ok(Exported {
        checkpoint,
        folded,
        ranges,
        policy,
    })
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
/// and quantizes. `options.balance_inputs` and `options.input_precision` do not apply (each input
/// layer has its own scale).
pub fn export_transformer_checkpoint(
    dir: &Path,
    options: ExportOptions,
    calibration: Option<CalibrationSet>,
) -> anyhow::Result<ExportedTransformer> {
    let checkpoint = read_checkpoint(dir)?;
    let folded = FoldedTransformer::new(&checkpoint, options.steps)
        .with_context(|| format!("cannot export {}", dir.display()))?;
    let set = calibration_rows(dir, &checkpoint, calibration)?;
    let ranges = crate::transformer::calibrate(&folded, &set, options.ranges)?;
    let model = crate::transformer::quantize(&folded, &ranges)?;
    Ok(ExportedTransformer {
        checkpoint,
        ranges,
        model,
    })
}
