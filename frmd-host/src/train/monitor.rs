//! What a training run does between optimizer steps: progress on stderr, the closed-loop
//! evaluation every `eval_every` steps and at the end (the success curve), and the open-loop
//! chunk error on training and held-out windows when `--holdout` data is given.
use super::holdout::{generalization, windows_in, ChunkSampler, GeneralizationReport};
use super::recipe::TrainConfig;
use super::Progress as StepProgress;
use crate::data::{Dataset, Normalization, WindowSet};
use crate::diffusion::ddpm::EpsParametrization;
use crate::eval::{run_episodes, EvalConfig};
use crate::models::OwnedNetwork;
use crate::policy::float::{FloatPolicy, Sampler};
use crate::progress::Progress;
use anyhow::Context;
use frmd_core::sigma::SigmaConfig;
use serde_json::json;

/// Windows per set of the open-loop generalization check.
const PROBE_WINDOWS: usize = 512;

/// Training and held-out windows for the open-loop generalization check.
pub(super) struct HoldoutProbe {
    train: WindowSet,
    held_out: WindowSet,
    sampler: ChunkSampler,
    action_scale: Vec<f32>,
}

impl HoldoutProbe {
    /// The probe of `cfg.holdout` (`None` without held-out data) against the training windows.
    pub(super) fn new(
        cfg: &TrainConfig,
        dataset: &Dataset,
        windows: &WindowSet,
        norm: &Normalization,
        sampler: ChunkSampler,
    ) -> anyhow::Result<Option<Self>> {
        let Some(path) = &cfg.holdout else {
            return Ok(None);
        };
        let data = Dataset::load(path)
            .with_context(|| format!("loading held-out data {}", path.display()))?;
        if data.obs_dim != dataset.obs_dim || data.action_dim != dataset.action_dim {
            anyhow::bail!(
                "held-out data {} has obs/action dims {}/{}, training data {}/{}",
                path.display(),
                data.obs_dim,
                data.action_dim,
                dataset.obs_dim,
                dataset.action_dim
            );
        }
        let held_out = windows_in(&data, windows.history, windows.horizon, norm)?;
        Ok(Some(HoldoutProbe {
            train: windows.clone(),
            held_out,
            sampler,
            action_scale: norm.action.scale(),
        }))
    }
}

/// Progress and periodic evaluation of one run, collecting the success curve.
pub(super) struct Monitor<'a> {
    progress: Progress,
    pub(super) cfg: &'a TrainConfig,
    task: String,
    norm: Normalization,
    sigma: SigmaConfig,
    sampler: Sampler,
    /// Noise-network parametrization of a DP model (ignored for the other roles).
    pub(super) dp_parametrization: EpsParametrization,
    pub(super) success: Vec<(usize, f64)>,
    pub(super) last_eval: Option<serde_json::Value>,
    pub(super) probe: Option<HoldoutProbe>,
    pub(super) generalization: Vec<(usize, GeneralizationReport)>,
}

impl<'a> Monitor<'a> {
    pub(super) fn new(
        cfg: &'a TrainConfig,
        task: &str,
        norm: &Normalization,
        sigma: SigmaConfig,
        sampler: Sampler,
        label: &str,
    ) -> Self {
        let progress = Progress::new(label, cfg.steps as u64, "step");
        if cfg.eval_episodes > 0 && !crate::tasks::is_simulated(task) {
            progress.println(&format!(
                "{label}: task {task:?} of {} is not simulated by frmd-host ({}): closed-loop evaluation skipped; evaluate the checkpoint with `frmd serve` and the task's own simulator",
                cfg.data.display(),
                crate::tasks::TASK_NAMES.join(", ")
            ));
        }
        Monitor {
            progress,
            cfg,
            task: task.to_string(),
            norm: norm.clone(),
            sigma,
            sampler,
            dp_parametrization: EpsParametrization::Direct,
            success: Vec::new(),
            last_eval: None,
            probe: None,
            generalization: Vec::new(),
        }
    }

    /// The held-out probe and the closed-loop evaluation of `model` at `step`.
    pub(super) fn evaluate(&mut self, step: usize, model: &OwnedNetwork) -> anyhow::Result<()> {
        if let Some(probe) = &self.probe {
            let report = generalization(
                &model.net,
                &self.sigma,
                probe.sampler,
                &probe.train,
                &probe.held_out,
                &probe.action_scale,
                PROBE_WINDOWS,
                self.cfg.seed,
            )?;
            self.progress.println(&format!("step {step}: {report}"));
            self.generalization.push((step, report));
        }
        if self.cfg.eval_episodes == 0 || !crate::tasks::is_simulated(&self.task) {
            return Ok(());
        }
        let mut policy = FloatPolicy::new(
            model.duplicate(&candle_core::Device::Cpu)?,
            self.norm.clone(),
            self.sigma,
            self.sampler,
        )?
        .with_dp_parametrization(self.dp_parametrization);
        let cfg = EvalConfig {
            episodes: self.cfg.eval_episodes,
            exec_steps: self.cfg.exec_steps,
            history: model.net.config().history,
            ..EvalConfig::default()
        };
        let report = run_episodes(&self.task, &mut policy, &cfg)?;
        self.progress.println(&format!(
            "step {step}: {} success {:.1} % over {} episodes, non-smooth {:.2}/episode, {:.0} us/chunk",
            report.policy, 100.0 * report.success_rate, report.episodes, report.non_smooth_ee_mean, report.latency_us_median
        ));
        self.success.push((step, report.success_rate));
        self.last_eval = Some(
            json!({ "step": step, "policy": report.policy, "success_rate": report.success_rate,
            "episodes": report.episodes, "non_smooth_ee_mean": report.non_smooth_ee_mean,
            "non_smooth_action_mean": report.non_smooth_action_mean, "latency_us_median": report.latency_us_median }),
        );
        Ok(())
    }

    /// The trainer's callback: shows progress and evaluates when due (the final evaluation runs
    /// after the checkpoint is saved, see `train::run`).
    pub(super) fn on_progress(&mut self, p: &StepProgress<'_>) -> anyhow::Result<()> {
        self.progress.update(
            p.step as u64,
            &format!("loss {:.5} lr {:.2e}", p.loss, p.lr),
        );
        let every = self.cfg.eval_every;
        let before_end = p.step < self.cfg.steps;
        if every > 0 && p.step % every < self.cfg.log_every.max(1) && p.step >= every && before_end
        {
            self.evaluate(p.step, p.model)?;
        }
        Ok(())
    }

    /// Removes the progress bar.
    pub(super) fn finish(&self) {
        self.progress.finish();
    }
}
