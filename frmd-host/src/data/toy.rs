//! A toy 1-D bimodal data set for tests and experiments: one DoF, a constant observation, y0 =
//! v0 = 0, and every trajectory is the ProDMP decode of goal +0.5 or -0.5 (zero weights), each
//! with probability 1/2 — so the data distribution has exactly two modes.
use super::windows::{Normalization, Normalizer, WindowSet};
use crate::models::decoder::DecoderRows;
use crate::models::{Activation, BackboneConfig, HeadConfig, ModelConfig};
use crate::rng::HostRng;

/// Goal of the two modes (normalized units).
pub const MODE_GOAL: f64 = 0.5;

/// Small config for toy runs: horizon 4, 4 basis functions, dt 0.1, MLP [64, 64] SiLU.
pub fn toy_config(head: HeadConfig) -> ModelConfig {
    ModelConfig {
        obs_dim: 1,
        history: 1,
        action_dim: 1,
        horizon: 4,
        control_dt: 0.1,
        embed_dim: 8,
        backbone: BackboneConfig::Mlp {
            hidden: vec![64, 64],
            activation: Activation::Silu,
        },
        head,
    }
}

/// [`toy_config`] with the ProDMP head the toy runs use: 4 basis functions, direct output, the
/// basis unscaled.
pub fn toy_prodmp_config() -> ModelConfig {
    toy_config(HeadConfig::prodmp(4))
}

/// `count` windows, modes drawn from `seed`. Works for any head (the trajectories come from the
/// ProDMP rows of a 4-basis policy config).
pub fn bimodal_windows(cfg: &ModelConfig, count: usize, seed: u64) -> anyhow::Result<WindowSet> {
    let pcfg = crate::models::ProDmpConfig::policy(1, 4, cfg.horizon, cfg.control_dt);
    let rows = DecoderRows::new(&pcfg, cfg.horizon)?;
    let goal_column = rows.num_params - 1;
    let mut rng = HostRng::new(seed);
    let mut actions = Vec::with_capacity(count * cfg.horizon);
    for _ in 0..count {
        let goal = if rng.uniform() < 0.5 {
            MODE_GOAL
        } else {
            -MODE_GOAL
        };
        for row in rows.pos_params.chunks_exact(rows.num_params) {
            actions.push((row[goal_column] * goal) as f32);
        }
    }
    Ok(WindowSet {
        obs_dim: 1,
        action_dim: 1,
        history: 1,
        horizon: cfg.horizon,
        dt: cfg.control_dt as f32,
        obs: vec![0.0; count],
        prev_action: vec![0.0; count],
        prev_rate: vec![0.0; count],
        actions,
    })
}

/// Fraction of trajectories (rows of `traj`, [B, n]) whose last step is positive.
pub fn positive_fraction(traj: &[f32], horizon: usize) -> f64 {
    let rows = traj.len() / horizon.max(1);
    let positive = traj
        .chunks_exact(horizon)
        .filter(|row| row.last().copied().unwrap_or(0.0) > 0.0)
        .count();
    positive as f64 / rows.max(1) as f64
}

/// A normalization of the toy sizes' raw units: observation in [-2, 2], action in [10, 20].
pub fn toy_normalization() -> Normalization {
    Normalization {
        obs: Normalizer {
            min: vec![-2.0],
            max: vec![2.0],
        },
        action: Normalizer {
            min: vec![10.0],
            max: vec![20.0],
        },
    }
}

/// Mean distance of the last step of each trajectory (rows of `traj`, [B, n]) to the nearest
/// mode's last step, which is the magnitude of the last action of `windows`' first window.
pub fn last_step_error(traj: &[f32], windows: &WindowSet) -> f64 {
    let goal_end = windows.actions[windows.horizon - 1].abs() as f64;
    let rows = traj.len() / windows.horizon.max(1);
    traj.chunks_exact(windows.horizon)
        .map(|r| ((*r.last().unwrap() as f64).abs() - goal_end).abs())
        .sum::<f64>()
        / rows as f64
}

/// The condition of `batch` toy samples: zero observation, y0 and v0.
pub fn toy_condition(batch: usize) -> anyhow::Result<crate::models::Condition> {
    let zeros = candle_core::Tensor::zeros(
        (batch, 1),
        candle_core::DType::F32,
        &candle_core::Device::Cpu,
    )?;
    Ok(crate::models::Condition::new(
        &zeros,
        zeros.clone(),
        zeros.clone(),
        0.1,
    )?)
}
