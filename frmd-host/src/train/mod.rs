//! Training: the EDM teacher, consistency distillation of the student (Algorithm 1 plus the ODE
//! map) and the DP baseline, sharing one loop shape (seeded batches, scheduled AdamW, a progress
//! callback every `log_every` steps); [`recipe`] holds the settings of a run (their `Default` is
//! the recipe) and [`run`] turns a demonstration file into a checkpoint directory.
pub mod batch;
pub(crate) mod checks;
pub(crate) mod curve;
pub mod distill;
#[cfg(test)]
mod distill_tests;
pub mod dp;
#[cfg(test)]
mod dp_checkpoint_tests;
pub(crate) mod holdout;
mod monitor;
pub mod on_policy;
pub mod optim;
pub(crate) mod padding;
pub mod recipe;
pub mod run;
pub mod teacher;
#[cfg(test)]
mod tests;

use crate::models::OwnedNetwork;
use serde::{Deserialize, Serialize};

/// Settings shared by every trainer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LoopConfig {
    pub steps: usize,
    pub batch_size: usize,
    pub seed: u64,
    pub optim: optim::OptimConfig,
    /// Loss is averaged and reported every `log_every` steps.
    pub log_every: usize,
}

impl LoopConfig {
    /// docs/design.md defaults (batch 128, AdamW 1e-4, wd 1e-6, 500 warm-up, cosine) for `steps`.
    pub fn paper(steps: usize, seed: u64) -> Self {
        LoopConfig {
            steps,
            batch_size: 128,
            seed,
            optim: optim::OptimConfig::paper(steps),
            log_every: 100,
        }
    }

    /// A short run for toy data (`data::toy`): batch 64, lr 3e-3, 50 warm-up steps, the loss
    /// reported every 50 steps.
    pub fn toy(steps: usize, seed: u64) -> Self {
        let mut cfg = LoopConfig::paper(steps, seed);
        cfg.batch_size = 64;
        cfg.optim.lr = 3e-3;
        cfg.optim.warmup_steps = 50;
        cfg.log_every = 50;
        cfg
    }

    /// The same settings with peak learning rate `lr`.
    pub fn with_lr(mut self, lr: f64) -> Self {
        self.optim.lr = lr;
        self
    }
}

/// What a trainer reports to its caller while running.
pub struct Progress<'a> {
    /// Steps done so far (1-based count).
    pub step: usize,
    /// Mean loss since the last report.
    pub loss: f64,
    pub lr: f64,
    /// The network to evaluate at this point (the slow EMA for the student).
    pub model: &'a OwnedNetwork,
}

/// Training history for the checkpoint summary and the learning-curve plot.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct TrainReport {
    pub steps: usize,
    /// (step, mean loss over the preceding interval).
    pub loss_curve: Vec<(usize, f64)>,
    pub seconds: f64,
}

impl TrainReport {
    pub fn final_loss(&self) -> Option<f64> {
        self.loss_curve.last().map(|&(_, l)| l)
    }
}

/// Callback type: return an error to abort training.
pub type ProgressFn<'a> = dyn FnMut(&Progress<'_>) -> anyhow::Result<()> + 'a;

/// Runs `steps` iterations of `step_fn` (which returns the loss of one update), reporting
/// averaged losses every `log_every` steps and at the end.
pub(crate) fn run_loop(
    cfg: &LoopConfig,
    mut step_fn: impl FnMut(usize) -> anyhow::Result<(f64, f64)>,
    eval_model: &OwnedNetwork,
    progress: &mut ProgressFn<'_>,
) -> anyhow::Result<TrainReport> {
    let start = std::time::Instant::now();
    let mut report = TrainReport::default();
    let (mut sum, mut count) = (0.0, 0usize);
    for step in 0..cfg.steps {
        let (loss, lr) = step_fn(step)?;
        if !loss.is_finite() {
            anyhow::bail!("loss became {loss} at step {}", step + 1);
        }
        sum += loss;
        count += 1;
        let done = step + 1;
        if done % cfg.log_every.max(1) == 0 || done == cfg.steps {
            let mean = sum / count as f64;
            report.loss_curve.push((done, mean));
            progress(&Progress {
                step: done,
                loss: mean,
                lr,
                model: eval_model,
            })?;
            sum = 0.0;
            count = 0;
        }
    }
    report.steps = cfg.steps;
    report.seconds = start.elapsed().as_secs_f64();
    Ok(report)
}
