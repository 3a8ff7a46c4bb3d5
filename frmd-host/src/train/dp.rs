//! DP baseline training: epsilon prediction on raw action trajectories (no decoder), with an
//! optional exponential moving average of the weights for evaluation (as Chi et al. do).
use super::batch::{check_windows, sample};
use super::optim::ScheduledAdamW;
use super::{run_loop, LoopConfig, ProgressFn, TrainReport};
use crate::data::windows::WindowSet;
use crate::diffusion::ddpm::{dp_loss, DdpmSchedule, EpsParametrization, DP_TRAIN_STEPS};
use crate::models::init::ema_update;
use crate::models::{HeadConfig, ModelConfig, OwnedNetwork};
use crate::rng::HostRng;
use candle_core::Device;

/// DP-specific training settings.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DpConfig {
    pub parametrization: EpsParametrization,
    /// Decay in [0, 1) of the weight average that is evaluated during training and returned
    /// (0 returns the trained weights themselves).
    pub eval_ema: f64,
}

impl Default for DpConfig {
    /// The preconditioned noise network (see [`EpsParametrization`] for why) with a 0.999
    /// weight EMA as in Chi et al.
    fn default() -> Self {
        DpConfig {
            parametrization: EpsParametrization::Preconditioned,
            eval_ema: 0.999,
        }
    }
}

/// Trains the DP baseline; returns the evaluated network (the weight EMA when `eval_ema` > 0).
pub fn train_dp(
    windows: &WindowSet,
    model: &ModelConfig,
    cfg: &LoopConfig,
    dp: &DpConfig,
    progress: &mut ProgressFn<'_>,
) -> anyhow::Result<(OwnedNetwork, TrainReport)> {
    let eval_ema = dp.eval_ema;
    check_windows(windows, model)?;
    if model.head != HeadConfig::Raw {
        anyhow::bail!("the DP baseline needs a raw head");
    }
    if !(0.0..1.0).contains(&eval_ema) {
        anyhow::bail!("the DP's weight EMA decay must be in [0, 1), got {eval_ema}");
    }
    let device = Device::Cpu;
    let sched = DdpmSchedule::cosine(DP_TRAIN_STEPS).with_parametrization(dp.parametrization);
    let net = OwnedNetwork::new_seeded(model, cfg.seed, &device)?;
    let averaged = net.duplicate(&device)?;
    let mut opt = ScheduledAdamW::new(net.varmap.all_vars(), cfg.optim.clone())?;
    let mut rng = HostRng::derive(cfg.seed, "dp-batches");
    let report = run_loop(
        cfg,
        |_| {
            let batch = sample(windows, model, cfg.batch_size, &mut rng, &device)?;
            let loss = dp_loss(&net.net, &sched, &batch.x0, &batch.cond, &mut rng)?;
            let lr = opt.current_lr();
            opt.backward_step(&loss)?;
            ema_update(&averaged.varmap, &net.varmap, eval_ema)?;
            Ok((loss.to_scalar::<f32>()? as f64, lr))
        },
        &averaged,
        progress,
    )?;
    Ok((averaged, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::toy::{bimodal_windows, positive_fraction, toy_config, MODE_GOAL};
    use crate::diffusion::ddpm::{sample_dp, DpSampler};
    use crate::diffusion::samplers::gaussian;
    use crate::models::Condition;
    use crate::train::Progress;
    use candle_core::Tensor;

    /// The preconditioned DP with a weight EMA learns the toy bimodal set: DDPM-100 and DDIM-10
    /// both give the two modes in equal proportion and end near +-MODE_GOAL-scaled endpoints.
    #[test]
    fn preconditioned_dp_with_ema_learns_bimodal_toy() {
        let cfg = toy_config(HeadConfig::Raw);
        let windows = bimodal_windows(&cfg, 512, 2).unwrap();
        let mut loop_cfg = LoopConfig::paper(2000, 4);
        loop_cfg.batch_size = 64;
        loop_cfg.optim.lr = 3e-3;
        loop_cfg.optim.warmup_steps = 50;
        loop_cfg.log_every = 50;
        let dp = DpConfig {
            parametrization: EpsParametrization::Preconditioned,
            eval_ema: 0.99,
        };
        let (net, report) =
            train_dp(&windows, &cfg, &loop_cfg, &dp, &mut |_: &Progress| Ok(())).unwrap();
        assert!(
            report.final_loss().unwrap() < 0.5 * report.loss_curve[0].1,
            "{:?}",
            report.loss_curve
        );
        // Endpoints of the two modes in the data.
        let ends: Vec<f32> = windows
            .actions
            .chunks_exact(cfg.horizon)
            .map(|r| r[cfg.horizon - 1].abs())
            .collect();
        let end = ends.iter().sum::<f32>() / ends.len() as f32;
        assert!(end > 0.1 && MODE_GOAL > 0.0);
        let sched = DdpmSchedule::cosine(DP_TRAIN_STEPS).with_parametrization(dp.parametrization);
        let batch = 300;
        let zeros = Tensor::zeros((batch, 1), candle_core::DType::F32, &Device::Cpu).unwrap();
        let cond = Condition::new(&zeros, zeros.clone(), zeros.clone(), cfg.control_dt).unwrap();
        for (sampler, steps) in [(DpSampler::Ddpm, 100), (DpSampler::Ddim, 10)] {
            let mut rng = HostRng::new(5);
            let z = gaussian(&mut rng, batch, cfg.traj_dim(), &Device::Cpu).unwrap();
            let flat = sample_dp(&net.net, &sched, &cond, z, sampler, steps, &mut rng)
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1::<f32>()
                .unwrap();
            let fraction = positive_fraction(&flat, cfg.horizon);
            let end_error = flat
                .chunks_exact(cfg.horizon)
                .map(|r| (r[cfg.horizon - 1].abs() - end).abs())
                .sum::<f32>()
                / batch as f32;
            assert!((fraction - 0.5).abs() <= 0.1, "{sampler:?}: {fraction}");
            assert!(
                end_error < 0.1 * end,
                "{sampler:?}: endpoint error {end_error} (data {end})"
            );
        }
        assert!(train_dp(
            &windows,
            &cfg,
            &loop_cfg,
            &DpConfig {
                eval_ema: 1.0,
                ..dp
            },
            &mut |_: &Progress| Ok(())
        )
        .is_err());
    }

    /// Straight-line chunks whose slope is the observation: (RMS second difference of sampled
    /// chunks, mean abs error) after a short run with `dp`.
    fn line_fit(dp: &DpConfig) -> (f64, f64) {
        let mut cfg = toy_config(HeadConfig::Raw);
        cfg.horizon = 12;
        cfg.action_dim = 2;
        cfg.backbone = crate::models::BackboneConfig::Mlp {
            hidden: vec![128, 128, 128],
            activation: crate::models::Activation::Silu,
        };
        let count = 512;
        let mut rng = HostRng::new(8);
        let slopes: Vec<f32> = (0..count)
            .map(|_| (2.0 * rng.uniform() - 1.0) as f32)
            .collect();
        // Both DoFs follow the line (the second mirrored), step-major.
        let line = |s: f32| {
            (0..24)
                .map(move |i| (if i % 2 == 0 { 0.8 } else { -0.8 }) * s * (i / 2 + 1) as f32 / 12.0)
        };
        let windows = WindowSet {
            obs_dim: 1,
            action_dim: 2,
            history: 1,
            horizon: 12,
            dt: 0.1,
            obs: slopes.clone(),
            prev_action: vec![0.0; 2 * count],
            prev_rate: vec![0.0; 2 * count],
            actions: slopes.iter().flat_map(|&s| line(s)).collect(),
        };
        let mut loop_cfg = LoopConfig::paper(2000, 4);
        loop_cfg.batch_size = 64;
        loop_cfg.optim.lr = 3e-3;
        loop_cfg.optim.warmup_steps = 50;
        loop_cfg.log_every = 500;
        let (net, _) = train_dp(&windows, &cfg, &loop_cfg, dp, &mut |_: &Progress| Ok(())).unwrap();
        let sched = DdpmSchedule::cosine(DP_TRAIN_STEPS).with_parametrization(dp.parametrization);
        let test: Vec<f32> = (0..64).map(|i| -0.9 + 1.8 * i as f32 / 63.0).collect();
        let obs = Tensor::from_slice(&test, (64, 1), &Device::Cpu).unwrap();
        let zeros = obs.zeros_like().unwrap();
        let zeros = Tensor::cat(&[&zeros, &zeros], 1).unwrap();
        let cond = Condition::new(&obs, zeros.clone(), zeros, cfg.control_dt).unwrap();
        let z = gaussian(&mut rng, 64, 24, &Device::Cpu).unwrap();
        let out = sample_dp(&net.net, &sched, &cond, z, DpSampler::Ddim, 10, &mut rng)
            .unwrap()
            .to_vec2::<f32>()
            .unwrap();
        let (mut rough, mut err) = (0.0, 0.0);
        for (row, &s) in out.iter().zip(&test) {
            rough += row
                .windows(5)
                .map(|w| f64::from(w[4] - 2.0 * w[2] + w[0]).powi(2))
                .sum::<f64>()
                / 20.0;
            err += row
                .iter()
                .zip(line(s))
                .map(|(a, b)| f64::from((a - b).abs()))
                .sum::<f64>()
                / 24.0;
        }
        ((rough / 64.0).sqrt(), err / 64.0)
    }

    /// Regression test for the jittery DP chunks (60+ non-smooth transitions per episode): the
    /// default DP must reproduce smooth straight-line chunks (2 DoF, n = 12, MLP 128x3, 2000
    /// steps, deterministic). The direct epsilon network of the old default has to carry x_t
    /// through the MLP (scaled by up to 40x at t = 0) and leaves per-action noise; measured on
    /// this toy: direct roughness 0.052 / error 0.016, preconditioned 0.033 / 0.011 (on the
    /// `avoid` demonstrations after 20k steps the gap is 4x: 0.016 vs 0.0038, data 0.0030).
    #[test]
    fn default_dp_chunks_are_smooth() {
        // No weight EMA: its 1000-step horizon would average in the first weights of this short run.
        let dp = DpConfig {
            eval_ema: 0.0,
            ..DpConfig::default()
        };
        let (rough, err) = line_fit(&dp);
        let (direct_rough, direct_err) = line_fit(&DpConfig {
            parametrization: EpsParametrization::Direct,
            ..dp
        });
        eprintln!("preconditioned: roughness {rough:.4}, error {err:.4}; direct: roughness {direct_rough:.4}, error {direct_err:.4}");
        assert!(
            rough < 0.045 && err < 0.015,
            "roughness {rough}, error {err}"
        );
        assert!(
            rough < 0.8 * direct_rough && err < direct_err,
            "{rough} vs direct {direct_rough}"
        );
    }
}
