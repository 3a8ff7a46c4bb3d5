//! `frmd export`: student checkpoint -> calibrated int8 policy, written as a baked Rust module
//! (`policy.rs` + `weights.bin`, plus `policy.blob` and `export.json` beside them) and/or a blob,
//! with the RAM and flash figures of the policy. The checkpoint's backbone picks the exporter:
//! MLP students get the const-baked module, transformer-lite students the `FRMT` blob plus a
//! generated module that embeds it (`frmd_export::transformer::bake`).
use crate::checkpoint::CALIBRATION_FILE;
use crate::data::Dataset;
use anyhow::{bail, Context};
use clap::Args;
use frmd_export::calibrate::{CalibrationSet, RangeMethod};
use frmd_export::checkpoint::BackboneConfig;
use frmd_export::export::{export_checkpoint, export_transformer_checkpoint, ExportOptions, Exported, ExportedTransformer};
use frmd_export::MemoryFigures;
use frmd_core::model::mlp::InputPrecision;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Blob written beside a baked module (what `--baked DIR` loads).
pub const BAKED_BLOB_FILE: &str = "policy.blob";
/// Export settings written beside a baked module.
pub const EXPORT_INFO_FILE: &str = "export.json";

#[derive(Args, Debug)]
pub struct ExportArgs {
    /// Student checkpoint directory.
    #[arg(long)]
    pub ckpt: PathBuf,
    /// Directory for the baked module (policy.rs, weights.bin, policy.blob, export.json).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also (or only) write the self-describing blob here.
    #[arg(long)]
    pub blob: Option<PathBuf>,
    /// Sampling steps baked into the step table (1..4).
    #[arg(long, default_value_t = 1)]
    pub steps: usize,
    /// Activation ranges: minmax | percentile:P (e.g. percentile:99.9).
    #[arg(long, default_value = "minmax")]
    pub calibration: String,
    /// Demonstrations to calibrate on when the checkpoint has no calibration.safetensors.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Keep the raw input segments (no range balancing of the trajectory and rate inputs).
    #[arg(long)]
    pub no_balance_inputs: bool,
    /// Quantize the model input to one int8 plane (default: one 16-bit plane).
    #[arg(long)]
    pub int8_input: bool,
    /// 16-bit input: widen the calibrated input range by this factor (>= 1).
    #[arg(long, default_value_t = frmd_export::export::DEFAULT_INPUT_HEADROOM)]
    pub input_headroom: f32,
    /// With --data: also store the calibration rows as the checkpoint's calibration.safetensors.
    #[arg(long)]
    pub save_calibration: bool,
}

/// What `export.json` records (enough to reproduce the export).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExportInfo {
    pub checkpoint: String,
    pub steps: usize,
    pub calibration: String,
    pub calibration_data: Option<String>,
    /// Input range balancing (`frmd_export::fold::FoldedMlp::with_input_gains`).
    #[serde(default = "default_true")]
    pub balance_inputs: bool,
    /// About 16-bit input precision: the 16-bit input plane
    /// (`frmd_core::model::mlp::InputPrecision::Int16`; before blob format 3, two int8 planes).
    #[serde(default = "default_true")]
    pub two_plane_input: bool,
    /// Input range widening with the 16-bit input.
    #[serde(default = "default_headroom")]
    pub input_headroom: f32,
}

fn default_headroom() -> f32 {
    frmd_export::export::DEFAULT_INPUT_HEADROOM
}

fn default_true() -> bool {
    true
}

/// Calibration rows from a dataset file, checked against the checkpoint's normalization.
pub fn calibration_from_data(path: &Path, ckpt: &Path) -> anyhow::Result<CalibrationSet> {
    let meta = frmd_export::checkpoint::CheckpointMeta::read(ckpt)?;
    let dataset = Dataset::load(path)?;
    let (windows, norm) = dataset.windows(meta.model.history, meta.model.horizon)?;
    if Some(&norm) != meta.normalization.as_ref() {
        bail!("{}: its normalization differs from the checkpoint's (not the training data?)", path.display());
    }
    Ok(crate::cli::train::calibration_rows(&windows, crate::cli::train::CALIBRATION_ROWS, 0x5eed))
}

/// The calibration rows `info` names: its data file, else `None` (the checkpoint's own file),
/// failing with advice when neither exists.
fn calibration_set(info: &ExportInfo) -> anyhow::Result<Option<CalibrationSet>> {
    let ckpt = Path::new(&info.checkpoint);
    let meta = frmd_export::checkpoint::CheckpointMeta::read(ckpt)?;
    if meta.role != frmd_export::checkpoint::Role::Student {
        bail!("{}: only student checkpoints can be exported; this one is a {:?} (its sampler needs many network evaluations)", ckpt.display(), meta.role);
    }
    match &info.calibration_data {
        Some(data) => Ok(Some(calibration_from_data(Path::new(data), ckpt)?)),
        None if !ckpt.join(CALIBRATION_FILE).exists() => {
            bail!("{} has no {CALIBRATION_FILE}; pass --data with the training demonstrations", ckpt.display())
        }
        None => Ok(None),
    }
}

fn options(info: &ExportInfo) -> anyhow::Result<ExportOptions> {
    let ranges: RangeMethod = info.calibration.parse()?;
    Ok(ExportOptions { steps: info.steps, ranges, balance_inputs: info.balance_inputs, input_precision: if info.two_plane_input { InputPrecision::Int16 } else { InputPrecision::Int8 }, input_headroom: info.input_headroom })
}

/// Whether the checkpoint `info` names has a transformer backbone (which picks the exporter).
pub fn is_transformer(info: &ExportInfo) -> anyhow::Result<bool> {
    let meta = frmd_export::checkpoint::CheckpointMeta::read(Path::new(&info.checkpoint))?;
    Ok(matches!(meta.model.backbone, BackboneConfig::Transformer { .. }))
}

/// Runs the MLP export of `info` (reads the calibration data it names).
pub fn export(info: &ExportInfo) -> anyhow::Result<Exported> {
    export_checkpoint(Path::new(&info.checkpoint), options(info)?, calibration_set(info)?)
}

/// Runs the transformer export of `info`.
pub fn export_transformer(info: &ExportInfo) -> anyhow::Result<ExportedTransformer> {
    export_transformer_checkpoint(Path::new(&info.checkpoint), options(info)?, calibration_set(info)?)
}

/// The `FRMT` blob of a transformer export.
pub fn transformer_blob(exported: &ExportedTransformer) -> anyhow::Result<Vec<u8>> {
    let norm = exported.checkpoint.meta.normalization.as_ref().context("the checkpoint has no normalization")?;
    frmd_export::blob::write_transformer(&exported.model, norm).map_err(|e| anyhow::anyhow!("encoding the transformer blob: {e}"))
}

fn print_memory(m: &MemoryFigures, blob_len: usize) {
    println!("  RAM    scratch {} B (width {}) + state {} B = {} B", m.scratch_bytes, m.scratch_width, m.state_bytes, m.scratch_bytes + m.state_bytes);
    println!("  flash  weights {} B + tables {} B = {} B (blob {} B)", m.weights_bytes, m.table_bytes, m.flash_bytes(), blob_len);
}

/// `frmd export` for a transformer student: the blob (and, with `--out`, the blob plus
/// `export.json` and the generated loader module in that directory).
fn run_transformer(args: &ExportArgs, info: &ExportInfo) -> anyhow::Result<ExitCode> {
    let exported = export_transformer(info)?;
    let blob = transformer_blob(&exported)?;
    if let Some(dir) = &args.out {
        frmd_export::transformer::bake::write_module(&exported.model, &blob, dir).with_context(|| format!("writing {}", dir.display()))?;
        std::fs::write(dir.join(EXPORT_INFO_FILE), serde_json::to_string_pretty(info)?)?;
        println!(
            "transformer module: {}/{{{}, {BAKED_BLOB_FILE}, {EXPORT_INFO_FILE}}} (the module embeds the blob and loads it with frmd-core's checked loader)",
            dir.display(),
            frmd_export::transformer::bake::MODULE_FILE
        );
    }
    if let Some(path) = &args.blob {
        std::fs::write(path, &blob).with_context(|| format!("writing {}", path.display()))?;
        println!("blob: {} ({} bytes)", path.display(), blob.len());
    }
    let f = &exported.model.folded;
    let model = &exported.checkpoint.meta.model;
    println!(
        "policy: {:?}, m {} O {} K {} n {} P {}, {} step(s), calibration {} on {} rows",
        model.backbone, model.history, model.obs_dim, model.action_dim, model.horizon, model.output_dim() / model.action_dim.max(1),
        f.steps.len(), info.calibration, exported.ranges.rows
    );
    print_memory(&exported.model.memory(), blob.len());
    Ok(ExitCode::SUCCESS)
}

pub fn run(args: ExportArgs) -> anyhow::Result<ExitCode> {
    if args.out.is_none() && args.blob.is_none() {
        bail!("nothing to write: pass --out DIR and/or --blob FILE");
    }
    let info = ExportInfo {
        checkpoint: args.ckpt.display().to_string(),
        steps: args.steps,
        calibration: args.calibration.clone(),
        calibration_data: args.data.as_ref().map(|p| p.display().to_string()),
        balance_inputs: !args.no_balance_inputs,
        two_plane_input: !args.int8_input,
        input_headroom: args.input_headroom,
    };
    if args.save_calibration {
        let data = args.data.as_ref().context("--save-calibration needs --data")?;
        let set = calibration_from_data(data, &args.ckpt)?;
        frmd_export::calibration_file::write(&args.ckpt.join(CALIBRATION_FILE), &set)?;
    }
    if is_transformer(&info)? {
        return run_transformer(&args, &info);
    }
    let exported = export(&info)?;
    let policy = &exported.policy;
    let blob = frmd_export::blob::write(policy).map_err(|e| anyhow::anyhow!("encoding the blob: {e}"))?;
    if let Some(dir) = &args.out {
        frmd_export::bake::write_module(policy, dir).with_context(|| format!("writing {}", dir.display()))?;
        std::fs::write(dir.join(BAKED_BLOB_FILE), &blob)?;
        std::fs::write(dir.join(EXPORT_INFO_FILE), serde_json::to_string_pretty(&info)?)?;
        println!("baked module: {}/{{policy.rs, weights.bin, {BAKED_BLOB_FILE}, {EXPORT_INFO_FILE}}}", dir.display());
    }
    if let Some(path) = &args.blob {
        std::fs::write(path, &blob).with_context(|| format!("writing {}", path.display()))?;
        println!("blob: {} ({} bytes)", path.display(), blob.len());
    }
    let m = policy.memory();
    let model = &exported.checkpoint.meta.model;
    println!(
        "policy: {:?}, m {} O {} K {} n {} P {}, {} step(s), calibration {} on {} rows",
        model.backbone, policy.history, policy.obs_dim, policy.action_dim, policy.horizon, policy.params_per_dof,
        policy.steps.len(), info.calibration, exported.ranges.rows
    );
    let gains = exported.folded.gains;
    println!(
        "  input  int8 scale {:.5} (zero point {}, {:?}) over the whole input vector; segment gains: trajectory {:.4}, rate {:.4}",
        policy.input.scale, policy.input.zero_point, policy.input_precision, gains.traj_gain, gains.rate_gain
    );
    print_memory(&m, blob.len());
    Ok(ExitCode::SUCCESS)
}
