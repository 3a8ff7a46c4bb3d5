//! Training windows cut from demonstrations: the contract between datasets and training.

/// Per-dimension affine map from raw units to [-1, 1], fitted on training min/max.
/// Constant dimensions (max == min) map to 0.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Normalizer {
    pub min: Vec<f32>,
    pub max: Vec<f32>,
}

/// A batch-ready set of training windows, all in normalized units, stored row-major.
///
/// Row `i` holds: the observation history (`history` observations, oldest first), the last
/// commanded action before the chunk (ProDMP `y0`), its finite-difference rate in normalized
/// units per second (ProDMP `v0`), and the `horizon` actions that follow.
#[derive(Clone, Debug, Default)]
pub struct WindowSet {
    pub obs_dim: usize,
    pub action_dim: usize,
    /// Observation history length m.
    pub history: usize,
    /// Prediction horizon n (actions per chunk).
    pub horizon: usize,
    /// Control period of the demonstrations, seconds.
    pub dt: f32,
    /// [len, history * obs_dim]
    pub obs: Vec<f32>,
    /// [len, action_dim]
    pub prev_action: Vec<f32>,
    /// [len, action_dim], normalized units per second
    pub prev_rate: Vec<f32>,
    /// [len, horizon * action_dim], step-major (all DoFs of step 1, then step 2, ...)
    pub actions: Vec<f32>,
}

impl WindowSet {
    /// Number of windows.
    pub fn len(&self) -> usize {
        if self.action_dim == 0 {
            0
        } else {
            self.prev_action.len() / self.action_dim
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}
