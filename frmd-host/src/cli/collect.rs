//! `frmd collect`: runs a task's scripted expert and writes a demonstration dataset
//! ([`crate::data::collect::collect_to_file`]).
use crate::data::collect::{collect_to_file, CollectConfig};
use crate::data::perturb::ActionNoise;
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug)]
pub struct CollectArgs {
    /// Task name (reach, avoid, push, insert).
    #[arg(long)]
    pub task: String,
    /// Number of successful demonstrations to write.
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
    };
    let c = collect_to_file(&cfg)?;
    println!(
        "wrote {}: {} episodes, {} steps (mean length {:.1}), obs_dim {}, action_dim {}, {} bytes; \
         expert failures skipped: {} of {}; sim step {:.2} us",
        cfg.out.display(),
        c.episodes,
        c.steps,
        c.mean_length,
        c.obs_dim,
        c.action_dim,
        c.bytes,
        c.stats.failed,
        c.stats.attempted,
        c.stats.sim_step_us
    );
    Ok(ExitCode::SUCCESS)
}
