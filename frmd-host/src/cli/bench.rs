//! `frmd bench` (alias `frmd latency`): wall time per action chunk of every policy kind side by
//! side ([`crate::bench`]).
use crate::bench::{bench_rows, print_table, write_json, BenchConfig, PolicySpec};
use crate::models::BackboneConfig;
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Policies as DIR[:STEPS[:SOLVER]], e.g. `runs/quickstart/teacher:10:heun`, `dir/dp:100`.
    /// Default: student:1, student:2, teacher:10:heun, dp:100, dp:10 from --dir.
    #[arg(long = "policy")]
    pub policies: Vec<PolicySpec>,
    /// Directory holding `student/`, `teacher/` and `dp/` checkpoints (as written by quickstart);
    /// the frmd-core rows export its student unless a `--policy` names a student checkpoint.
    #[arg(long, default_value_os_t = BenchConfig::default().dir)]
    pub dir: PathBuf,
    /// Time randomly initialized networks of `--backbone` instead of checkpoints.
    #[arg(long)]
    pub synthetic: bool,
    /// Backbone of the synthetic networks (see `frmd train --backbone`).
    #[arg(long, default_value_t = BenchConfig::default().backbone)]
    pub backbone: BackboneConfig,
    /// Timed calls per policy (at least 200 for the docs/design.md p99).
    #[arg(long, default_value_t = BenchConfig::default().calls)]
    pub calls: usize,
    /// Untimed warm-up calls per policy.
    #[arg(long, default_value_t = BenchConfig::default().warmup)]
    pub warmup: usize,
    /// Write the results as JSON here (must not exist unless --force).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Replace an existing --json file.
    #[arg(long)]
    pub force: bool,
}

pub fn run(args: BenchArgs) -> anyhow::Result<ExitCode> {
    let cfg = BenchConfig {
        policies: args.policies,
        dir: args.dir,
        synthetic: args.synthetic,
        backbone: args.backbone,
        calls: args.calls,
        warmup: args.warmup,
    };
    crate::limits::count("calls", cfg.calls, 1, crate::limits::MAX_CHECKS)?;
    crate::limits::count("warmup", cfg.warmup, 0, crate::limits::MAX_CHECKS)?;
    if let Some(path) = &args.json {
        frmd_formats::artifact::check_output_file(path, "--json", args.force, &[])?;
    }
    let (rows, note) = bench_rows(&cfg)?;
    print_table(&rows, cfg.warmup, note.as_deref());
    if let Some(path) = &args.json {
        write_json(path, &rows, note.as_deref())?;
    }
    Ok(ExitCode::SUCCESS)
}
