//! `frmd collect`: runs a task's scripted expert and writes a demonstration dataset.
use crate::data::collect::collect_demos;
use crate::data::perturb::ActionNoise;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug)]
pub struct CollectArgs {
    /// Task name (reach, avoid, push, insert).
    #[arg(long)]
    pub task: String,
    /// Number of successful demonstrations to write.
    #[arg(long, default_value_t = 100)]
    pub episodes: usize,
    /// First collection seed (must be below 2^63; evaluation uses seeds from 2^63 on).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output safetensors file.
    #[arg(long)]
    pub out: PathBuf,
    /// Perturb the executed actions with smooth noise of this standard deviation (metres) and
    /// record the expert's clean actions (DART), so the demonstrations contain recoveries.
    /// 0 = unperturbed.
    #[arg(long, default_value_t = 0.0)]
    pub perturb_std: f64,
    /// Correlation time of the perturbation, seconds.
    #[arg(long, default_value_t = 0.5)]
    pub perturb_time: f64,
}

pub fn run(args: CollectArgs) -> anyhow::Result<ExitCode> {
    let bar = ProgressBar::new(args.episodes as u64);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} episodes ({elapsed})")?
            .progress_chars("=> "),
    );
    bar.set_message(format!("collect {}", args.task));
    // `collect_demos` validates the noise and treats std 0 as unperturbed.
    let noise = ActionNoise {
        std: args.perturb_std,
        correlation_time: args.perturb_time,
    };
    let (data, stats) = collect_demos(
        &args.task,
        args.episodes,
        args.seed,
        Some(noise),
        &mut |done| bar.set_position(done as u64),
    )?;
    bar.finish();
    data.save(&args.out)?;
    let size = std::fs::metadata(&args.out)?.len();
    let lengths: Vec<f64> = data
        .episode_ranges()
        .iter()
        .map(|r| r.len() as f64)
        .collect();
    println!(
        "wrote {}: {} episodes, {} steps (mean length {:.1}), obs_dim {}, action_dim {}, {} bytes; \
         expert failures skipped: {} of {}; sim step {:.2} us",
        args.out.display(),
        data.num_episodes(),
        data.len(),
        crate::eval::metrics::mean(&lengths),
        data.obs_dim,
        data.action_dim,
        size,
        stats.failed,
        stats.attempted,
        stats.sim_step_us
    );
    Ok(ExitCode::SUCCESS)
}
