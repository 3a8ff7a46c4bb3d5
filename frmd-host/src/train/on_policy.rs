//! On-policy distillation: the ODE-map term also runs on states the student itself visits,
//! labelled by the teacher (DAgger with the teacher as the expert). A one-step student that
//! strays from the demonstrations' states (on avoid it stalls short of the goal) is then trained
//! where it actually goes. The states come from recorded rollouts (`frmd collect --policy`, or a
//! simulator's own recorder: `--on-policy-data`) or, for the tasks frmd-host simulates, from
//! rounds run inside `frmd train student` (`--on-policy-rounds`): distill, roll the student out,
//! distill again from the teacher with those states.
use crate::data::policy_rollouts::{record_policy_rollouts, RolloutStats};
use crate::data::{Dataset, Normalization, WindowSet};
use crate::models::OwnedNetwork;
use crate::policy::float::{FloatPolicy, Sampler};
use anyhow::Context;
use frmd_core::sigma::SigmaConfig;
use std::path::PathBuf;

/// First collection seed of the rollouts of round `r` (1-based): `r * ROUND_SEED_STRIDE`, far
/// from the demonstrations' seeds (0 ..) and below the evaluation stream (2^63 ..).
pub const ROUND_SEED_STRIDE: u64 = 1_000_000;

/// Most on-policy rounds `frmd train student` runs.
pub const MAX_ON_POLICY_ROUNDS: usize = 5;

/// The windows of the recorded rollouts in `paths`, all of task `task`, normalized with the
/// teacher's `norm` (`None` when there are none).
pub fn recorded_windows(
    paths: &[PathBuf],
    task: &str,
    history: usize,
    horizon: usize,
    norm: &Normalization,
) -> anyhow::Result<Option<WindowSet>> {
    let mut all: Option<WindowSet> = None;
    for path in paths {
        let visited = Dataset::load(path)?;
        anyhow::ensure!(
            visited.task == task,
            "--on-policy-data {}: rollouts of task `{}`, the demonstrations are of `{task}`",
            path.display(),
            visited.task,
        );
        let windows = super::holdout::windows_in(&visited, history, horizon, norm)
            .with_context(|| format!("--on-policy-data {}", path.display()))?;
        add_windows(&mut all, windows)?;
    }
    Ok(all)
}

/// Adds `windows` to the on-policy set `all` (which starts as `None`: no on-policy states).
pub fn add_windows(all: &mut Option<WindowSet>, windows: WindowSet) -> anyhow::Result<()> {
    match all {
        Some(all) => all.append(&windows),
        None => {
            *all = Some(windows);
            Ok(())
        }
    }
}

/// Rolls the one-step `student` out for `episodes` episodes of `task` on the collection seeds
/// of `round` and returns the windows of the states it visited (normalized with `norm`).
pub fn student_round(
    student: OwnedNetwork,
    norm: &Normalization,
    sigma: SigmaConfig,
    task: &str,
    episodes: usize,
    round: usize,
) -> anyhow::Result<(WindowSet, RolloutStats)> {
    let (history, horizon) = {
        let cfg = student.net.config();
        (cfg.history, cfg.horizon)
    };
    let mut policy = FloatPolicy::new(student, norm.clone(), sigma, Sampler::Student { steps: 1 })?;
    let (data, stats) = record_policy_rollouts(
        task,
        &mut policy,
        history,
        episodes,
        round as u64 * ROUND_SEED_STRIDE,
        &format!("student of on-policy round {round}"),
        &mut |_| {},
    )?;
    let windows = super::holdout::windows_in(&data, history, horizon, norm)?;
    Ok((windows, stats))
}
