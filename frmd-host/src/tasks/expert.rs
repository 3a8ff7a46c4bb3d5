//! The scripted experts of the path-following tasks (reach, avoid, insert): each plans one timed
//! path from the episode's first observation, then commands its points one control period apart.

use super::geom::{TimedPath, V2};
use super::{last_obs, TaskSpec, CONTROL_DT};
use crate::tasks::{Policy, PolicyInput};

/// How one task's expert plans its path (and, where the task needs it, corrects each command).
pub trait PathPlanner {
    /// The task the expert is for (its observation layout).
    const SPEC: &'static TaskSpec;
    /// The path of the episode with `seed`, from its first observation.
    fn plan(&self, seed: u64, obs: &[f32]) -> TimedPath;
    /// The command for the path's `target` given the current observation (default: `target`).
    fn command(&self, target: V2, _obs: &[f32]) -> V2 {
        target
    }
}

/// A scripted expert: a [`PathPlanner`], the episode's seed and its progress along the plan.
#[derive(Clone, Debug, Default)]
pub struct PathExpert<P> {
    planner: P,
    seed: u64,
    plan: Option<TimedPath>,
    step: usize,
}

impl<P> PathExpert<P> {
    pub fn new(planner: P) -> Self {
        Self {
            planner,
            seed: 0,
            plan: None,
            step: 0,
        }
    }
}

impl<P: PathPlanner> Policy for PathExpert<P> {
    fn name(&self) -> String {
        "expert".into()
    }

    fn reset(&mut self, seed: u64) {
        self.seed = seed;
        self.plan = None;
        self.step = 0;
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> anyhow::Result<Vec<Vec<f32>>> {
        let obs = last_obs(input, P::SPEC)?;
        let (planner, seed) = (&self.planner, self.seed);
        let plan = self.plan.get_or_insert_with(|| planner.plan(seed, obs));
        let target = plan.at(self.step as f64 * CONTROL_DT);
        self.step += 1;
        Ok(vec![planner.command(target, obs).to_f32().to_vec()])
    }
}
