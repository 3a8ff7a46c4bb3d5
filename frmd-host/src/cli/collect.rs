//! `frmd collect`: runs a task's scripted expert and writes a demonstration dataset
//! ([`crate::data::collect::collect_to_file`]).
use crate::data::collect::{collect_to_file, CollectConfig, PolicySource};
use crate::data::perturb::ActionNoise;
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug)]
pub struct CollectArgs {
    /// Task name (reach, avoid, push, insert).
    #[arg(long)]
    pub task: String,
    /// Number of successful demonstrations to write (with --policy: episodes to record).
    #[arg(long, default_value_t = CollectConfig::default().episodes)]
    pub episodes: usize,
    /// First collection seed (must be below 2^63; evaluation uses seeds from 2^63 on).
    #[arg(long, default_value_t = CollectConfig::default().seed)]
    pub seed: u64,
    /// Output safetensors file (must not exist unless --force).
    #[arg(long)]
    pub out: PathBuf,
    /// Replace an existing --out file.
    #[arg(long)]
    pub force: bool,
    /// Perturb the executed actions with smooth noise of this standard deviation (metres) and
    /// record the expert's clean actions (DART), so the demonstrations contain recoveries.
    /// 0 = unperturbed.
    #[arg(long, default_value_t = CollectConfig::default().noise.std)]
    pub perturb_std: f64,
    /// Correlation time of the perturbation, seconds.
    #[arg(long, default_value_t = CollectConfig::default().noise.correlation_time)]
    pub perturb_time: f64,
    /// Record this many more expert steps after each episode's first success (0: a
    /// demonstration ends at it), so the data shows the expert settling at the goal.
    #[arg(long, default_value_t = CollectConfig::default().after_success)]
    pub after_success: usize,
    /// Record this trained policy's rollouts instead of the expert's demonstrations: every
    /// episode is kept, with the executed actions (on-policy states for `frmd train student
    /// --on-policy-data`). The perturbation options do not apply.
    #[arg(long, value_name = "CKPT")]
    pub policy: Option<PathBuf>,
    /// Sampling steps of --policy (default: its role's, one for a student).
    #[arg(long, requires = "policy")]
    pub policy_steps: Option<usize>,
}

pub fn run(args: CollectArgs) -> anyhow::Result<ExitCode> {
    let noise = ActionNoise {
        std: args.perturb_std,
        correlation_time: args.perturb_time,
    };
    let cfg = CollectConfig {
        task: args.task,
        episodes: args.episodes,
        seed: args.seed,
        out: args.out,
        force: args.force,
        noise,
        after_success: args.after_success,
        policy: args.policy.map(|ckpt| PolicySource {
            ckpt,
            steps: args.policy_steps,
        }),
    };
    let c = collect_to_file(&cfg)?;
    let outcome = if cfg.policy.is_some() {
        format!(
            "policy successes: {} of {} (every episode kept)",
            c.stats.attempted - c.stats.failed,
            c.stats.attempted
        )
    } else {
        format!(
            "expert failures skipped: {} of {}; sim step {:.2} us",
            c.stats.failed, c.stats.attempted, c.stats.sim_step_us
        )
    };
    println!(
        "wrote {}: {} episodes, {} steps (mean length {:.1}), obs_dim {}, action_dim {}, {} bytes; {outcome}",
        cfg.out.display(),
        c.episodes,
        c.steps,
        c.mean_length,
        c.obs_dim,
        c.action_dim,
        c.bytes,
    );
    Ok(ExitCode::SUCCESS)
}
