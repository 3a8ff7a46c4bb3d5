//! DP baseline training: epsilon prediction on raw action trajectories (no decoder).
use super::batch::{check_windows, sample};
use super::optim::ScheduledAdamW;
use super::{run_loop, LoopConfig, ProgressFn, TrainReport};
use crate::data::windows::WindowSet;
use crate::diffusion::ddpm::{dp_loss, DdpmSchedule};
use crate::models::{HeadConfig, ModelConfig, OwnedNetwork};
use crate::rng::HostRng;
use candle_core::Device;

/// Number of DDPM training steps of the baseline.
pub const DP_TRAIN_STEPS: usize = 100;

pub fn train_dp(windows: &WindowSet, model: &ModelConfig, cfg: &LoopConfig, progress: &mut ProgressFn<'_>) -> anyhow::Result<(OwnedNetwork, TrainReport)> {
    check_windows(windows, model)?;
    if model.head != HeadConfig::Raw {
        anyhow::bail!("the DP baseline needs a raw head");
    }
    let device = Device::Cpu;
    let sched = DdpmSchedule::cosine(DP_TRAIN_STEPS);
    let net = OwnedNetwork::new_seeded(model, cfg.seed, &device)?;
    let mut opt = ScheduledAdamW::new(net.varmap.all_vars(), cfg.optim.clone())?;
    let mut rng = HostRng::derive(cfg.seed, "dp-batches");
    let report = run_loop(
        cfg,
        |_| {
            let batch = sample(windows, model, cfg.batch_size, &mut rng, &device)?;
            let loss = dp_loss(&net.net, &sched, &batch.x0, &batch.cond, &mut rng)?;
            let lr = opt.current_lr();
            opt.backward_step(&loss)?;
            Ok((loss.to_scalar::<f32>()? as f64, lr))
        },
        &net,
        progress,
    )?;
    Ok((net, report))
}
