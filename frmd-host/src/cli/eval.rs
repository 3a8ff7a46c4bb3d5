//! `frmd eval`: closed-loop evaluation of a policy on a task, with the metrics of docs/design.md
//! section 6.
use crate::checkpoint::{CALIBRATION_FILE, CONFIG_FILE, WEIGHTS_FILE};
use crate::diffusion::samplers::Solver;
use crate::eval::plot::{plot_paths, PLOTTED_EPISODES};
use crate::eval::{evaluate, expert_policy, EvalConfig};
use crate::firmware::Board;
use crate::limits::{self, OptionError};
use crate::tasks::Policy;
use anyhow::bail;
use clap::Args;
use frmd_formats::artifact::{check_output_file, write_atomic};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Task name (reach, avoid, push, insert).
    #[arg(long)]
    pub task: String,
    /// Policy to evaluate: `expert` (the task's scripted expert; the default without --ckpt,
    /// --blob or --baked).
    #[arg(long)]
    pub policy: Option<String>,
    /// Number of evaluation episodes.
    #[arg(long, default_value_t = EvalConfig::default().episodes)]
    pub episodes: usize,
    /// Actions executed from each predicted chunk.
    #[arg(long, default_value_t = EvalConfig::default().exec_steps)]
    pub exec_steps: usize,
    /// Observation history handed to the expert (default 2; learned policies use their own).
    #[arg(long)]
    pub history: Option<usize>,
    /// Index of the first seed within the evaluation seed stream.
    #[arg(long, default_value_t = EvalConfig::default().first_seed)]
    pub first_seed: u64,
    /// Replace existing --json/--plot files (inputs are never overwritten).
    #[arg(long)]
    pub force: bool,
    /// Write the full report (with per-episode records) as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Draw the executed end-effector paths of the first episodes over the layout (PNG).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Number of episodes drawn by --plot.
    #[arg(long, default_value_t = PLOTTED_EPISODES)]
    pub plot_episodes: usize,
    /// Float checkpoint (teacher, student or DP) to evaluate.
    #[arg(long)]
    pub ckpt: Option<PathBuf>,
    /// Sampling steps for --ckpt (defaults: teacher 10, student 1, DP 10 = DDIM; DP 100 = DDPM).
    #[arg(long)]
    pub steps: Option<usize>,
    /// Teacher ODE solver for --ckpt: euler | heun | dpm++2m.
    #[arg(long)]
    pub solver: Option<Solver>,
    /// int8 student blob (written by `frmd export --blob`) run by frmd-core.
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
    pub firmware: Option<Board>,
    /// With --firmware: also run the host int8 policy (the blob beside --baked, or --blob) on every
    /// request and count the chunks whose bits differ from the firmware's.
    #[arg(long, requires = "firmware")]
    pub check_host: bool,
}

/// Options that do not go together: one policy source, and the sampler options only with a
/// float checkpoint.
fn check_sources(args: &EvalArgs) -> Result<(), OptionError> {
    let sources: Vec<&str> = [
        ("policy", args.policy.is_some()),
        ("ckpt", args.ckpt.is_some()),
        ("blob", args.blob.is_some()),
        ("baked", args.baked.is_some()),
    ]
    .into_iter()
    .filter_map(|(name, given)| given.then_some(name))
    .collect();
    if let [first, second, ..] = sources.as_slice() {
        let option = if *first == "policy" {
            "policy"
        } else if *first == "ckpt" {
            "ckpt"
        } else {
            "blob"
        };
        return Err(limits::conflict(
            option,
            format!("--{second}"),
            "give one policy to evaluate",
        ));
    }
    let int8 = if args.blob.is_some() {
        Some("--blob")
    } else if args.baked.is_some() {
        Some("--baked")
    } else {
        None
    };
    let float_only: [(&'static str, bool); 2] = [
        ("steps", args.steps.is_some()),
        ("solver", args.solver.is_some()),
    ];
    for (option, given) in float_only {
        if !given {
            continue;
        }
        if let Some(source) = int8 {
            return Err(limits::conflict(
                option,
                source,
                "the int8 blob's sampling steps are fixed at export (`frmd export --steps`)",
            ));
        }
        if args.ckpt.is_none() {
            return Err(limits::conflict(
                option,
                "the scripted expert",
                "it applies to a float checkpoint (--ckpt) only",
            ));
        }
    }
    if args.history.is_some() && (args.ckpt.is_some() || int8.is_some()) {
        return Err(limits::conflict(
            "history",
            int8.unwrap_or("--ckpt"),
            "a learned policy uses the history it was trained with",
        ));
    }
    if args.plot.is_none() && args.plot_episodes != PLOTTED_EPISODES {
        return Err(limits::conflict(
            "plot-episodes",
            "no --plot",
            "it sets how many episodes --plot draws",
        ));
    }
    Ok(())
}

/// Output files are checked before the run: neither an input nor (without --force) existing.
fn check_outputs(args: &EvalArgs, blob: Option<&Path>) -> anyhow::Result<()> {
    let mut inputs: Vec<PathBuf> = blob.into_iter().map(Path::to_path_buf).collect();
    if let Some(dir) = &args.ckpt {
        inputs.extend([CONFIG_FILE, WEIGHTS_FILE, CALIBRATION_FILE].map(|f| dir.join(f)));
    }
    let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    if let Some(path) = &args.json {
        check_output_file(path, "--json", args.force, &inputs)?;
    }
    if let Some(path) = &args.plot {
        check_output_file(path, "--plot", args.force, &inputs)?;
    }
    if let (Some(json), Some(plot)) = (&args.json, &args.plot) {
        if json == plot {
            bail!("--json and --plot name the same file {}", json.display());
        }
    }
    Ok(())
}

pub fn run(args: EvalArgs) -> anyhow::Result<ExitCode> {
    check_sources(&args)?;
    let blob = args.blob.clone().or_else(|| {
        args.baked
            .as_ref()
            .map(|d| d.join(frmd_export::bake::BLOB_FILE))
    });
    check_outputs(&args, blob.as_deref())?;
    if let Some(board) = args.firmware {
        anyhow::ensure!(
            args.ckpt.is_none(),
            "--firmware runs a baked int8 policy; --ckpt does not apply (use --baked DIR)"
        );
        return super::eval_firmware::run(&super::eval_firmware::FirmwareEval {
            task: &args.task,
            board,
            baked: args.baked.as_deref(),
            check_host: args.check_host,
            blob: blob.as_deref(),
            json: args.json.as_deref(),
            episodes: args.episodes,
            exec_steps: args.exec_steps,
            first_seed: args.first_seed,
        });
    }
    let (mut policy, history): (Box<dyn Policy>, usize) = match (&blob, &args.ckpt) {
        (Some(path), _) => {
            let p = crate::policy::int8::Int8Policy::load(path)?;
            let history = p.history();
            (Box::new(p), history)
        }
        (None, Some(dir)) => crate::policy::float::boxed(dir, args.steps, args.solver)?,
        (None, None) => match args.policy.as_deref().unwrap_or("expert") {
            "expert" => (
                expert_policy(&args.task)?,
                args.history.unwrap_or(EvalConfig::default().history),
            ),
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
    cfg.validate_for(policy.as_ref())?;
    let report = evaluate(&args.task, policy.as_mut(), &cfg)?;
    print!("{report}");
    if let Some(path) = &args.json {
        write_atomic(path, serde_json::to_string_pretty(&report)?.as_bytes())?;
        println!("  report         {}", path.display());
    }
    if let Some(path) = &args.plot {
        plot_paths(path, &report)?;
        println!("  plot           {}", path.display());
    }
    Ok(ExitCode::SUCCESS)
}
