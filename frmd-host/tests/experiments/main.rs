//! Experiments: manual measurements behind the design choices, kept runnable. Every test here is
//! `#[ignore]`d; those on trained checkpoints do nothing unless their inputs are named in the
//! environment (the toy sweeps need none):
//!
//! - `FRMD_CKPT`: a checkpoint directory (teacher, student or DP, as the experiment says);
//! - `FRMD_DATA`: the demonstrations it was trained on;
//! - `FRMD_TASK`, `FRMD_STEPS`, `FRMD_SOLVER`, `FRMD_SEED`, `FRMD_EPISODE`, `FRMD_GOAL_DIMS`: as
//!   each experiment documents.
//!
//! Run one with its measurements printed, e.g.
//! `FRMD_CKPT=runs/reach/dp FRMD_DATA=reach.safetensors cargo test -p frmd-host --test experiments
//! start_travel -- --ignored --nocapture`. What they found is logged in `docs/experiments.md`.
#![allow(clippy::needless_range_loop)]

mod dp_baseline;
mod float_policy;
mod toy_sweeps;

/// What the experiments share.
mod prelude {
    pub use candle_core::Device;
    pub use frmd_host::diffusion::samplers::{gaussian, Solver};
    pub use frmd_host::models::{Condition, OwnedNetwork};
    pub use frmd_host::policy::float::FloatPolicy;
    pub use frmd_host::tasks::{Policy, PolicyInput};
    pub use std::path::Path;

    use frmd_host::data::{Dataset, WindowSet};
    use frmd_host::models::ModelConfig;
    use frmd_host::tasks::Task;

    /// The environment variable `name` parsed; `None` when it is unset or does not parse.
    pub fn env_value<T: std::str::FromStr>(name: &str) -> Option<T> {
        std::env::var(name).ok().and_then(|s| s.parse().ok())
    }

    /// The checkpoint directory and demonstrations named by `FRMD_CKPT` and `FRMD_DATA`; `None`
    /// (the experiment does nothing) when either variable is unset.
    pub fn diagnostic_inputs() -> Option<(String, Dataset)> {
        let (Ok(ckpt), Ok(data)) = (std::env::var("FRMD_CKPT"), std::env::var("FRMD_DATA")) else {
            return None;
        };
        let dataset = Dataset::load(Path::new(&data)).unwrap();
        Some((ckpt, dataset))
    }

    /// A checkpoint examined on its demonstrations: `FRMD_CKPT` loaded as a policy sampling with
    /// `steps` (`None`: its recorded default), its model, `FRMD_DATA`'s windows at its sizes and
    /// the data set itself; `None` when either variable is unset.
    pub fn diagnostic_policy(
        steps: Option<usize>,
    ) -> Option<(FloatPolicy, ModelConfig, Windows, Dataset)> {
        let (ckpt, ds) = diagnostic_inputs()?;
        let policy = FloatPolicy::load(Path::new(&ckpt), steps, None).unwrap();
        let cfg = policy.network().net.config().clone();
        let windows = Windows::new(&ds, &cfg);
        Some((policy, cfg, windows, ds))
    }

    /// Mean absolute difference of two equally long vectors.
    pub fn mean_abs_error(a: &[f32], b: &[f32]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| f64::from((x - y).abs()))
            .sum::<f64>()
            / a.len() as f64
    }

    /// How far a chunk's last action (its last `y0.len()` values) lies from `y0`.
    pub fn travel(chunk: &[f32], y0: &[f32]) -> f32 {
        chunk[chunk.len() - y0.len()..]
            .iter()
            .zip(y0)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f32>()
            .sqrt()
    }

    /// A data set's windows at a model's sizes, read one window at a time.
    pub struct Windows {
        pub set: WindowSet,
        /// Observation history width, action dimension, chunk length.
        pub obs_w: usize,
        pub k: usize,
        pub traj: usize,
    }

    impl Windows {
        pub fn new(ds: &Dataset, cfg: &ModelConfig) -> Self {
            let (set, _) = ds.windows(cfg.history, cfg.horizon).unwrap();
            Windows {
                set,
                obs_w: cfg.history * cfg.obs_dim,
                k: cfg.action_dim,
                traj: cfg.traj_dim(),
            }
        }

        pub fn obs(&self, i: usize) -> &[f32] {
            &self.set.obs[i * self.obs_w..(i + 1) * self.obs_w]
        }

        pub fn prev_action(&self, i: usize) -> &[f32] {
            &self.set.prev_action[i * self.k..(i + 1) * self.k]
        }

        pub fn prev_rate(&self, i: usize) -> &[f32] {
            &self.set.prev_rate[i * self.k..(i + 1) * self.k]
        }

        pub fn actions(&self, i: usize) -> &[f32] {
            &self.set.actions[i * self.traj..(i + 1) * self.traj]
        }

        /// About 200 windows spread evenly over the set.
        pub fn spread(&self) -> impl Iterator<Item = usize> {
            (0..self.set.len()).step_by(self.set.len() / 200 + 1)
        }

        /// The policy's normalized chunk for window `i`.
        pub fn sample(&self, policy: &mut FloatPolicy, i: usize) -> Vec<f32> {
            let (obs, prev, rate) = (self.obs(i), self.prev_action(i), self.prev_rate(i));
            policy.sample_normalized(obs, prev, rate).unwrap()
        }
    }

    /// What a policy is shown in closed loop: the observation history and the last action and
    /// its rate, advanced by the actions the task executes.
    pub struct ClosedLoop {
        pub hist: Vec<Vec<f32>>,
        pub prev: Vec<f32>,
        pub rate: Vec<f32>,
        dt: f32,
    }

    impl ClosedLoop {
        /// At `task`'s current state, at rest at the end effector.
        pub fn start(task: &dyn Task, history: usize, dt: f32) -> Self {
            let prev: Vec<f32> = task.ee_position().iter().map(|&v| v as f32).collect();
            ClosedLoop {
                hist: vec![task.observe(); history],
                rate: vec![0.0; prev.len()],
                prev,
                dt,
            }
        }

        /// The policy's next chunk.
        pub fn query(&self, policy: &mut dyn Policy) -> Vec<Vec<f32>> {
            let input = PolicyInput {
                obs_history: &self.hist,
                prev_action: &self.prev,
                prev_rate: &self.rate,
            };
            policy.act(&input).unwrap()
        }

        /// Executes the first `steps` actions of `chunk` on `task`.
        pub fn execute(&mut self, task: &mut dyn Task, chunk: &[Vec<f32>], steps: usize) {
            for act in chunk.iter().take(steps) {
                task.step(act).unwrap();
                for d in 0..self.prev.len() {
                    self.rate[d] = (act[d] - self.prev[d]) / self.dt;
                    self.prev[d] = act[d];
                }
                self.hist.remove(0);
                self.hist.push(task.observe());
            }
        }
    }
}
