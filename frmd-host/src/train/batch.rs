//! Random training batches drawn from a [`WindowSet`] with the seeded generator.
use crate::data::windows::WindowSet;
use crate::models::{Condition, ModelConfig};
use crate::rng::HostRng;
use anyhow::bail;
use candle_core::{Device, Tensor};

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
    if windows.obs_dim != cfg.obs_dim || windows.action_dim != cfg.action_dim || windows.history != cfg.history || windows.horizon != cfg.horizon {
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
pub fn gather(windows: &WindowSet, cfg: &ModelConfig, indices: &[usize], device: &Device) -> anyhow::Result<Batch> {
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
    Ok(Batch { x0: Tensor::from_vec(x0, (indices.len(), traj), device)?, cond })
}

/// A batch of `size` windows drawn uniformly with replacement.
pub fn sample(windows: &WindowSet, cfg: &ModelConfig, size: usize, rng: &mut HostRng, device: &Device) -> anyhow::Result<Batch> {
    let indices: Vec<usize> = (0..size).map(|_| rng.below(windows.len())).collect();
    gather(windows, cfg, &indices, device)
}
