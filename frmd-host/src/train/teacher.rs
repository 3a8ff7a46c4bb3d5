//! Teacher (MPD) training: EDM denoising loss through the ProDMP decoder.
use super::batch::{check_windows, sample_augmented, CondAugment};
use super::optim::ScheduledAdamW;
use super::{run_loop, LoopConfig, ProgressFn, TrainReport};
use crate::data::windows::WindowSet;
use crate::diffusion::loss::{teacher_loss, LossWeight, SigmaSampling};
use crate::models::init::ema_update;
use crate::models::{ModelConfig, OwnedNetwork};
use crate::rng::HostRng;
use candle_core::Device;
use frmd_core::sigma::SigmaConfig;
use serde::{Deserialize, Serialize};

/// Teacher-specific settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TeacherConfig {
    pub weight: LossWeight,
    pub sampling: SigmaSampling,
    pub augment: CondAugment,
    /// EMA decay of the returned (evaluated, saved) weights; 0 returns the raw weights.
    pub ema: f64,
}

impl Default for TeacherConfig {
    /// The recipe: uniform loss weight, a fifth of the noise levels drawn log-uniformly, no
    /// augmentation, the raw weights (docs/experiments.md has the measurements behind each).
    fn default() -> Self {
        TeacherConfig::plain(
            LossWeight::Uniform,
            SigmaSampling {
                uniform_fraction: 0.2,
            },
        )
    }
}

impl TeacherConfig {
    /// Loss weight and sigma sampling as given, no augmentation, no EMA.
    pub fn plain(weight: LossWeight, sampling: SigmaSampling) -> Self {
        TeacherConfig {
            weight,
            sampling,
            augment: CondAugment::NONE,
            ema: 0.0,
        }
    }
}

/// Trains a teacher from scratch (variables seeded from `cfg.seed`). Returns the EMA of the
/// weights when `tcfg.ema > 0`.
pub fn train_teacher(
    windows: &WindowSet,
    model: &ModelConfig,
    sig: &SigmaConfig,
    tcfg: &TeacherConfig,
    cfg: &LoopConfig,
    progress: &mut ProgressFn<'_>,
) -> anyhow::Result<(OwnedNetwork, TrainReport)> {
    check_windows(windows, model)?;
    if model.prodmp().is_none() {
        anyhow::bail!("the teacher needs a ProDMP head");
    }
    let device = Device::Cpu;
    let net = OwnedNetwork::new_seeded(model, cfg.seed, &device)?;
    let mut opt = ScheduledAdamW::for_network(&net, cfg.optim.clone())?;
    let mut rng = HostRng::derive(cfg.seed, "teacher-batches");
    anyhow::ensure!(
        (0.0..1.0).contains(&tcfg.ema),
        "teacher EMA decay must be in [0, 1), got {}",
        tcfg.ema
    );
    let averaged = if tcfg.ema > 0.0 {
        Some(net.duplicate(&device)?)
    } else {
        None
    };
    let report = run_loop(
        cfg,
        |_| {
            let batch = sample_augmented(
                windows,
                model,
                cfg.batch_size,
                &tcfg.augment,
                &mut rng,
                &device,
            )?;
            let loss = teacher_loss(
                &net.net,
                sig,
                &batch.x0,
                &batch.cond,
                tcfg.weight,
                tcfg.sampling,
                &mut rng,
            )?;
            let lr = opt.current_lr();
            opt.backward_step(&loss)?;
            if let Some(avg) = &averaged {
                ema_update(&avg.varmap, &net.varmap, tcfg.ema)?;
            }
            Ok((loss.to_scalar::<f32>()? as f64, lr))
        },
        averaged.as_ref().unwrap_or(&net),
        progress,
    )?;
    Ok((averaged.unwrap_or(net), report))
}

/// [`train_teacher`] with the default noise schedule, the log-normal levels alone, no
/// augmentation, no EMA and no progress reports: the plain teacher of the toy tests and sweeps.
pub fn train_plain_teacher(
    windows: &WindowSet,
    model: &ModelConfig,
    weight: LossWeight,
    cfg: &LoopConfig,
) -> anyhow::Result<(OwnedNetwork, TrainReport)> {
    train_teacher(
        windows,
        model,
        &SigmaConfig::default(),
        &TeacherConfig::plain(weight, SigmaSampling::LOG_NORMAL),
        cfg,
        &mut |_: &super::Progress<'_>| Ok(()),
    )
}
