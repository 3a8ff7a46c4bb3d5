//! `frmd eval`: closed-loop evaluation of a policy on a task, with the metrics of docs/design.md
//! section 6.
use crate::eval::plot::{plot_paths, PLOTTED_EPISODES};
use crate::eval::{evaluate, expert_policy, EvalConfig, EvalReport};
use crate::tasks::Policy;
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Task name (reach, avoid, push, insert).
    #[arg(long)]
    pub task: String,
    /// Policy to evaluate: `expert` (the task's scripted expert).
    #[arg(long, default_value = "expert")]
    pub policy: String,
    /// Number of evaluation episodes.
    #[arg(long, default_value_t = EvalConfig::default().episodes)]
    pub episodes: usize,
    /// Actions executed from each predicted chunk.
    #[arg(long, default_value_t = EvalConfig::default().exec_steps)]
    pub exec_steps: usize,
    /// Observation history length handed to the policy.
    #[arg(long, default_value_t = EvalConfig::default().history)]
    pub history: usize,
    /// Index of the first seed within the evaluation seed stream.
    #[arg(long, default_value_t = EvalConfig::default().first_seed)]
    pub first_seed: u64,
    /// Write the full report (with per-episode records) as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Draw the executed end-effector paths of the first episodes over the layout (PNG).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Number of episodes drawn by --plot.
    #[arg(long, default_value_t = PLOTTED_EPISODES)]
    pub plot_episodes: usize,
    /// Float checkpoint (teacher, student or DP) to evaluate; overrides --policy and --history.
    #[arg(long)]
    pub ckpt: Option<PathBuf>,
    /// Sampling steps for --ckpt (defaults: teacher 10, student 1, DP 10 = DDIM; DP 100 = DDPM).
    #[arg(long)]
    pub steps: Option<usize>,
    /// Teacher ODE solver for --ckpt: euler | heun | dpm++2m.
    #[arg(long)]
    pub solver: Option<String>,
    /// int8 student blob (written by `frmd export --blob`) run by frmd-core; overrides --policy.
    #[arg(long)]
    pub blob: Option<PathBuf>,
    /// Baked module directory (`frmd export --out`): evaluates the blob written beside it (with
    /// --firmware: bakes its module into the firmware image).
    #[arg(long)]
    pub baked: Option<PathBuf>,
    /// Processor in the loop: every chunk comes from the `pil` firmware image on this core (m4,
    /// m7, m33, m0, m55) under QEMU; reports the instructions per chunk the image counted. Bakes
    /// --baked DIR's module, else the checked-in reach student.
    #[arg(long, value_name = "CORE")]
    pub firmware: Option<String>,
    /// With --firmware: also run the host int8 policy (the blob beside --baked, or --blob) on every
    /// request and count the chunks whose bits differ from the firmware's.
    #[arg(long, requires = "firmware")]
    pub check_host: bool,
}

/// Prints the human-readable summary of a report.
pub fn print_report(report: &EvalReport) {
    println!(
        "task {} / policy {} / {} episodes (exec {} of each chunk, history {})",
        report.task, report.policy, report.episodes, report.exec_steps, report.history
    );
    println!(
        "  success        {:.1} % ({} of {}), 95 % Wilson [{:.1}, {:.1}] %",
        100.0 * report.success_rate,
        report.successes,
        report.episodes,
        100.0 * report.success_ci95[0],
        100.0 * report.success_ci95[1]
    );
    println!(
        "  length         {:.1} steps (successful: {:.1})",
        report.mean_length, report.mean_length_success
    );
    println!(
        "  latency/chunk  median {:.1} us, p99 {:.1} us over {} calls (RAYON_NUM_THREADS={})",
        report.latency_us_median, report.latency_us_p99, report.chunk_calls, report.threads
    );
    println!("  sim step       {:.2} us", report.sim_step_us);
    println!(
        "  non-smooth     {:.2} per episode (end effector), {:.2} (actions); RMS jerk {:.2} m/s^3",
        report.non_smooth_ee_mean, report.non_smooth_action_mean, report.rms_jerk_mean
    );
}

pub fn run(args: EvalArgs) -> anyhow::Result<ExitCode> {
    if let Some(board) = &args.firmware {
        return super::eval_firmware::run(&args, board);
    }
    let blob = args.blob.clone().or_else(|| args.baked.as_ref().map(|d| d.join(crate::export::BAKED_BLOB_FILE)));
    let (mut policy, history): (Box<dyn Policy>, usize) = match (&blob, &args.ckpt) {
        (Some(path), _) => {
            let p = crate::policy::int8::Int8Policy::load(path)?;
            let history = p.history();
            (Box::new(p), history)
        }
        (None, Some(dir)) => crate::policy::float::boxed(dir, args.steps, args.solver.as_deref())?,
        (None, None) => match args.policy.as_str() {
            "expert" => (expert_policy(&args.task)?, args.history),
            other => anyhow::bail!("unknown policy {other:?}; available: expert (or --ckpt DIR)"),
        },
    };
    let cfg = EvalConfig {
        episodes: args.episodes,
        exec_steps: args.exec_steps,
        history,
        first_seed: args.first_seed,
        keep_paths: if args.plot.is_some() {
            args.plot_episodes
        } else {
            0
        },
        ..EvalConfig::default()
    };
    let report = evaluate(&args.task, policy.as_mut(), &cfg)?;
    print_report(&report);
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))?;
        println!("  report         {}", path.display());
    }
    if let Some(path) = &args.plot {
        plot_paths(path, &report)?;
        println!("  plot           {}", path.display());
    }
    Ok(ExitCode::SUCCESS)
}
