//! The controller interface: what every policy implements, the tasks' scripted experts as well as
//! the learned float and int8 policies, so that evaluation and data collection can run any of them.

/// What a policy sees when asked for a chunk, all in raw (robot) units.
pub struct PolicyInput<'a> {
    /// The last `m` observations, oldest first (padded with the first one at episode start).
    pub obs_history: &'a [Vec<f32>],
    /// The last commanded action (at episode start: the initial end-effector position).
    pub prev_action: &'a [f32],
    /// Finite-difference rate of the commanded action, units per second.
    pub prev_rate: &'a [f32],
}

/// A chunking policy: maps the current input to a sequence of future actions.
pub trait Policy {
    /// Short name for reports ("expert", "student-1", "int8", ...).
    fn name(&self) -> String;
    /// Called at the start of each episode with the episode's seed (for noise streams).
    fn reset(&mut self, seed: u64);
    /// Returns a chunk of actions in raw units, at least one. The evaluator executes up to its
    /// configured number of steps of it and then asks again.
    fn act(&mut self, input: &PolicyInput<'_>) -> anyhow::Result<Vec<Vec<f32>>>;
    /// Actions per chunk when fixed (learned policies: the model's horizon); `None` for
    /// policies whose chunks vary (the scripted experts).
    fn horizon(&self) -> Option<usize> {
        None
    }
}
