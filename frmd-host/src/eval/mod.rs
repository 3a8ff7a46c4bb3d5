//! Closed-loop evaluation: any policy (expert, float models, the int8 core) against the built-in
//! tasks, with the metrics of docs/design.md section 6.
//!
//! Seeds: demonstrations are collected on seeds below [`EVAL_SEED_OFFSET`] (2^63; `frmd collect`
//! refuses others) and evaluation episode `i` runs on seed `EVAL_SEED_OFFSET + first_seed + i`,
//! so evaluation layouts never coincide with demonstration layouts by construction.
use crate::limits::{self, OptionError};
use crate::tasks::{make_task, Policy, PolicyInput, Task};
use serde::Serialize;
use std::collections::VecDeque;
use std::time::Instant;

pub mod metrics;
pub(crate) mod plot;

#[cfg(test)]
mod tests;

/// First seed of the evaluation stream; collection seeds are all below it.
pub const EVAL_SEED_OFFSET: u64 = 1 << 63;

/// Checks that `count` collection seeds from `seed` stay below the evaluation stream.
pub fn check_collection_seeds(seed: u64, count: usize) -> anyhow::Result<()> {
    anyhow::ensure!(
        seed.checked_add(count as u64).is_some_and(|end| end <= EVAL_SEED_OFFSET),
        "collection seeds must stay below 2^63 (the evaluation seed stream); seed {seed} is too large"
    );
    Ok(())
}

/// Settings of a closed-loop evaluation.
#[derive(Clone, Debug)]
pub struct EvalConfig {
    /// Number of episodes (docs/design.md asks for at least 50 per task and method).
    pub episodes: usize,
    /// Actions executed from each predicted chunk before the policy is queried again.
    pub exec_steps: usize,
    /// Observation history m handed to the policy.
    pub history: usize,
    /// Index of the first evaluation seed within the evaluation stream.
    pub first_seed: u64,
    /// Policy calls made (and discarded) before timing starts.
    pub warmup_calls: usize,
    /// Keep the executed end-effector paths and layouts of this many episodes (for plots).
    pub keep_paths: usize,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            episodes: 50,
            exec_steps: 8,
            history: 2,
            first_seed: 0,
            warmup_calls: 5,
            keep_paths: 0,
        }
    }
}

impl EvalConfig {
    /// Checks the counts against `crate::limits` and that every seed of the run stays in the
    /// evaluation stream (`first_seed + episodes <= 2^63`, no wrap into the collection seeds).
    pub fn validate(&self) -> Result<(), OptionError> {
        limits::count("episodes", self.episodes, 1, limits::MAX_EPISODES)?;
        limits::count("exec-steps", self.exec_steps, 1, limits::MAX_HORIZON)?;
        limits::count("history", self.history, 1, limits::MAX_HISTORY)?;
        limits::count("plot-episodes", self.keep_paths, 0, limits::MAX_EPISODES)?;
        let last = EVAL_SEED_OFFSET - self.episodes as u64;
        if self.first_seed > last {
            return Err(limits::range("first-seed", self.first_seed, format!("at most {last} (index within the evaluation stream: seed 2^63 + first seed + episode must stay below 2^64 for {} episodes)", self.episodes)));
        }
        Ok(())
    }

    /// [`Self::validate`] plus the policy's own limits: at most its horizon executed per chunk.
    pub fn validate_for(&self, policy: &dyn Policy) -> Result<(), OptionError> {
        self.validate()?;
        match policy.horizon() {
            Some(horizon) if self.exec_steps > horizon => Err(limits::range(
                "exec-steps",
                self.exec_steps,
                format!("at most the policy's horizon {horizon} (actions per chunk)"),
            )),
            _ => Ok(()),
        }
    }
}

/// The seed of evaluation episode `index` for a given `first_seed`.
pub fn eval_seed(first_seed: u64, index: usize) -> u64 {
    EVAL_SEED_OFFSET
        .wrapping_add(first_seed)
        .wrapping_add(index as u64)
}

/// What happened in one episode.
#[derive(Clone, Debug, Serialize)]
pub struct EpisodeRecord {
    pub seed: u64,
    pub success: bool,
    /// True when the task reported an irrecoverable failure (e.g. a collision).
    pub failed: bool,
    /// Control steps executed.
    pub length: usize,
    /// Non-smooth transitions of the executed end-effector path.
    pub non_smooth_ee: usize,
    /// Non-smooth transitions of the commanded action path.
    pub non_smooth_action: usize,
    /// RMS jerk of the end-effector path, m/s^3.
    pub rms_jerk: f64,
}

/// A kept path with the task layout at the start and end of its episode.
#[derive(Clone, Debug)]
pub struct KeptPath {
    pub seed: u64,
    pub success: bool,
    pub ee_path: Vec<[f64; 2]>,
    pub layout_start: Vec<crate::tasks::LayoutItem>,
    pub layout_end: Vec<crate::tasks::LayoutItem>,
}

/// Report of an evaluation run (serialized by `frmd eval --json`).
#[derive(Clone, Debug, Serialize)]
pub struct EvalReport {
    pub task: String,
    pub policy: String,
    pub episodes: usize,
    pub successes: usize,
    pub success_rate: f64,
    /// 95 % Wilson score interval of the success rate.
    pub success_ci95: [f64; 2],
    /// Mean episode length in control steps (all episodes).
    pub mean_length: f64,
    /// Mean episode length of successful episodes.
    pub mean_length_success: f64,
    pub exec_steps: usize,
    pub history: usize,
    pub first_seed: u64,
    /// Policy calls (chunks) timed.
    pub chunk_calls: usize,
    /// Wall time per chunk, microseconds.
    pub latency_us_median: f64,
    pub latency_us_p99: f64,
    /// Mean wall time of one simulation step, microseconds.
    pub sim_step_us: f64,
    /// Mean non-smooth transitions per episode (end-effector path, curvature > 1 rad/m).
    pub non_smooth_ee_mean: f64,
    /// Mean non-smooth transitions per episode of the commanded action path.
    pub non_smooth_action_mean: f64,
    /// Mean over episodes of the RMS jerk of the end-effector path, m/s^3.
    pub rms_jerk_mean: f64,
    /// Threads used by the process for the policy (from RAYON_NUM_THREADS, "unset" otherwise).
    pub threads: String,
    pub per_episode: Vec<EpisodeRecord>,
    #[serde(skip)]
    pub kept_paths: Vec<KeptPath>,
}

/// The human-readable summary of a report (what `frmd eval` prints).
impl std::fmt::Display for EvalReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "task {} / policy {} / {} episodes (exec {} of each chunk, history {})",
            self.task, self.policy, self.episodes, self.exec_steps, self.history
        )?;
        writeln!(
            f,
            "  success        {:.1} % ({} of {}), 95 % Wilson [{:.1}, {:.1}] %",
            100.0 * self.success_rate,
            self.successes,
            self.episodes,
            100.0 * self.success_ci95[0],
            100.0 * self.success_ci95[1]
        )?;
        writeln!(
            f,
            "  length         {:.1} steps (successful: {:.1})",
            self.mean_length, self.mean_length_success
        )?;
        writeln!(
            f,
            "  latency/chunk  median {:.1} us, p99 {:.1} us over {} calls (RAYON_NUM_THREADS={})",
            self.latency_us_median, self.latency_us_p99, self.chunk_calls, self.threads
        )?;
        writeln!(f, "  sim step       {:.2} us", self.sim_step_us)?;
        writeln!(
            f,
            "  non-smooth     {:.2} per episode (end effector), {:.2} (actions); RMS jerk {:.2} m/s^3",
            self.non_smooth_ee_mean, self.non_smooth_action_mean, self.rms_jerk_mean
        )
    }
}

/// The raw outcome of one rollout.
pub struct Rollout {
    pub success: bool,
    pub failed: bool,
    pub ee_path: Vec<[f64; 2]>,
    pub action_path: Vec<[f64; 2]>,
    /// Wall time of each policy call, seconds.
    pub latencies: Vec<f64>,
    /// Total wall time spent in `Task::step`, seconds, and the number of steps.
    pub step_time: f64,
    pub steps: usize,
}

/// Runs one episode of `task` on `seed` with `policy`, executing up to `exec_steps` actions of
/// each chunk. `on_step(obs, action)` sees every observation and the action then executed.
/// The episode ends at a failure, at the task's step limit, or `after_success` steps after the
/// first success (0: at it; demonstration collection records the expert settling at the goal
/// with more); `success` says whether the success test held at some step.
pub fn rollout(
    task: &mut dyn Task,
    policy: &mut dyn Policy,
    seed: u64,
    exec_steps: usize,
    history: usize,
    after_success: usize,
    on_step: &mut dyn FnMut(&[f32], &[f32]),
) -> anyhow::Result<Rollout> {
    anyhow::ensure!(exec_steps >= 1, "exec_steps must be at least 1");
    anyhow::ensure!(history >= 1, "observation history must be at least 1");
    task.reset(seed);
    policy.reset(seed);
    let dt = task.dt();
    let action_dim = task.action_dim();
    let obs = task.observe();
    let mut obs_history: VecDeque<Vec<f32>> = std::iter::repeat_n(obs, history).collect();
    let ee0 = task.ee_position();
    let mut prev_action: Vec<f32> = ee0.iter().map(|&x| x as f32).collect();
    prev_action.resize(action_dim, 0.0);
    let mut prev_rate = vec![0.0f32; action_dim];
    let mut out = Rollout {
        success: false,
        failed: false,
        ee_path: vec![ee0],
        action_path: Vec::new(),
        latencies: Vec::new(),
        step_time: 0.0,
        steps: 0,
    };
    let max_steps = task.max_steps();
    let mut first_success: Option<usize> = None;
    'episode: while out.steps < max_steps || first_success.is_some() {
        let hist: Vec<Vec<f32>> = obs_history.iter().cloned().collect();
        let input = PolicyInput {
            obs_history: &hist,
            prev_action: &prev_action,
            prev_rate: &prev_rate,
        };
        let started = Instant::now();
        let chunk = policy.act(&input)?;
        out.latencies.push(started.elapsed().as_secs_f64());
        anyhow::ensure!(
            !chunk.is_empty(),
            "policy {} returned an empty chunk",
            policy.name()
        );
        for action in chunk.iter().take(exec_steps) {
            anyhow::ensure!(
                action.len() == action_dim,
                "policy {} returned an action with {} values, task {} expects {action_dim}",
                policy.name(),
                action.len(),
                task.name()
            );
            let observed = obs_history.back().cloned().unwrap_or_default();
            on_step(&observed, action);
            let started = Instant::now();
            task.step(action)?;
            out.step_time += started.elapsed().as_secs_f64();
            out.steps += 1;
            out.ee_path.push(task.ee_position());
            out.action_path.push([
                f64::from(action[0]),
                f64::from(action.get(1).copied().unwrap_or(0.0)),
            ]);
            for ((rate, prev), &a) in prev_rate
                .iter_mut()
                .zip(prev_action.iter_mut())
                .zip(action.iter())
            {
                *rate = ((f64::from(a) - f64::from(*prev)) / dt) as f32;
                *prev = a;
            }
            obs_history.pop_front();
            obs_history.push_back(task.observe());
            if first_success.is_none() && task.success() {
                first_success = Some(out.steps);
            }
            out.success = first_success.is_some();
            out.failed = task.failed();
            let done = match first_success {
                Some(at) => out.steps >= at + after_success,
                None => out.steps >= max_steps,
            };
            if out.failed || done {
                break 'episode;
            }
        }
    }
    Ok(out)
}

fn threads_note() -> String {
    std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "unset".into())
}

/// Runs `cfg.episodes` closed-loop episodes of `task` on the evaluation seed stream.
pub fn run_episodes(
    task: &str,
    policy: &mut dyn Policy,
    cfg: &EvalConfig,
) -> anyhow::Result<EvalReport> {
    run_episodes_with_progress(task, policy, cfg, &mut |_| {})
}

/// [`run_episodes`] with progress over episodes on stderr (`crate::progress`).
pub fn evaluate(
    task: &str,
    policy: &mut dyn Policy,
    cfg: &EvalConfig,
) -> anyhow::Result<EvalReport> {
    let mut progress = crate::progress::Progress::new(
        &format!("eval {} on {task}", policy.name()),
        cfg.episodes as u64,
        "episode",
    );
    let report = run_episodes_with_progress(task, policy, cfg, &mut |done| {
        progress.update(done as u64, "")
    })?;
    progress.finish();
    Ok(report)
}

/// [`run_episodes`] with a callback after each finished episode (for progress bars).
pub fn run_episodes_with_progress(
    task_name: &str,
    policy: &mut dyn Policy,
    cfg: &EvalConfig,
    progress: &mut dyn FnMut(usize),
) -> anyhow::Result<EvalReport> {
    cfg.validate_for(policy)?;
    let mut task = make_task(task_name)?;
    let dt = task.dt();
    if cfg.warmup_calls > 0 {
        let seed = eval_seed(cfg.first_seed, 0);
        task.reset(seed);
        policy.reset(seed);
        let obs = task.observe();
        let hist = vec![obs; cfg.history.max(1)];
        let prev: Vec<f32> = task.ee_position().iter().map(|&x| x as f32).collect();
        let rate = vec![0.0f32; prev.len()];
        for _ in 0..cfg.warmup_calls {
            policy.act(&PolicyInput {
                obs_history: &hist,
                prev_action: &prev,
                prev_rate: &rate,
            })?;
        }
    }
    let mut records = Vec::with_capacity(cfg.episodes);
    let mut latencies = Vec::new();
    let (mut step_time, mut steps) = (0.0, 0usize);
    let mut kept_paths = Vec::new();
    for index in 0..cfg.episodes {
        let seed = eval_seed(cfg.first_seed, index);
        task.reset(seed);
        let layout_start = task.layout();
        let run = rollout(
            task.as_mut(),
            policy,
            seed,
            cfg.exec_steps,
            cfg.history,
            0,
            &mut |_, _| {},
        )?;
        latencies.extend_from_slice(&run.latencies);
        step_time += run.step_time;
        steps += run.steps;
        records.push(EpisodeRecord {
            seed,
            success: run.success,
            failed: run.failed,
            length: run.steps,
            non_smooth_ee: metrics::non_smooth_transitions(&run.ee_path),
            non_smooth_action: metrics::non_smooth_transitions(&run.action_path),
            rms_jerk: metrics::rms_jerk(&run.ee_path, dt),
        });
        if kept_paths.len() < cfg.keep_paths {
            kept_paths.push(KeptPath {
                seed,
                success: run.success,
                ee_path: run.ee_path,
                layout_start,
                layout_end: task.layout(),
            });
        }
        progress(index + 1);
    }
    let successes = records.iter().filter(|r| r.success).count();
    let lengths: Vec<f64> = records.iter().map(|r| r.length as f64).collect();
    let success_lengths: Vec<f64> = records
        .iter()
        .filter(|r| r.success)
        .map(|r| r.length as f64)
        .collect();
    let micros: Vec<f64> = latencies.iter().map(|s| s * 1e6).collect();
    Ok(EvalReport {
        task: task_name.to_string(),
        policy: policy.name(),
        episodes: records.len(),
        successes,
        success_rate: successes as f64 / records.len() as f64,
        success_ci95: metrics::wilson_interval(successes, records.len()),
        mean_length: metrics::mean(&lengths),
        mean_length_success: metrics::mean(&success_lengths),
        exec_steps: cfg.exec_steps,
        history: cfg.history,
        first_seed: cfg.first_seed,
        chunk_calls: micros.len(),
        latency_us_median: metrics::quantile(&micros, 0.5),
        latency_us_p99: metrics::quantile(&micros, 0.99),
        sim_step_us: if steps > 0 {
            step_time / steps as f64 * 1e6
        } else {
            0.0
        },
        non_smooth_ee_mean: metrics::mean(
            &records
                .iter()
                .map(|r| r.non_smooth_ee as f64)
                .collect::<Vec<_>>(),
        ),
        non_smooth_action_mean: metrics::mean(
            &records
                .iter()
                .map(|r| r.non_smooth_action as f64)
                .collect::<Vec<_>>(),
        ),
        rms_jerk_mean: metrics::mean(&records.iter().map(|r| r.rms_jerk).collect::<Vec<_>>()),
        threads: threads_note(),
        per_episode: records,
        kept_paths,
    })
}

/// The task's scripted expert as a policy (`frmd eval --policy expert`).
pub fn expert_policy(task: &str) -> anyhow::Result<Box<dyn Policy>> {
    Ok(make_task(task)?.expert())
}
