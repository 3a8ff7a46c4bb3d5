//! Training windows cut from demonstrations: the contract between datasets and training.

use frmd_formats::calibration::CalibrationSet;
pub use frmd_formats::checkpoint::{Normalization, Normalizer};

/// Smallest normalizer range, raw units. MetaWorld demonstrations have observation dimensions
/// that barely move (a resting object's quaternion jitters by +-0.002: 12 dimensions of reach-v3
/// span under 1e-2, 7 of peg-insert-side-v3, 2 of hammer-v3); plain min/max would stretch that
/// jitter to [-1, 1]. Every dimension of the built-in tasks' demonstrations spans more than 0.09,
/// so their normalization is unchanged.
pub const MIN_NORM_RANGE: f32 = 1e-2;

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
        self.prev_action
            .len()
            .checked_div(self.action_dim)
            .unwrap_or(0)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Appends `other`'s windows (same shapes and period, else an error).
    pub fn append(&mut self, other: &WindowSet) -> anyhow::Result<()> {
        let shape = |w: &WindowSet| {
            (
                w.obs_dim,
                w.action_dim,
                w.history,
                w.horizon,
                w.dt.to_bits(),
            )
        };
        anyhow::ensure!(
            shape(self) == shape(other),
            "window sets differ in shape or period: (obs, action, history, horizon, dt bits) {:?} against {:?}",
            shape(self),
            shape(other)
        );
        self.obs.extend_from_slice(&other.obs);
        self.prev_action.extend_from_slice(&other.prev_action);
        self.prev_rate.extend_from_slice(&other.prev_rate);
        self.actions.extend_from_slice(&other.actions);
        Ok(())
    }

    /// Up to `rows` evenly spaced window conditions `[obs history, y0, v0]` (normalized) as
    /// calibration rows for the exporter, with a noise seed derived from `seed`. Training
    /// writes `CALIBRATION_ROWS` of them beside a student checkpoint
    /// (`frmd_formats::calibration`).
    pub fn calibration_rows(&self, rows: usize, seed: u64) -> CalibrationSet {
        let (obs_w, k) = (self.history * self.obs_dim, self.action_dim);
        let stride = (self.len() / rows.max(1)).max(1);
        let mut cond = Vec::new();
        for i in (0..self.len()).step_by(stride).take(rows) {
            cond.extend_from_slice(&self.obs[i * obs_w..(i + 1) * obs_w]);
            cond.extend_from_slice(&self.prev_action[i * k..(i + 1) * k]);
            cond.extend_from_slice(&self.prev_rate[i * k..(i + 1) * k]);
        }
        CalibrationSet {
            cond_dim: obs_w + 2 * k,
            cond,
            seed: seed ^ 0xca11_b4a7e,
        }
    }
}

/// Calibration rows written beside a student checkpoint.
pub const CALIBRATION_ROWS: usize = 256;

impl super::Dataset {
    /// Training windows of docs/design.md section 4 and the normalization fitted on this dataset.
    ///
    /// One window per step t of every episode: observations t-m+1..=t, the previous action
    /// a_{t-1} with rate (a_{t-1} - a_{t-2}) / dt, and actions a_t..a_{t+n-1}, all normalized.
    /// Episodes are padded by repeating the first observation before their start and the last
    /// action after their end. Before the start, the action is the dataset's
    /// [`ActionBeforeStart`](super::ActionBeforeStart): a_{-1} = a_{-2} = a_0 (`First`, matching the
    /// evaluator, whose experts start their commands at the initial end-effector position) or the
    /// zero action (`Zero`, displacement commands: what `frmd serve` resets with), rate 0 either
    /// way; why it matters is measured in docs/design.md, section 4.
    ///
    /// Normalizer ranges below `MIN_NORM_RANGE` are widened to it (exactly constant dimensions
    /// stay constant).
    pub fn windows(
        &self,
        history: usize,
        horizon: usize,
    ) -> anyhow::Result<(WindowSet, Normalization)> {
        anyhow::ensure!(
            history >= 1,
            "observation history must be at least 1, got {history}"
        );
        anyhow::ensure!(horizon >= 1, "horizon must be at least 1, got {horizon}");
        self.validate()?;
        let norm = Normalization {
            obs: Normalizer::fit(&self.obs, self.obs_dim).with_min_range(MIN_NORM_RANGE),
            action: Normalizer::fit(&self.action, self.action_dim).with_min_range(MIN_NORM_RANGE),
        };
        let mut obs = self.obs.clone();
        norm.obs.normalize(&mut obs);
        let mut action = self.action.clone();
        norm.action.normalize(&mut action);
        let (o, a) = (self.obs_dim, self.action_dim);
        let steps = self.len();
        let mut set = WindowSet {
            obs_dim: o,
            action_dim: a,
            history,
            horizon,
            dt: self.dt,
            obs: Vec::with_capacity(steps * history * o),
            prev_action: Vec::with_capacity(steps * a),
            prev_rate: Vec::with_capacity(steps * a),
            actions: Vec::with_capacity(steps * horizon * a),
        };
        let obs_row = |r: usize| &obs[r * o..(r + 1) * o];
        let action_row = |r: usize| &action[r * a..(r + 1) * a];
        let mut rest = vec![0.0; a];
        norm.action.normalize(&mut rest);
        for range in self.episode_ranges() {
            let (first, last) = (range.start, range.end - 1);
            // Row of in-episode index t (may be negative or past the end), padded.
            let row =
                |t: isize| (range.start as isize + t).clamp(first as isize, last as isize) as usize;
            for t in 0..range.len() as isize {
                for k in 0..history as isize {
                    set.obs
                        .extend_from_slice(obs_row(row(t + k + 1 - history as isize)));
                }
                let before = |t: isize| match self.action_before_start {
                    super::ActionBeforeStart::Zero if t < 0 => rest.as_slice(),
                    _ => action_row(row(t)),
                };
                let (prev, prev2) = (before(t - 1), before(t - 2));
                set.prev_action.extend_from_slice(prev);
                set.prev_rate
                    .extend(prev.iter().zip(prev2).map(|(p, q)| (p - q) / self.dt));
                for k in 0..horizon as isize {
                    set.actions.extend_from_slice(action_row(row(t + k)));
                }
            }
        }
        Ok((set, norm))
    }
}
