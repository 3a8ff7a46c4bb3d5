//! Teacher (MPD) training: EDM denoising loss through the ProDMP decoder.
use super::batch::{check_windows, sample_augmented, CondAugment};
use super::optim::ScheduledAdamW;
use super::{run_loop, LoopConfig, ProgressFn, TrainReport};
use crate::data::windows::WindowSet;
use crate::diffusion::loss::{teacher_loss, LossWeight, SigmaSampling};
use crate::models::{ModelConfig, OwnedNetwork};
use crate::rng::HostRng;
use candle_core::Device;
use frmd_core::sigma::SigmaConfig;

/// Trains a teacher from scratch (variables seeded from `cfg.seed`).
pub fn train_teacher(
    windows: &WindowSet,
    model: &ModelConfig,
    sig: &SigmaConfig,
    weight: LossWeight,
    sampling: SigmaSampling,
    augment: CondAugment,
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
    let report = run_loop(
        cfg,
        |_| {
            let batch = sample_augmented(windows, model, cfg.batch_size, &augment, &mut rng, &device)?;
            let loss = teacher_loss(&net.net, sig, &batch.x0, &batch.cond, weight, sampling, &mut rng)?;
            let lr = opt.current_lr();
            opt.backward_step(&loss)?;
            Ok((loss.to_scalar::<f32>()? as f64, lr))
        },
        &net,
        progress,
    )?;
    Ok((net, report))
}
