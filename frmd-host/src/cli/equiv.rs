//! `frmd equiv --ckpt DIR --baked DIR`: the bit-accuracy harness ([`crate::equiv`]); exits
//! non-zero when a bound is exceeded.
use crate::checkpoint::{CONFIG_FILE, WEIGHTS_FILE};
use crate::equiv::{print, run as run_equiv, EquivConfig};
use crate::export::EXPORT_INFO_FILE;
use clap::Args;
use frmd_export::bake::BLOB_FILE;
use frmd_formats::artifact::{check_output_file, write_atomic};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug)]
pub struct EquivArgs {
    /// Student checkpoint directory.
    #[arg(long)]
    pub ckpt: PathBuf,
    /// Baked module directory written by `frmd export --out`.
    #[arg(long)]
    pub baked: PathBuf,
    /// Closed-loop episodes per method (0 skips the success-rate check).
    #[arg(long, default_value_t = EquivConfig::default().episodes)]
    pub episodes: usize,
    /// Open-loop inputs for checks (a), (b), (d).
    #[arg(long, default_value_t = EquivConfig::default().inputs)]
    pub inputs: usize,
    /// Random requantization cases for (d).
    #[arg(long, default_value_t = EquivConfig::default().random_requant)]
    pub random_requant: u64,
    /// Calibration data override (demonstrations file).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Bound of (a), normalized units.
    #[arg(long, default_value_t = EquivConfig::default().max_f32_error)]
    pub max_f32_error: f64,
    /// Bound of (b) max abs error, fraction of the mean action range.
    #[arg(long, default_value_t = EquivConfig::default().max_int8_error_frac)]
    pub max_int8_error_frac: f64,
    /// Bound of (b) mean abs error, fraction of the mean action range.
    #[arg(long, default_value_t = EquivConfig::default().mean_int8_error_frac)]
    pub mean_int8_error_frac: f64,
    /// Bound of the success-rate difference, percentage points.
    #[arg(long, default_value_t = EquivConfig::default().max_success_diff_points)]
    pub max_success_diff: f64,
    /// Also write the report as JSON (must not exist unless --force).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Replace an existing --json file (inputs are never overwritten).
    #[arg(long)]
    pub force: bool,
}

pub fn run(args: EquivArgs) -> anyhow::Result<ExitCode> {
    if let Some(path) = &args.json {
        let inputs = [
            args.ckpt.join(CONFIG_FILE),
            args.ckpt.join(WEIGHTS_FILE),
            args.baked.join(BLOB_FILE),
            args.baked.join(EXPORT_INFO_FILE),
        ];
        check_output_file(
            path,
            "--json",
            args.force,
            &inputs.iter().map(PathBuf::as_path).collect::<Vec<_>>(),
        )?;
    }
    let cfg = EquivConfig {
        episodes: args.episodes,
        inputs: args.inputs,
        random_requant: args.random_requant,
        data: args.data,
        max_f32_error: args.max_f32_error,
        max_int8_error_frac: args.max_int8_error_frac,
        mean_int8_error_frac: args.mean_int8_error_frac,
        max_success_diff_points: args.max_success_diff,
        ..EquivConfig::new(args.ckpt, args.baked)
    };
    let report = run_equiv(&cfg)?;
    print(&report);
    if let Some(path) = &args.json {
        write_atomic(path, serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    Ok(if report.passed {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}
