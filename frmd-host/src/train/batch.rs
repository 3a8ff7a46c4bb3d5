//! Random training batches drawn from a [`WindowSet`] with the seeded generator.
use crate::data::windows::WindowSet;
use crate::models::{Condition, ModelConfig};
use crate::rng::HostRng;
use anyhow::bail;
use candle_core::{Device, Tensor};
use serde::{Deserialize, Serialize};

/// One batch: clean trajectories and their condition.
pub struct Batch {
    /// [B, n k], normalized, step-major.
    pub x0: Tensor,
    pub cond: Condition,
}

/// Checks that a window set matches a model config.
pub fn check_windows(windows: &WindowSet, cfg: &ModelConfig) -> anyhow::Result<()> {
    let len = windows.len();
    if len == 0 {
        bail!("no training windows");
    }
    if windows.obs_dim != cfg.obs_dim
        || windows.action_dim != cfg.action_dim
        || windows.history != cfg.history
        || windows.horizon != cfg.horizon
    {
        bail!(
            "windows (obs {}, action {}, history {}, horizon {}) do not match the model (obs {}, action {}, history {}, horizon {})",
            windows.obs_dim, windows.action_dim, windows.history, windows.horizon, cfg.obs_dim, cfg.action_dim, cfg.history, cfg.horizon
        );
    }
    let ok = windows.obs.len() == len * cfg.history * cfg.obs_dim
        && windows.prev_rate.len() == len * cfg.action_dim
        && windows.actions.len() == len * cfg.traj_dim();
    if !ok {
        bail!("window set arrays have inconsistent lengths for {len} windows");
    }
    Ok(())
}

/// Gathers the windows at `indices` into a batch.
pub fn gather(
    windows: &WindowSet,
    cfg: &ModelConfig,
    indices: &[usize],
    device: &Device,
) -> anyhow::Result<Batch> {
    let obs_w = cfg.history * cfg.obs_dim;
    let (k, traj) = (cfg.action_dim, cfg.traj_dim());
    let mut obs = Vec::with_capacity(indices.len() * obs_w);
    let mut y0 = Vec::with_capacity(indices.len() * k);
    let mut v0 = Vec::with_capacity(indices.len() * k);
    let mut x0 = Vec::with_capacity(indices.len() * traj);
    for &i in indices {
        obs.extend_from_slice(&windows.obs[i * obs_w..(i + 1) * obs_w]);
        y0.extend_from_slice(&windows.prev_action[i * k..(i + 1) * k]);
        v0.extend_from_slice(&windows.prev_rate[i * k..(i + 1) * k]);
        x0.extend_from_slice(&windows.actions[i * traj..(i + 1) * traj]);
    }
    let cond = Condition::from_slices(cfg, &obs, &y0, &v0, device)?;
    Ok(Batch {
        x0: Tensor::from_vec(x0, (indices.len(), traj), device)?,
        cond,
    })
}

/// A batch of `size` windows drawn uniformly with replacement.
pub fn sample(
    windows: &WindowSet,
    cfg: &ModelConfig,
    size: usize,
    rng: &mut HostRng,
    device: &Device,
) -> anyhow::Result<Batch> {
    let indices: Vec<usize> = (0..size).map(|_| rng.below(windows.len())).collect();
    gather(windows, cfg, &indices, device)
}

/// Perturbation of the chunk's initial condition (y0, v0) during training, normalized units.
///
/// The demonstrations never show a chunk that starts off the demonstrated path, yet in closed
/// loop every chunk starts from the previous chunk's last executed command and rate, so small
/// errors feed back through the ProDMP boundary conditions. With probability `prob` a window's
/// y0 and v0 (both the decoder's boundary condition and the network's features) get Gaussian
/// offsets of standard deviation `y0_std` and `v0_std` (per second) while the target stays the
/// demonstrated chunk: the model learns chunks that start from the perturbed state and blend
/// back onto the demonstration (the ProDMP fixes the start, so the first steps cannot match).
///
/// Measured on insert (8k steps, prob 0.5, y0 std 0.01, v0 std 0.1/s): held-out chunk error
/// 9.9 vs 9.5 mm (8.5 vs 8.3 mm with the output-layer lr x10), success 20 % either way with
/// x10 and 5 % vs 5 % when re-planning every 2 steps: no measurable gain, off by default.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CondAugment {
    pub prob: f64,
    pub y0_std: f64,
    pub v0_std: f64,
    /// Standard deviation of one offset added to every observation frame of a perturbed window
    /// (normalized units; the same offset for each frame of the history, so frame differences
    /// stay). For a student the targets come from the teacher at the perturbed input, so this
    /// widens the inputs the teacher is imitated on (docs/experiments.md).
    #[serde(default)]
    pub obs_std: f64,
}

impl CondAugment {
    /// No perturbation.
    pub const NONE: CondAugment = CondAugment {
        prob: 0.0,
        y0_std: 0.0,
        v0_std: 0.0,
        obs_std: 0.0,
    };

    pub fn is_active(&self) -> bool {
        self.prob > 0.0 && (self.y0_std > 0.0 || self.v0_std > 0.0 || self.obs_std > 0.0)
    }
}

impl Default for CondAugment {
    fn default() -> Self {
        CondAugment::NONE
    }
}

/// [`sample`] with the initial-condition perturbation `augment` applied.
pub fn sample_augmented(
    windows: &WindowSet,
    cfg: &ModelConfig,
    size: usize,
    augment: &CondAugment,
    rng: &mut HostRng,
    device: &Device,
) -> anyhow::Result<Batch> {
    if !augment.is_active() {
        return sample(windows, cfg, size, rng, device);
    }
    let indices: Vec<usize> = (0..size).map(|_| rng.below(windows.len())).collect();
    let mut perturbed = WindowSet {
        obs_dim: windows.obs_dim,
        action_dim: windows.action_dim,
        history: windows.history,
        horizon: windows.horizon,
        dt: windows.dt,
        obs: Vec::with_capacity(size * cfg.history * cfg.obs_dim),
        prev_action: Vec::with_capacity(size * cfg.action_dim),
        prev_rate: Vec::with_capacity(size * cfg.action_dim),
        actions: Vec::with_capacity(size * cfg.traj_dim()),
    };
    let (obs_w, k, traj) = (cfg.history * cfg.obs_dim, cfg.action_dim, cfg.traj_dim());
    for &i in &indices {
        perturbed
            .obs
            .extend_from_slice(&windows.obs[i * obs_w..(i + 1) * obs_w]);
        perturbed
            .actions
            .extend_from_slice(&windows.actions[i * traj..(i + 1) * traj]);
        let hit = rng.uniform() < augment.prob;
        for d in 0..k {
            let (dy, dv) = if hit {
                (augment.y0_std * rng.normal(), augment.v0_std * rng.normal())
            } else {
                (0.0, 0.0)
            };
            perturbed
                .prev_action
                .push(windows.prev_action[i * k + d] + dy as f32);
            perturbed
                .prev_rate
                .push(windows.prev_rate[i * k + d] + dv as f32);
        }
        if hit && augment.obs_std > 0.0 {
            let offsets: Vec<f32> = (0..cfg.obs_dim)
                .map(|_| (augment.obs_std * rng.normal()) as f32)
                .collect();
            let start = perturbed.obs.len() - obs_w;
            for (j, v) in perturbed.obs[start..].iter_mut().enumerate() {
                *v += offsets[j % cfg.obs_dim];
            }
        }
    }
    let all: Vec<usize> = (0..size).collect();
    gather(&perturbed, cfg, &all, device)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::toy::{bimodal_windows, toy_prodmp_config};

    fn rows(t: &Tensor) -> Vec<f32> {
        t.flatten_all().unwrap().to_vec1::<f32>().unwrap()
    }

    #[test]
    fn augmentation_perturbs_only_the_initial_condition() {
        let cfg = toy_prodmp_config();
        let windows = bimodal_windows(&cfg, 64, 5).unwrap();
        let device = Device::Cpu;
        // Inactive augmentation draws exactly what `sample` draws.
        let plain = sample(&windows, &cfg, 32, &mut HostRng::new(9), &device).unwrap();
        let none = sample_augmented(
            &windows,
            &cfg,
            32,
            &CondAugment::NONE,
            &mut HostRng::new(9),
            &device,
        )
        .unwrap();
        assert_eq!(rows(&plain.x0), rows(&none.x0));
        assert_eq!(rows(&plain.cond.features), rows(&none.cond.features));
        // Always-on augmentation: targets are demonstration chunks, y0/v0 (zero in the toy set)
        // get offsets of about the requested spread, and the features carry the same offsets.
        let augment = CondAugment {
            prob: 1.0,
            y0_std: 0.1,
            v0_std: 2.0,
            obs_std: 0.0,
        };
        let batch = sample_augmented(
            &windows,
            &cfg,
            2000,
            &augment,
            &mut HostRng::new(9),
            &device,
        )
        .unwrap();
        let goals: Vec<f32> = rows(&batch.x0)
            .chunks_exact(cfg.horizon)
            .map(|c| c[cfg.horizon - 1])
            .collect();
        let first_goal = windows.actions[cfg.horizon - 1].abs();
        assert!(
            goals.iter().all(|g| (g.abs() - first_goal).abs() < 1e-6),
            "targets must stay demonstration chunks"
        );
        let std =
            |v: &[f32]| (v.iter().map(|x| f64::from(x * x)).sum::<f64>() / v.len() as f64).sqrt();
        let (y0, v0) = (rows(&batch.cond.y0), rows(&batch.cond.v0));
        assert!((std(&y0) - 0.1).abs() < 0.01, "y0 spread {}", std(&y0));
        assert!((std(&v0) - 2.0).abs() < 0.2, "v0 spread {}", std(&v0));
        let features = rows(&batch.cond.features);
        // Features = [obs, y0, v0 * dt] per row.
        for (row, (y, v)) in features.chunks_exact(3).zip(y0.iter().zip(&v0)) {
            assert_eq!(row[1], *y);
            assert!((row[2] - v * cfg.control_dt as f32).abs() < 1e-6);
        }
        // Half the windows perturbed at prob 0.5.
        let half = CondAugment {
            prob: 0.5,
            ..augment
        };
        let batch =
            sample_augmented(&windows, &cfg, 2000, &half, &mut HostRng::new(3), &device).unwrap();
        let moved = rows(&batch.cond.y0).iter().filter(|y| **y != 0.0).count();
        assert!((800..1200).contains(&moved), "{moved} of 2000 perturbed");
    }

    #[test]
    fn observation_offsets_are_shared_by_the_frames_of_a_window() {
        let device = Device::Cpu;
        let mut cfg = toy_prodmp_config();
        let mut windows = bimodal_windows(&cfg, 64, 1).unwrap();
        // Two frames of two observations per window, all zero.
        cfg.history = 2;
        cfg.obs_dim = 2;
        windows.history = 2;
        windows.obs_dim = 2;
        windows.obs = vec![0.0; 64 * 4];
        let augment = CondAugment {
            prob: 1.0,
            obs_std: 0.3,
            ..CondAugment::NONE
        };
        let batch = sample_augmented(
            &windows,
            &cfg,
            2000,
            &augment,
            &mut HostRng::new(5),
            &device,
        )
        .unwrap();
        let obs: Vec<f32> = rows(&batch.cond.features)
            .chunks_exact(cfg.history * cfg.obs_dim + 2)
            .flat_map(|r| r[..4].to_vec())
            .collect();
        for w in obs.chunks_exact(4) {
            assert_eq!(w[0], w[2], "frames share the offset");
            assert_eq!(w[1], w[3]);
        }
        let spread = (obs.iter().map(|x| f64::from(x * x)).sum::<f64>() / obs.len() as f64).sqrt();
        assert!((spread - 0.3).abs() < 0.02, "offset spread {spread}");
        assert_eq!(
            rows(&batch.cond.y0).iter().filter(|y| **y != 0.0).count(),
            0
        );
    }
}
