//! Rollouts of a trained policy recorded as a dataset: the states the policy itself visits, for
//! on-policy distillation (`frmd train student --on-policy-data`, where the teacher labels them).
//! Unlike demonstrations, every episode is kept, successful or not (the states where a policy
//! stalls are the ones worth labelling), and the recorded actions are the executed ones, so the
//! windows' initial conditions are what the policy sees when it is deployed.
use super::{ActionBeforeStart, Dataset};
use crate::eval::{check_collection_seeds, rollout, EvalConfig};
use crate::tasks::{make_task, Policy, Task};

/// Counts from a recording run.
#[derive(Clone, Debug, Default)]
pub struct RolloutStats {
    /// Episodes in which the task's success test held at some step.
    pub successes: usize,
}

/// Rolls `policy` (which takes `history` observations) out for `episodes` episodes of
/// `task_name` on collection seeds `seed`, `seed + 1`, ... (below the evaluation stream),
/// executing [`EvalConfig`]'s default actions per chunk, and records every step. `source` says
/// in the dataset which policy it was.
pub fn record_policy_rollouts(
    task_name: &str,
    policy: &mut dyn Policy,
    history: usize,
    episodes: usize,
    seed: u64,
    source: &str,
    progress: &mut dyn FnMut(usize),
) -> anyhow::Result<(Dataset, RolloutStats)> {
    anyhow::ensure!(episodes >= 1, "at least one episode must be recorded");
    check_collection_seeds(seed, episodes)?;
    let mut task = make_task(task_name)?;
    let exec_steps = EvalConfig::default().exec_steps;
    let mut data = recording_of(task.as_ref(), task_name);
    let mut stats = RolloutStats::default();
    for episode in 0..episodes {
        let run = rollout(
            task.as_mut(),
            policy,
            seed + episode as u64,
            exec_steps,
            history,
            0,
            &mut |o, executed| {
                data.obs.extend_from_slice(o);
                data.action.extend_from_slice(executed);
            },
        )?;
        stats.successes += run.success as usize;
        data.episode_ends
            .push((data.action.len() / data.action_dim) as i64);
        progress(episode + 1);
    }
    data.source = format!(
        "frmd collect --policy: {source}, seeds {seed}..{}, {} of {episodes} episodes successful, every episode kept",
        seed + episodes as u64,
        stats.successes
    );
    Ok((data, stats))
}

/// An empty dataset of a built-in task's shapes and control period, for a recorder to append
/// episodes to (the first action holds before the start, as the tasks' experts begin).
pub(super) fn recording_of(task: &dyn Task, task_name: &str) -> Dataset {
    Dataset {
        obs: Vec::new(),
        action: Vec::new(),
        episode_ends: Vec::new(),
        obs_dim: task.obs_dim(),
        action_dim: task.action_dim(),
        task: task_name.to_string(),
        dt: task.dt() as f32,
        source: String::new(),
        action_before_start: ActionBeforeStart::First,
        extra: Default::default(),
    }
}
