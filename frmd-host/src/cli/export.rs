//! `frmd export`: student checkpoint -> calibrated int8 policy ([`crate::export`]), written as a
//! baked Rust module directory and/or a blob, with the RAM and flash figures of the policy.
use crate::checkpoint::{CALIBRATION_FILE, CONFIG_FILE, WEIGHTS_FILE};
use crate::export::{
    export_student, save_calibration, write_export, ExportConfig, ExportedStudent, BAKED_BLOB_FILE,
    EXPORT_INFO_FILE,
};
use anyhow::{bail, Context};
use clap::Args;
use frmd_export::artifact::{check_output_dir, check_output_file};
use frmd_export::MemoryFigures;
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

fn print_memory(m: &MemoryFigures, blob_len: usize) {
    println!(
        "  RAM    scratch {} B (width {}) + state {} B = {} B",
        m.scratch_bytes,
        m.scratch_width,
        m.state_bytes,
        m.scratch_bytes + m.state_bytes
    );
    println!(
        "  flash  weights {} B + tables {} B = {} B (blob {} B)",
        m.weights_bytes,
        m.table_bytes,
        m.flash_bytes(),
        blob_len
    );
}

fn print_summary(args: &ExportArgs, cfg: &ExportConfig, student: &ExportedStudent) {
    let blob = student.blob();
    match student {
        ExportedStudent::Mlp { exported, .. } => {
            if let Some(dir) = &args.out {
                println!("baked module: {}/{{policy.rs, weights.bin, {BAKED_BLOB_FILE}, {EXPORT_INFO_FILE}}}", dir.display());
            }
            if let Some(path) = &args.blob {
                println!("blob: {} ({} bytes)", path.display(), blob.len());
            }
            let policy = &exported.policy;
            let model = &exported.checkpoint.meta.model;
            println!(
                "policy: {:?}, m {} O {} K {} n {} P {}, {} step(s), calibration {} on {} rows",
                model.backbone,
                policy.history,
                policy.obs_dim,
                policy.action_dim,
                policy.horizon,
                policy.params_per_dof,
                policy.steps.len(),
                cfg.calibration,
                exported.ranges.rows
            );
            let gains = exported.folded.gains;
            println!(
                "  input  int8 scale {:.5} (zero point {}, {:?}) over the whole input vector; segment gains: trajectory {:.4}, rate {:.4}",
                policy.input.scale, policy.input.zero_point, policy.input_precision, gains.traj_gain, gains.rate_gain
            );
            print_memory(&policy.memory(), blob.len());
        }
        ExportedStudent::Transformer { exported, .. } => {
            if let Some(dir) = &args.out {
                println!(
                    "transformer module: {}/{{{}, {BAKED_BLOB_FILE}, {EXPORT_INFO_FILE}}} (the module embeds the blob and loads it with frmd-core's checked loader)",
                    dir.display(),
                    frmd_export::transformer::bake::MODULE_FILE
                );
            }
            if let Some(path) = &args.blob {
                println!("blob: {} ({} bytes)", path.display(), blob.len());
            }
            let f = &exported.model.folded;
            let model = &exported.checkpoint.meta.model;
            println!(
                "policy: {:?}, m {} O {} K {} n {} P {}, {} step(s), calibration {} on {} rows",
                model.backbone,
                model.history,
                model.obs_dim,
                model.action_dim,
                model.horizon,
                model.output_dim() / model.action_dim.max(1),
                f.steps.len(),
                cfg.calibration,
                exported.ranges.rows
            );
            print_memory(&exported.model.memory(), blob.len());
        }
    }
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
                .is_some_and(|(p, n)| same_dir(p, dir) && n == BAKED_BLOB_FILE)
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
    if args.save_calibration {
        let data = args
            .data
            .as_ref()
            .context("--save-calibration needs --data")?;
        save_calibration(data, &args.ckpt)?;
    }
    let student = export_student(&cfg)?;
    write_export(&cfg, &student, args.out.as_deref(), args.blob.as_deref())?;
    print_summary(&args, &cfg, &student);
    Ok(ExitCode::SUCCESS)
}
