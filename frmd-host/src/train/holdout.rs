//! Open-loop chunk error of a teacher or student on training windows and on held-out
//! demonstrations: separates underfitting (high error on training windows) from poor
//! generalization (low training error, high held-out error) before anything is run in closed loop.
//!
//! Errors are mean absolute differences between sampled and demonstrated chunks, reported in the
//! action's raw units (metres for the built-in tasks), next to the "hold the last action"
//! baseline of the same windows.
use super::batch::gather;
use crate::data::windows::WindowSet;
use crate::data::{Dataset, Normalization};
use crate::diffusion::samplers::{gaussian, sample_consistency, sample_teacher, Solver};
use crate::models::Network;
use crate::rng::HostRng;
use anyhow::{bail, ensure};
use candle_core::Device;
use frmd_core::sigma::SigmaConfig;
use serde::Serialize;

/// How chunks are sampled for the measurement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ChunkSampler {
    /// Teacher ODE from sigma_max in `steps` steps.
    Teacher { solver: Solver, steps: usize },
    /// Consistency sampling in `steps` steps.
    Student { steps: usize },
}

/// Open-loop error of one window set.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ChunkError {
    /// Windows measured.
    pub windows: usize,
    /// Mean |sampled - demonstrated| over all steps and DoFs, raw action units.
    pub mean_abs: f64,
    /// Mean |sampled - demonstrated| of the last step of each chunk, raw action units.
    pub last_step_abs: f64,
    /// Mean |a_{t-1} - demonstrated| (hold the last action), raw action units.
    pub hold_baseline: f64,
}

/// Train and held-out errors side by side.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct GeneralizationReport {
    pub train: ChunkError,
    pub held_out: ChunkError,
}

impl std::fmt::Display for GeneralizationReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "chunk error train {:.4} (last step {:.4}) / held-out {:.4} (last step {:.4}), hold-last baseline {:.4} / {:.4}",
            self.train.mean_abs, self.train.last_step_abs, self.held_out.mean_abs, self.held_out.last_step_abs, self.train.hold_baseline, self.held_out.hold_baseline
        )
    }
}

/// Maps windows normalized with `from` to the normalization `to` (same dimensions): positions
/// through raw units, rates by the ratio of scales (a constant dimension of `from` maps to 0).
pub fn renormalize(
    windows: &mut WindowSet,
    from: &Normalization,
    to: &Normalization,
) -> anyhow::Result<()> {
    ensure!(
        from.obs.dim() == to.obs.dim() && from.action.dim() == to.action.dim(),
        "normalizations differ in size (obs {} vs {}, action {} vs {})",
        from.obs.dim(),
        to.obs.dim(),
        from.action.dim(),
        to.action.dim()
    );
    ensure!(
        windows.obs_dim == to.obs.dim() && windows.action_dim == to.action.dim(),
        "windows do not match the normalization's dimensions"
    );
    from.obs.denormalize(&mut windows.obs);
    to.obs.normalize(&mut windows.obs);
    for values in [&mut windows.prev_action, &mut windows.actions] {
        from.action.denormalize(values);
        to.action.normalize(values);
    }
    let ratio: Vec<f32> = from
        .action
        .scale()
        .iter()
        .zip(to.action.scale())
        .map(|(&f, t)| if f > 0.0 { t / f } else { 0.0 })
        .collect();
    for row in windows.prev_rate.chunks_mut(ratio.len()) {
        row.iter_mut().zip(&ratio).for_each(|(v, r)| *v *= r);
    }
    Ok(())
}

/// Windows of `data` expressed in the normalization `norm` of a trained model.
pub fn windows_in(
    data: &Dataset,
    history: usize,
    horizon: usize,
    norm: &Normalization,
) -> anyhow::Result<WindowSet> {
    let (mut windows, own) = data.windows(history, horizon)?;
    renormalize(&mut windows, &own, norm)?;
    Ok(windows)
}

/// Chunk error of `net` on up to `max_windows` evenly spaced windows (batches of 256), with
/// noise from `seed`. `action_scale` is the normalizer's `scale()` (normalized per raw unit).
pub fn chunk_error(
    net: &Network,
    sig: &SigmaConfig,
    sampler: ChunkSampler,
    windows: &WindowSet,
    action_scale: &[f32],
    max_windows: usize,
    seed: u64,
) -> anyhow::Result<ChunkError> {
    let cfg = net.config();
    let (k, traj) = (cfg.action_dim, cfg.traj_dim());
    ensure!(
        action_scale.len() == k,
        "action scale has {} values, the model has {k} action dimensions",
        action_scale.len()
    );
    let len = windows.len();
    if len == 0 || max_windows == 0 {
        bail!("no windows to measure");
    }
    let stride = len.div_ceil(max_windows).max(1);
    let indices: Vec<usize> = (0..len).step_by(stride).collect();
    let mut rng = HostRng::derive(seed, "chunk-error");
    let device = Device::Cpu;
    let (mut sum, mut last, mut hold) = (0.0f64, 0.0f64, 0.0f64);
    for part in indices.chunks(256) {
        let batch = gather(windows, cfg, part, &device)?;
        let z = gaussian(&mut rng, part.len(), traj, &device)?;
        let out = match sampler {
            ChunkSampler::Teacher { solver, steps } => {
                sample_teacher(net, sig, &batch.cond, (z * sig.sigma_max)?, steps, solver)?
            }
            ChunkSampler::Student { steps } => {
                sample_consistency(net, sig, &batch.cond, &z, steps, &mut rng)?
            }
        };
        let out = out.flatten_all()?.to_vec1::<f32>()?;
        for (row, &i) in part.iter().enumerate() {
            let (sampled, truth) = (
                &out[row * traj..(row + 1) * traj],
                &windows.actions[i * traj..(i + 1) * traj],
            );
            let prev = &windows.prev_action[i * k..(i + 1) * k];
            for (step, (s, t)) in sampled
                .chunks_exact(k)
                .zip(truth.chunks_exact(k))
                .enumerate()
            {
                for d in 0..k {
                    let to_raw = if action_scale[d] > 0.0 {
                        1.0 / f64::from(action_scale[d])
                    } else {
                        0.0
                    };
                    let err = f64::from((s[d] - t[d]).abs()) * to_raw;
                    sum += err;
                    hold += f64::from((prev[d] - t[d]).abs()) * to_raw;
                    if step + 1 == cfg.horizon {
                        last += err;
                    }
                }
            }
        }
    }
    let count = indices.len() as f64;
    Ok(ChunkError {
        windows: indices.len(),
        mean_abs: sum / (count * traj as f64),
        last_step_abs: last / (count * k as f64),
        hold_baseline: hold / (count * traj as f64),
    })
}

/// [`chunk_error`] on training windows and on held-out windows.
#[allow(clippy::too_many_arguments)]
pub fn generalization(
    net: &Network,
    sig: &SigmaConfig,
    sampler: ChunkSampler,
    train: &WindowSet,
    held_out: &WindowSet,
    action_scale: &[f32],
    max_windows: usize,
    seed: u64,
) -> anyhow::Result<GeneralizationReport> {
    Ok(GeneralizationReport {
        train: chunk_error(net, sig, sampler, train, action_scale, max_windows, seed)?,
        held_out: chunk_error(net, sig, sampler, held_out, action_scale, max_windows, seed)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::toy::{bimodal_windows, toy_prodmp_config};
    use crate::models::OwnedNetwork;

    fn dataset(offset: f32) -> Dataset {
        // Two episodes of a 2-D action and 3-D observation; `offset` shifts every value.
        let steps = 9;
        let obs: Vec<f32> = (0..steps * 3)
            .map(|i| offset + (i as f32 * 0.37).sin() * (1 + i % 3) as f32)
            .collect();
        let action: Vec<f32> = (0..steps * 2)
            .map(|i| offset + (i as f32 * 0.21).cos() * (2 + i % 2) as f32)
            .collect();
        Dataset::handmade(obs, action, vec![4, 9], (3, 2))
    }

    #[test]
    fn renormalized_windows_equal_windows_normalized_directly() {
        let (train, held) = (dataset(0.0), dataset(0.5));
        let (_, train_norm) = train.windows(2, 3).unwrap();
        let moved = windows_in(&held, 2, 3, &train_norm).unwrap();
        // Reference: normalize the held-out raw values with the training normalization.
        let (own, own_norm) = held.windows(2, 3).unwrap();
        assert_ne!(own_norm, train_norm);
        let mut raw_actions = own.actions.clone();
        own_norm.action.denormalize(&mut raw_actions);
        let mut expected = raw_actions.clone();
        train_norm.action.normalize(&mut expected);
        for (a, b) in moved.actions.iter().zip(&expected) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
        // Rates: differences of the renormalized previous actions over dt, same as the raw rate
        // times the training scale.
        let scale = train_norm.action.scale();
        let (raw_rates, own_scale) = (own.prev_rate.clone(), own_norm.action.scale());
        for (i, (r, own_r)) in moved.prev_rate.iter().zip(&raw_rates).enumerate() {
            let raw = own_r / own_scale[i % 2];
            assert!(
                (r - raw * scale[i % 2]).abs() < 1e-4,
                "rate {r} vs {}",
                raw * scale[i % 2]
            );
        }
        // Renormalizing with the set's own normalization is the identity.
        let same = windows_in(&train, 2, 3, &train_norm).unwrap();
        let (direct, _) = train.windows(2, 3).unwrap();
        for (a, b) in same.obs.iter().zip(&direct.obs) {
            assert!((a - b).abs() < 1e-5);
        }
        // Mismatched sizes are an error.
        let mut wrong = train_norm.clone();
        wrong.action.min.pop();
        assert!(windows_in(&held, 2, 3, &wrong).is_err());
    }

    #[test]
    fn chunk_error_reports_the_hold_baseline_and_rejects_bad_input() {
        let cfg = toy_prodmp_config();
        let windows = bimodal_windows(&cfg, 40, 2).unwrap();
        let net = OwnedNetwork::new_seeded(&cfg, 1, &Device::Cpu).unwrap();
        let sig = SigmaConfig::default();
        let sampler = ChunkSampler::Student { steps: 1 };
        // Scale 0.5 normalized per raw unit: raw errors are twice the normalized ones.
        let err = chunk_error(&net.net, &sig, sampler, &windows, &[0.5], 40, 0).unwrap();
        assert_eq!(err.windows, 40);
        let expected_hold = windows
            .actions
            .iter()
            .map(|a| f64::from(a.abs()) * 2.0)
            .sum::<f64>()
            / windows.actions.len() as f64;
        assert!(
            (err.hold_baseline - expected_hold).abs() < 1e-6,
            "{} vs {expected_hold}",
            err.hold_baseline
        );
        assert!(err.mean_abs.is_finite() && err.mean_abs > 0.0);
        // Every 4th window when capped at 10.
        assert_eq!(
            chunk_error(&net.net, &sig, sampler, &windows, &[0.5], 10, 0)
                .unwrap()
                .windows,
            10
        );
        assert!(chunk_error(&net.net, &sig, sampler, &windows, &[0.5, 1.0], 10, 0).is_err());
        assert!(chunk_error(&net.net, &sig, sampler, &windows, &[0.5], 0, 0).is_err());
    }
}
