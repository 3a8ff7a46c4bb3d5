//! `frmd export`: student checkpoint -> calibrated int8 policy ([`crate::export`]), written as a
//! baked Rust module directory and/or a blob, with the RAM and flash figures of the policy.
use crate::checkpoint::{CALIBRATION_FILE, CONFIG_FILE, WEIGHTS_FILE};
use crate::export::{export_student, write_export, ExportConfig};
use anyhow::bail;
use clap::Args;
use frmd_export::bake::BLOB_FILE;
use frmd_export::{Activations, WeightRounding};
use frmd_formats::artifact::{check_output_dir, check_output_file};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

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
    #[arg(long, default_value_t = ExportConfig::default().steps)]
    pub steps: usize,
    /// Activation ranges: minmax | percentile:P (e.g. percentile:99.9).
    #[arg(long, default_value_t = ExportConfig::default().calibration)]
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
    #[arg(long, default_value_t = ExportConfig::default().input_headroom)]
    pub input_headroom: f32,
    /// Hidden activations: int8 (TFLite int8) or int16 (TFLite 16x8: int8 weights, int16
    /// activations, int64 biases; an MLP needs the 16-bit input) [default: int16 for an MLP,
    /// int8 for transformer-lite]
    #[arg(long)]
    pub activations: Option<Activations>,
    /// int16 activations: widen every calibrated activation range by this factor (>= 1).
    #[arg(long, default_value_t = ExportConfig::default().activation_headroom)]
    pub activation_headroom: f32,
    /// How int8 weights are rounded: nearest (each weight on its own) or gptq (column by column,
    /// each rounding error moved onto the columns not yet rounded, weighted by the calibration
    /// inputs; MLP only) [default: gptq for an MLP, nearest for transformer-lite]
    #[arg(long)]
    pub weight_rounding: Option<WeightRounding>,
    /// With --data: also store the calibration rows as the checkpoint's calibration.safetensors.
    #[arg(long)]
    pub save_calibration: bool,
    /// Replace an existing --blob file or write into a non-empty --out directory (inputs are
    /// never overwritten).
    #[arg(long)]
    pub force: bool,
}

impl From<&ExportArgs> for ExportConfig {
    fn from(a: &ExportArgs) -> Self {
        let defaults = ExportConfig::default();
        ExportConfig {
            checkpoint: a.ckpt.display().to_string(),
            steps: a.steps,
            calibration: a.calibration.clone(),
            calibration_data: a.data.as_ref().map(|p| p.display().to_string()),
            balance_inputs: defaults.balance_inputs && !a.no_balance_inputs,
            two_plane_input: defaults.two_plane_input && !a.int8_input,
            input_headroom: a.input_headroom,
            activations: a.activations.map(|a| a.to_string()),
            activation_headroom: a.activation_headroom,
            weight_rounding: a.weight_rounding.map(|r| r.to_string()),
        }
    }
}

/// Whether two directory paths name the same directory (existing or not).
fn same_dir(a: &Path, b: &Path) -> bool {
    let norm = |p: &Path| p.canonicalize().unwrap_or_else(|_| p.to_path_buf());
    let a = if a.as_os_str().is_empty() {
        Path::new(".")
    } else {
        a
    };
    norm(a) == norm(b)
}

pub fn run(args: ExportArgs) -> anyhow::Result<ExitCode> {
    if args.out.is_none() && args.blob.is_none() {
        bail!("nothing to write: pass --out DIR and/or --blob FILE");
    }
    let cfg = ExportConfig::from(&args);
    cfg.validate()?;
    let mut inputs = vec![
        args.ckpt.join(CONFIG_FILE),
        args.ckpt.join(WEIGHTS_FILE),
        args.ckpt.join(CALIBRATION_FILE),
    ];
    inputs.extend(args.data.clone());
    let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    if let Some(dir) = &args.out {
        check_output_dir(dir, "--out", args.force, &inputs)?;
    }
    if let Some(path) = &args.blob {
        check_output_file(path, "--blob", args.force, &inputs)?;
        if let Some(dir) = &args.out {
            if path
                .parent()
                .zip(path.file_name())
                .is_some_and(|(p, n)| same_dir(p, dir) && n == BLOB_FILE)
            {
                bail!(
                    "--blob {} is the blob --out writes; drop --blob",
                    path.display()
                );
            }
        }
    }
    if args.save_calibration && args.data.is_none() {
        bail!("--save-calibration needs --data");
    }
    let student = export_student(&cfg, args.save_calibration)?;
    let written = write_export(&cfg, &student, args.out.as_deref(), args.blob.as_deref())?;
    for path in written {
        println!("wrote {}", path.display());
    }
    println!("{student}");
    Ok(ExitCode::SUCCESS)
}
