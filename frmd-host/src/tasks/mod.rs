//! Built-in planar manipulation tasks with scripted experts.
//!
//! Every task shares one end effector model (`point_mass`): a point mass that tracks a commanded
//! 2-D position target (metres) with a stiff critically damped loop. Actions are therefore
//! position targets `[x, y]`, and the ProDMP initial condition of a chunk is the last commanded
//! action. All tasks use a control period of 0.1 s and live in the square [-2, 2]^2 m, a scale at
//! which the experts' smooth paths have curvature below the 1 rad/m non-smoothness threshold of
//! docs/design.md section 6 almost everywhere, so that kinks stand out.
//!
//! | task   | difficulty  | what makes it hard                                               |
//! |--------|-------------|------------------------------------------------------------------|
//! | reach  | easy        | nothing: go to a goal                                            |
//! | avoid  | medium      | bimodal demos (pass the obstacle left or right at random)        |
//! | push   | medium/hard | contact: push a puck (rapier2d) onto a target                    |
//! | insert | hard        | approach, then a peg into a slot with 1 cm clearance per side    |
//!
//! Observations: the end effector's absolute position and velocity, then every other position
//! relative to it (push: the target relative to the puck), in the frame the experts plan in.
//! Measured on push (mlp-paper teacher, 40 episodes): with absolute positions the learned policy's
//! first push left the puck 5-48 degrees off the line to the target (the expert: 0.3 degrees),
//! because its approach has to end within about a centimetre of that line, and 100
//! demonstrations spread over the arena do not pin that geometry down everywhere
//! (docs/design.md, "Observations").
//!
//! Seeds: a task's layout is a pure function of the episode seed (see `rng::TaskRng`). The
//! evaluator uses seeds from a disjoint range (see `eval::EVAL_SEED_OFFSET`).
pub mod avoid;
pub(crate) mod expert;
pub(crate) mod geom;
pub(crate) mod insert;
pub(crate) mod point_mass;
mod policy;
pub(crate) mod push;
pub(crate) mod reach;
pub(crate) mod rng;

pub use policy::{Policy, PolicyInput};

/// Names accepted by [`make_task`], easiest first.
pub const TASK_NAMES: &[&str] = &["reach", "avoid", "push", "insert"];

/// Whether frmd-host simulates `task` (a dataset's `task` field), i.e. can evaluate it in closed
/// loop; datasets of other simulators (e.g. `metaworld/reach-v3`) train but evaluate elsewhere.
pub fn is_simulated(task: &str) -> bool {
    TASK_NAMES.contains(&task)
}

/// Control period of every built-in task, seconds.
pub const CONTROL_DT: f64 = 0.1;

/// What a piece of the layout is, for plots.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    Goal,
    Obstacle,
    Object,
    Wall,
}

/// A shape in the plane, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    Disc { center: [f64; 2], radius: f64 },
    Rect { min: [f64; 2], max: [f64; 2] },
}

/// One element of a task layout (for plots).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LayoutItem {
    pub role: Role,
    pub shape: Shape,
}

/// What identifies a task apart from its state: name, observation fields, episode length.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TaskSpec {
    /// Task name as in [`TASK_NAMES`].
    pub name: &'static str,
    /// Names (with units) of the observation fields, in order.
    pub obs_fields: &'static [&'static str],
    /// Episode length limit in control steps.
    pub max_steps: usize,
}

/// A closed-loop task: reset with a seed, observe, step with a position-target action.
pub trait Task {
    /// The task's name, observation fields and episode length.
    fn spec(&self) -> &'static TaskSpec;
    /// Task name as in [`TASK_NAMES`].
    fn name(&self) -> &'static str {
        self.spec().name
    }
    /// Names (with units) of the observation fields, in order; `obs_dim` is their count.
    fn obs_fields(&self) -> &'static [&'static str] {
        self.spec().obs_fields
    }
    fn obs_dim(&self) -> usize {
        self.obs_fields().len()
    }
    /// Action dimension: 2 (x, y position target in metres) for every built-in task.
    fn action_dim(&self) -> usize {
        2
    }
    /// Control period, seconds.
    fn dt(&self) -> f64 {
        CONTROL_DT
    }
    /// Episode length limit in control steps.
    fn max_steps(&self) -> usize {
        self.spec().max_steps
    }
    /// Starts a new episode whose layout is determined by `seed`.
    fn reset(&mut self, seed: u64);
    /// The current observation (`obs_dim` values, fields as in [`Task::obs_fields`]).
    fn observe(&self) -> Vec<f32>;
    /// Applies one action for one control period. Errors (and leaves the state unchanged) if
    /// the action has the wrong length or is not finite.
    fn step(&mut self, action: &[f32]) -> anyhow::Result<()>;
    /// The task's own success test on the current state.
    fn success(&self) -> bool;
    /// True when the episode has failed irrecoverably (e.g. a collision); ends the episode.
    fn failed(&self) -> bool {
        false
    }
    /// End-effector position, metres (for smoothness metrics and plots).
    fn ee_position(&self) -> [f64; 2];
    /// The scripted expert for this task, as a policy (deterministic given the episode seed).
    fn expert(&self) -> Box<dyn Policy>;
    /// The current layout (goals, obstacles, objects, walls), for plots.
    fn layout(&self) -> Vec<LayoutItem>;
}

/// Creates a task by name, at the layout of seed 0.
pub fn make_task(name: &str) -> anyhow::Result<Box<dyn Task>> {
    fn at_seed_zero(mut task: impl Task + 'static) -> Box<dyn Task> {
        task.reset(0);
        Box::new(task)
    }
    Ok(match name {
        "reach" => at_seed_zero(reach::Reach::default()),
        "avoid" => at_seed_zero(avoid::Avoid::default()),
        "push" => at_seed_zero(push::Push::default()),
        "insert" => at_seed_zero(insert::Insert::default()),
        other => anyhow::bail!(
            "unknown task {other:?}; known tasks: {}",
            TASK_NAMES.join(", ")
        ),
    })
}

/// The last observation of a policy input, checked against the task's observation size.
pub(crate) fn last_obs<'a>(
    input: &'a PolicyInput<'_>,
    spec: &TaskSpec,
) -> anyhow::Result<&'a [f32]> {
    let (task, dim) = (spec.name, spec.obs_fields.len());
    let obs = input
        .obs_history
        .last()
        .ok_or_else(|| anyhow::anyhow!("{task} expert: empty observation history"))?;
    anyhow::ensure!(
        obs.len() == dim,
        "{task} expert: observation has {} values, expected {dim}",
        obs.len()
    );
    Ok(obs)
}

/// The 2-D vector stored at `obs[index..index + 2]` (callers check the length first).
pub(crate) fn v2_at(obs: &[f32], index: usize) -> geom::V2 {
    geom::V2::new(f64::from(obs[index]), f64::from(obs[index + 1]))
}
