//! Consistency distillation, the paper's Algorithm 1: student and target start as copies of the
//! teacher; each step draws a level index, noises clean trajectories to sigma_{n+K}, runs K
//! teacher ODE steps between adjacent levels down to sigma_n, and regresses
//! f_student(x_{n+K}, sigma_{n+K}) on f_target(x_n, sigma_n); then target <- EMA_mu(student).
//! A separate slow EMA of the student is what gets evaluated and saved.
use super::batch::{check_windows, sample_augmented, CondAugment};
use super::optim::ScheduledAdamW;
use super::{run_loop, LoopConfig, ProgressFn, TrainReport};
use crate::data::windows::WindowSet;
use crate::diffusion::precond::consistency;
use crate::diffusion::samplers::{gaussian, ode_step, Solver};
use crate::diffusion::sigma_err;
use crate::models::init::ema_update;
use crate::models::{HeadConfig, OwnedNetwork, ProDmpOutput};
use crate::rng::HostRng;
use anyhow::bail;
use candle_core::Device;
use frmd_core::sigma::SigmaConfig;
use serde::{Deserialize, Serialize};

/// Distillation settings (paper: K = 2, target EMA 0.95; N = 40 and eval EMA 0.99 measured best,
/// see docs/experiments.md).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DistillConfig {
    /// Number N of Karras levels of the consistency discretization.
    pub levels: usize,
    /// Teacher ODE steps K between the two levels of a training pair.
    pub teacher_steps: usize,
    /// Solver of those steps (Euler or Heun).
    pub solver: Solver,
    /// Target-network EMA mu.
    pub target_ema: f64,
    /// Slow EMA of the student used for evaluation and export.
    pub eval_ema: f64,
    /// Initial-condition perturbation of the training windows (as for the teacher, so the
    /// student learns the teacher's recovery chunks too).
    #[serde(default)]
    pub augment: CondAugment,
    /// Output parametrization of the student (`None`: the teacher's). The student starts from
    /// the teacher's weights either way.
    #[serde(default)]
    pub output: Option<ProDmpOutput>,
}

impl Default for DistillConfig {
    fn default() -> Self {
        DistillConfig {
            levels: 40,
            teacher_steps: 2,
            solver: Solver::Heun,
            target_ema: 0.95,
            eval_ema: 0.99,
            augment: CondAugment::NONE,
            output: None,
        }
    }
}

/// The networks distillation produces.
pub struct Distilled {
    /// Slow EMA of the student (evaluated and saved).
    pub eval_student: OwnedNetwork,
    /// The raw student.
    pub student: OwnedNetwork,
    pub report: TrainReport,
}

/// Distills `teacher` into a consistency student.
pub fn distill(
    teacher: &OwnedNetwork,
    windows: &WindowSet,
    sig: &SigmaConfig,
    dcfg: &DistillConfig,
    cfg: &LoopConfig,
    progress: &mut ProgressFn<'_>,
) -> anyhow::Result<Distilled> {
    let mut model = teacher.net.config().clone();
    if let (HeadConfig::ProDmp { output, .. }, Some(wanted)) = (&mut model.head, dcfg.output) {
        *output = wanted;
    }
    check_windows(windows, &model)?;
    if dcfg.solver == Solver::DpmPp2m {
        bail!("distillation steps use Euler or Heun");
    }
    if dcfg.levels < dcfg.teacher_steps + 1 || dcfg.teacher_steps == 0 {
        bail!(
            "distillation needs 1 <= K < N (got K = {}, N = {})",
            dcfg.teacher_steps,
            dcfg.levels
        );
    }
    let device = Device::Cpu;
    let levels = (0..dcfg.levels)
        .map(|i| sig.karras_sigma(i, dcfg.levels))
        .collect::<Result<Vec<_>, _>>()
        .map_err(sigma_err("distillation levels"))?;
    let student = teacher.duplicate_as(&model, &device)?;
    let target = teacher.duplicate_as(&model, &device)?;
    let eval_student = teacher.duplicate_as(&model, &device)?;
    let mut opt = ScheduledAdamW::for_network(&student, cfg.optim.clone())?;
    let mut rng = HostRng::derive(cfg.seed, "distill-batches");
    let k = dcfg.teacher_steps;
    let heun = dcfg.solver == Solver::Heun;
    let report = run_loop(
        cfg,
        |_| {
            let batch = sample_augmented(
                windows,
                &model,
                cfg.batch_size,
                &dcfg.augment,
                &mut rng,
                &device,
            )?;
            let size = cfg.batch_size;
            // Descending index: level j is sigma_{n+K}, level j + K is sigma_n.
            let starts: Vec<usize> = (0..size).map(|_| rng.below(dcfg.levels - k)).collect();
            let high: Vec<f64> = starts.iter().map(|&j| levels[j]).collect();
            let eps = gaussian(&mut rng, size, model.traj_dim(), &device)?;
            let noisy = (&batch.x0
                + eps.broadcast_mul(&crate::diffusion::precond::column(&high, &device)?)?)?;
            let mut x = noisy.clone();
            for s in 0..k {
                let from: Vec<f64> = starts.iter().map(|&j| levels[j + s]).collect();
                let to: Vec<f64> = starts.iter().map(|&j| levels[j + s + 1]).collect();
                x = ode_step(&teacher.net, sig, &x, &batch.cond, &from, &to, heun)?.detach();
            }
            let low: Vec<f64> = starts.iter().map(|&j| levels[j + k]).collect();
            let target_out = consistency(&target.net, sig, &x, &batch.cond, &low)?.detach();
            let predicted = consistency(&student.net, sig, &noisy, &batch.cond, &high)?;
            let loss = (predicted - target_out)?.sqr()?.mean_all()?;
            let lr = opt.current_lr();
            opt.backward_step(&loss)?;
            ema_update(&target.varmap, &student.varmap, dcfg.target_ema)?;
            ema_update(&eval_student.varmap, &student.varmap, dcfg.eval_ema)?;
            Ok((loss.to_scalar::<f32>()? as f64, lr))
        },
        &eval_student,
        progress,
    )?;
    Ok(Distilled {
        eval_student,
        student,
        report,
    })
}
