//! Demonstration collection: runs a task's scripted expert and gathers successful episodes.
use super::perturb::{ActionNoise, PerturbedExpert};
use super::policy_rollouts::{record_policy_rollouts, recording_of};
use super::Dataset;
use crate::eval::{check_collection_seeds, rollout, EVAL_SEED_OFFSET};
use crate::limits::{self, OptionError};
use crate::policy::float::FloatPolicy;
use crate::progress::Progress;
use crate::tasks::{make_task, Policy};
use std::path::PathBuf;

/// A collection run (`frmd collect`): `episodes` successful expert demonstrations of `task` on
/// seeds from `seed`, perturbed by `noise` (std 0: plain), written to `out`.
#[derive(Clone, Debug, PartialEq)]
pub struct CollectConfig {
    pub task: String,
    pub episodes: usize,
    /// First collection seed (below 2^63; evaluation uses seeds from 2^63 on).
    pub seed: u64,
    /// Output safetensors file (must not exist unless `force`).
    pub out: PathBuf,
    /// Replace an existing `out`.
    pub force: bool,
    pub noise: ActionNoise,
    /// Expert steps recorded after each episode's first success (0: the demonstration ends
    /// there), so the data shows the expert settling at the goal.
    pub after_success: usize,
    /// Roll out this trained policy instead of the scripted expert and record every episode
    /// (on-policy states for `frmd train student --on-policy-data`); the perturbation and
    /// `after_success` do not apply.
    pub policy: Option<PolicySource>,
}

/// A trained policy to record rollouts of (`frmd collect --policy`).
#[derive(Clone, Debug, PartialEq)]
pub struct PolicySource {
    /// Checkpoint directory.
    pub ckpt: PathBuf,
    /// Sampling steps (`None`: the checkpoint role's default, one for a student).
    pub steps: Option<usize>,
}

/// The recipe's perturbation of the executed actions during collection, metres (DART; teacher
/// success with plain -> perturbed demonstrations: avoid 60 -> 73 %, insert 38.5 -> 83.5 %,
/// docs/design.md section 4).
pub const RECIPE_PERTURB_STD: f64 = 0.02;

/// Most steps `--after-success` may add to an episode.
pub const MAX_AFTER_SUCCESS: usize = 1000;

impl CollectConfig {
    /// The counts, the seeds (below the evaluation stream) and the noise, before any work.
    pub fn validate(&self) -> Result<(), OptionError> {
        limits::count("episodes", self.episodes, 1, limits::MAX_EPISODES)?;
        let attempts = max_attempts(self.episodes, self.noise.std > 0.0) as u64;
        let last = EVAL_SEED_OFFSET - attempts;
        if self.seed > last {
            return Err(limits::range(
                "seed",
                self.seed,
                format!("at most {last} (collection seeds stay below 2^63, the evaluation stream)"),
            ));
        }
        limits::count("after-success", self.after_success, 0, MAX_AFTER_SUCCESS)?;
        if self.policy.is_some() && self.after_success > 0 {
            return Err(limits::range(
                "after-success",
                self.after_success,
                "0 with --policy (a recorded policy episode ends at its first success)",
            ));
        }
        limits::non_negative("perturb-std", self.noise.std)?;
        limits::positive("perturb-time", self.noise.correlation_time)
    }
}

impl Default for CollectConfig {
    /// 100 demonstrations from seed 0, executed actions perturbed with std
    /// [`RECIPE_PERTURB_STD`], ending at the first success (`after_success` 0: 20 measured no
    /// better over three avoid seeds, docs/experiments.md); no task or file named.
    fn default() -> Self {
        let noise = ActionNoise {
            std: RECIPE_PERTURB_STD,
            ..ActionNoise::default()
        };
        CollectConfig {
            task: String::new(),
            episodes: 100,
            seed: 0,
            out: PathBuf::new(),
            force: false,
            noise,
            after_success: 0,
            policy: None,
        }
    }
}

/// What a collection run wrote.
#[derive(Clone, Debug)]
pub struct Collected {
    pub episodes: usize,
    pub steps: usize,
    pub mean_length: f64,
    pub obs_dim: usize,
    pub action_dim: usize,
    /// Size of the written file.
    pub bytes: u64,
    pub stats: CollectStats,
}

/// Collects the demonstrations of `cfg` (with progress on stderr) and writes them to `cfg.out`.
pub fn collect_to_file(cfg: &CollectConfig) -> anyhow::Result<Collected> {
    cfg.validate()?;
    make_task(&cfg.task)?;
    frmd_formats::artifact::check_output_file(&cfg.out, "--out", cfg.force, &[])?;
    if let Some(source) = &cfg.policy {
        return record_to_file(cfg, source);
    }
    let mut progress = Progress::new(
        &format!("collect {}", cfg.task),
        cfg.episodes as u64,
        "episode",
    );
    // `collect_demos` validates the noise and treats std 0 as unperturbed.
    let (data, stats) = collect_demos(
        &cfg.task,
        cfg.episodes,
        cfg.seed,
        Some(cfg.noise),
        cfg.after_success,
        &mut |done| progress.update(done as u64, ""),
    )?;
    progress.finish();
    summarize(cfg, &data, stats)
}

/// Rolls out the policy of `source` for `cfg` and writes the recording.
fn record_to_file(cfg: &CollectConfig, source: &PolicySource) -> anyhow::Result<Collected> {
    let meta = crate::checkpoint::CheckpointMeta::read(&source.ckpt)?;
    if meta.dataset.task != cfg.task {
        anyhow::bail!(
            "--policy {}: the checkpoint was trained on task `{}`, not `{}`",
            source.ckpt.display(),
            meta.dataset.task,
            cfg.task
        );
    }
    let mut policy = FloatPolicy::load(&source.ckpt, source.steps, None)?;
    let history = policy.input_sizes().2;
    let mut progress = Progress::new(
        &format!("record {} ({})", cfg.task, source.ckpt.display()),
        cfg.episodes as u64,
        "episode",
    );
    let (data, rollouts) = record_policy_rollouts(
        &cfg.task,
        &mut policy,
        history,
        cfg.episodes,
        cfg.seed,
        &format!("{} {}", meta.role, source.ckpt.display()),
        &mut |done| progress.update(done as u64, ""),
    )?;
    progress.finish();
    let stats = CollectStats {
        attempted: cfg.episodes,
        failed: cfg.episodes - rollouts.successes,
        sim_step_us: 0.0,
    };
    summarize(cfg, &data, stats)
}

/// Writes `data` to `cfg.out` and counts what was written.
fn summarize(
    cfg: &CollectConfig,
    data: &Dataset,
    stats: CollectStats,
) -> anyhow::Result<Collected> {
    data.save(&cfg.out)?;
    let lengths: Vec<f64> = data
        .episode_ranges()
        .iter()
        .map(|r| r.len() as f64)
        .collect();
    Ok(Collected {
        episodes: data.num_episodes(),
        steps: data.len(),
        mean_length: crate::eval::metrics::mean(&lengths),
        obs_dim: data.obs_dim,
        action_dim: data.action_dim,
        bytes: std::fs::metadata(&cfg.out)?.len(),
        stats,
    })
}

/// Counts from a collection run.
#[derive(Clone, Debug, Default)]
pub struct CollectStats {
    /// Episodes attempted (seeds used), successful or not.
    pub attempted: usize,
    /// Expert episodes that failed and were left out of the dataset.
    pub failed: usize,
    /// Mean wall time of one simulation step, microseconds.
    pub sim_step_us: f64,
}

/// Seeds a collection of `episodes` may use: `episodes + 10 + episodes / 5`, three times as many
/// when the executed actions are perturbed (more perturbed episodes fail).
fn max_attempts(episodes: usize, perturbed: bool) -> usize {
    let base = episodes + 10 + episodes / 5;
    if perturbed {
        3 * base
    } else {
        base
    }
}

/// Collects `episodes` successful expert demonstrations of `task` on seeds `seed`, `seed + 1`, ...
/// Failed expert episodes are skipped; at most `episodes + 10 + episodes / 5` seeds are tried,
/// three times as many with `noise` (see `super::perturb`: the executed actions are perturbed,
/// the recorded ones are the expert's). Seeds must stay below the evaluation stream
/// ([`EVAL_SEED_OFFSET`]). Each episode goes on for `after_success` expert steps after its
/// first success (an episode that fails in them is skipped too).
pub fn collect_demos(
    task_name: &str,
    episodes: usize,
    seed: u64,
    noise: Option<ActionNoise>,
    after_success: usize,
    progress: &mut dyn FnMut(usize),
) -> anyhow::Result<(Dataset, CollectStats)> {
    anyhow::ensure!(episodes >= 1, "at least one episode must be collected");
    if let Some(noise) = &noise {
        noise.validate()?;
    }
    let noise = noise.filter(|n| n.std > 0.0);
    let max_attempts = max_attempts(episodes, noise.is_some());
    check_collection_seeds(seed, max_attempts)?;
    let mut task = make_task(task_name)?;
    let (mut expert, clean_action): (Box<dyn Policy>, _) = match noise {
        Some(noise) => {
            let (wrapped, clean) =
                PerturbedExpert::new(task.expert(), noise, task.dt(), task.action_dim());
            (Box::new(wrapped), Some(clean))
        }
        None => (task.expert(), None),
    };
    let mut data = recording_of(task.as_ref(), task_name);
    let mut stats = CollectStats::default();
    let (mut step_time, mut steps) = (0.0, 0usize);
    while data.episode_ends.len() < episodes {
        anyhow::ensure!(
            stats.attempted < max_attempts,
            "the {task_name} expert failed {} of {} episodes; giving up",
            stats.failed,
            stats.attempted
        );
        let episode_seed = seed + stats.attempted as u64;
        stats.attempted += 1;
        let (mut obs, mut action) = (Vec::new(), Vec::new());
        let run = rollout(
            task.as_mut(),
            expert.as_mut(),
            episode_seed,
            1,
            1,
            after_success,
            &mut |o, executed| {
                obs.extend_from_slice(o);
                match &clean_action {
                    Some(clean) => action.extend_from_slice(&clean.borrow()),
                    None => action.extend_from_slice(executed),
                }
            },
        )?;
        step_time += run.step_time;
        steps += run.steps;
        if !run.success || run.failed {
            stats.failed += 1;
            continue;
        }
        data.obs.extend_from_slice(&obs);
        data.action.extend_from_slice(&action);
        data.episode_ends
            .push((data.action.len() / data.action_dim) as i64);
        progress(data.episode_ends.len());
    }
    stats.sim_step_us = if steps > 0 {
        step_time / steps as f64 * 1e6
    } else {
        0.0
    };
    let perturbation = match noise {
        Some(n) => format!(
            ", executed actions perturbed (Ornstein-Uhlenbeck, std {} m, correlation {} s)",
            n.std, n.correlation_time
        ),
        None => String::new(),
    };
    let settling = if after_success > 0 {
        format!(", {after_success} steps recorded after the first success")
    } else {
        String::new()
    };
    data.source = format!(
        "frmd collect: scripted expert, seeds {seed}..{} ({} failed episodes skipped){perturbation}{settling}",
        seed + stats.attempted as u64,
        stats.failed
    );
    Ok((data, stats))
}
