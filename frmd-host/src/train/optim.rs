//! AdamW with linear warm-up and cosine decay (DESIGN.md: lr 1e-4, weight decay 1e-6,
//! 500 warm-up steps, cosine to zero over the run).
use candle_core::Var;
use candle_nn::{AdamW, Optimizer, ParamsAdamW};
use serde::{Deserialize, Serialize};

/// Optimizer settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OptimConfig {
    pub lr: f64,
    pub weight_decay: f64,
    pub warmup_steps: usize,
    /// Gradient steps of the whole run (cosine decays to `lr * min_lr_ratio` at the end).
    pub total_steps: usize,
    pub min_lr_ratio: f64,
}

impl OptimConfig {
    pub fn paper(total_steps: usize) -> Self {
        OptimConfig { lr: 1e-4, weight_decay: 1e-6, warmup_steps: 500, total_steps, min_lr_ratio: 0.0 }
    }

    /// Learning rate at (0-based) `step`: linear warm-up from lr / warmup, then cosine decay.
    pub fn lr_at(&self, step: usize) -> f64 {
        if step < self.warmup_steps {
            return self.lr * (step + 1) as f64 / self.warmup_steps as f64;
        }
        let span = self.total_steps.saturating_sub(self.warmup_steps).max(1) as f64;
        let progress = ((step - self.warmup_steps) as f64 / span).min(1.0);
        let floor = self.lr * self.min_lr_ratio;
        floor + (self.lr - floor) * 0.5 * (1.0 + (std::f64::consts::PI * progress).cos())
    }
}

/// AdamW driven by an [`OptimConfig`] schedule.
pub struct ScheduledAdamW {
    inner: AdamW,
    cfg: OptimConfig,
    step: usize,
}

impl ScheduledAdamW {
    pub fn new(vars: Vec<Var>, cfg: OptimConfig) -> anyhow::Result<Self> {
        let params = ParamsAdamW { lr: cfg.lr_at(0), weight_decay: cfg.weight_decay, ..Default::default() };
        Ok(ScheduledAdamW { inner: AdamW::new(vars, params)?, cfg, step: 0 })
    }

    /// Backpropagates `loss`, applies one update at the scheduled learning rate.
    pub fn backward_step(&mut self, loss: &candle_core::Tensor) -> anyhow::Result<()> {
        self.inner.set_learning_rate(self.cfg.lr_at(self.step));
        self.inner.backward_step(loss)?;
        self.step += 1;
        Ok(())
    }

    pub fn current_lr(&self) -> f64 {
        self.cfg.lr_at(self.step)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn warmup_then_cosine() {
        let cfg = OptimConfig { lr: 1e-3, weight_decay: 0.0, warmup_steps: 10, total_steps: 110, min_lr_ratio: 0.0 };
        assert!((cfg.lr_at(0) - 1e-4).abs() < 1e-12);
        assert!((cfg.lr_at(9) - 1e-3).abs() < 1e-12);
        assert!((cfg.lr_at(10) - 1e-3).abs() < 1e-12);
        assert!((cfg.lr_at(60) - 5e-4).abs() < 1e-9);
        assert!(cfg.lr_at(110) < 1e-12);
    }
}
