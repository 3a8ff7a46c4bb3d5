//! DP baseline training: epsilon prediction on raw action trajectories (no decoder), with an
//! optional exponential moving average of the weights for evaluation (as Chi et al. do).
use super::batch::{check_windows, sample};
use super::optim::ScheduledAdamW;
use super::{run_loop, LoopConfig, ProgressFn, TrainReport};
use crate::data::windows::WindowSet;
use crate::diffusion::ddpm::{dp_loss, DdpmSchedule, EpsParametrization};
use crate::models::init::ema_update;
use crate::models::{HeadConfig, ModelConfig, OwnedNetwork};
use crate::rng::HostRng;
use candle_core::Device;

/// Number of DDPM training steps of the baseline.
pub const DP_TRAIN_STEPS: usize = 100;

/// DP-specific training settings.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DpConfig {
    pub parametrization: EpsParametrization,
    /// Decay in [0, 1) of the weight average that is evaluated during training and returned
    /// (0 returns the trained weights themselves).
    pub eval_ema: f64,
}

impl Default for DpConfig {
    /// Chi et al.'s network (direct epsilon) with their 0.999-style weight EMA.
    fn default() -> Self {
        DpConfig { parametrization: EpsParametrization::Direct, eval_ema: 0.999 }
    }
}

/// Trains the DP baseline; returns the evaluated network (the weight EMA when `eval_ema` > 0).
pub fn train_dp(windows: &WindowSet, model: &ModelConfig, cfg: &LoopConfig, dp: &DpConfig, progress: &mut ProgressFn<'_>) -> anyhow::Result<(OwnedNetwork, TrainReport)> {
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
    use crate::diffusion::ddpm::{sample_dp, DpSampler};
    use crate::diffusion::samplers::gaussian;
    use crate::models::Condition;
    use crate::train::toy::{bimodal_windows, positive_fraction, toy_config, MODE_GOAL};
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
        let dp = DpConfig { parametrization: EpsParametrization::Preconditioned, eval_ema: 0.99 };
        let (net, report) = train_dp(&windows, &cfg, &loop_cfg, &dp, &mut |_: &Progress| Ok(())).unwrap();
        assert!(report.final_loss().unwrap() < 0.5 * report.loss_curve[0].1, "{:?}", report.loss_curve);
        // Endpoints of the two modes in the data.
        let ends: Vec<f32> = windows.actions.chunks_exact(cfg.horizon).map(|r| r[cfg.horizon - 1].abs()).collect();
        let end = ends.iter().sum::<f32>() / ends.len() as f32;
        assert!(end > 0.1 && MODE_GOAL > 0.0);
        let sched = DdpmSchedule::cosine(DP_TRAIN_STEPS).with_parametrization(dp.parametrization);
        let batch = 300;
        let zeros = Tensor::zeros((batch, 1), candle_core::DType::F32, &Device::Cpu).unwrap();
        let cond = Condition::new(&zeros, zeros.clone(), zeros.clone(), cfg.control_dt).unwrap();
        for (sampler, steps) in [(DpSampler::Ddpm, 100), (DpSampler::Ddim, 10)] {
            let mut rng = HostRng::new(5);
            let z = gaussian(&mut rng, batch, cfg.traj_dim(), &Device::Cpu).unwrap();
            let flat = sample_dp(&net.net, &sched, &cond, z, sampler, steps, &mut rng).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
            let fraction = positive_fraction(&flat, cfg.horizon);
            let end_error = flat.chunks_exact(cfg.horizon).map(|r| (r[cfg.horizon - 1].abs() - end).abs()).sum::<f32>() / batch as f32;
            assert!((fraction - 0.5).abs() <= 0.1, "{sampler:?}: {fraction}");
            assert!(end_error < 0.1 * end, "{sampler:?}: endpoint error {end_error} (data {end})");
        }
        assert!(train_dp(&windows, &cfg, &loop_cfg, &DpConfig { eval_ema: 1.0, ..dp }, &mut |_: &Progress| Ok(())).is_err());
    }
}
