//! `frmd train teacher|student|dp`: trains a model on a demonstration file, evaluates it in
//! closed loop on the task the data came from every `--eval-every` steps, and writes a checkpoint
//! (model.safetensors + frmd.json) and learning_curve.png into `--out`.
use crate::checkpoint::{self, fnv1a_hex, CheckpointMeta, DatasetInfo, Role};
use crate::data::{Dataset, Normalization, WindowSet};
use crate::diffusion::ddpm::EpsParametrization;
use crate::diffusion::loss::{LossWeight, SigmaSampling};
use crate::diffusion::samplers::Solver;
use crate::eval::{run_episodes, EvalConfig};
use crate::models::{BackboneConfig, HeadConfig, ModelConfig, OwnedNetwork};
use crate::policy::float::{FloatPolicy, Sampler, DP_TRAINING_KEY};
use crate::train::distill::{distill, DistillConfig};
use crate::train::optim::OptimConfig;
use crate::train::{curve::plot_learning_curve, dp::{train_dp, DpConfig}, teacher::train_teacher, LoopConfig, Progress, TrainReport};
use anyhow::Context;
use clap::{Args, Subcommand};
use frmd_core::sigma::SigmaConfig;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Subcommand, Debug)]
pub enum TrainCommand {
    /// The ProDMP diffusion teacher (EDM loss).
    Teacher(TeacherArgs),
    /// The one-step consistency student, distilled from `--teacher`.
    Student(StudentArgs),
    /// The action-space Diffusion Policy baseline (epsilon prediction, DDPM/DDIM).
    Dp(DpArgs),
}

#[derive(Args, Debug)]
pub struct CommonArgs {
    /// Demonstrations (.safetensors, DESIGN.md section 4).
    #[arg(long)]
    pub data: PathBuf,
    /// Output checkpoint directory.
    #[arg(long)]
    pub out: PathBuf,
    /// mlp | mlp-silu | mlp-paper | mlp:W1,W2,..[:silu|:mish] | transformer-lite | transformer.
    #[arg(long, default_value = "mlp")]
    pub backbone: String,
    /// Gradient steps.
    #[arg(long, default_value_t = 30000)]
    pub steps: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[arg(long, default_value_t = 128)]
    pub batch: usize,
    /// Peak learning rate (AdamW).
    #[arg(long, default_value_t = 1e-4)]
    pub lr: f64,
    #[arg(long, default_value_t = 1e-6)]
    pub weight_decay: f64,
    #[arg(long, default_value_t = 500)]
    pub warmup: usize,
    /// Observation history m.
    #[arg(long, default_value_t = 2)]
    pub history: usize,
    /// Prediction horizon n.
    #[arg(long, default_value_t = 12)]
    pub horizon: usize,
    /// ProDMP basis functions b.
    #[arg(long, default_value_t = 20)]
    pub num_basis: usize,
    /// Noise-embedding length.
    #[arg(long, default_value_t = 16)]
    pub embed_dim: usize,
    /// Loss is averaged and shown every this many steps.
    #[arg(long, default_value_t = 100)]
    pub log_every: usize,
    /// Closed-loop evaluation every this many steps (0: only at the end).
    #[arg(long, default_value_t = 0)]
    pub eval_every: usize,
    /// Episodes per evaluation (0 disables evaluation).
    #[arg(long, default_value_t = 20)]
    pub eval_episodes: usize,
    /// Actions executed per chunk in evaluation.
    #[arg(long, default_value_t = 8)]
    pub exec_steps: usize,
    /// Sampling steps used by evaluation (teacher default 10, student 1, DP 10).
    #[arg(long)]
    pub eval_steps: Option<usize>,
}

#[derive(Args, Debug)]
pub struct TeacherArgs {
    #[command(flatten)]
    pub common: CommonArgs,
    /// edm | inv-sigma2 | uniform. Default uniform: with the teacher's direct ProDMP output (no
    /// skip connection) the EDM weight (~1/sigma^2 for small sigma) left the reach teacher
    /// imprecise after 4000 steps (chunk error 0.088 vs 0.024 m, 0 % success either way at that
    /// budget; uniform reached 100 % at 20k steps).
    #[arg(long, default_value = "uniform")]
    pub loss_weight: String,
    /// Fraction of noise levels drawn log-uniformly on [sigma_min, sigma_max] instead of from
    /// the log-normal (covers the levels samplers and the student start from). Measured on
    /// avoid (MLP-SiLU, 20k steps): 0 % success with 0.0, 45 % with 0.2 (teacher D at sigma_max
    /// was an extrapolation).
    #[arg(long, default_value_t = 0.2)]
    pub sigma_uniform_fraction: f64,
    /// Solver for evaluation: euler | heun | dpm++2m.
    #[arg(long, default_value = "heun")]
    pub eval_solver: String,
}

#[derive(Args, Debug)]
pub struct StudentArgs {
    #[command(flatten)]
    pub common: CommonArgs,
    /// Teacher checkpoint directory.
    #[arg(long)]
    pub teacher: PathBuf,
    /// Karras levels N of the consistency discretization.
    #[arg(long, default_value_t = 18)]
    pub levels: usize,
    /// Teacher ODE steps K between paired levels.
    #[arg(long, default_value_t = 2)]
    pub k: usize,
    /// Teacher solver for those steps: euler | heun.
    #[arg(long, default_value = "heun")]
    pub solver: String,
    #[arg(long, default_value_t = 0.95)]
    pub target_ema: f64,
    /// Slow EMA of the student that is evaluated and saved.
    #[arg(long, default_value_t = 0.999)]
    pub eval_ema: f64,
}

#[derive(Args, Debug)]
pub struct DpArgs {
    #[command(flatten)]
    pub common: CommonArgs,
    /// Decay of the weight EMA that is evaluated and saved (0: the trained weights).
    #[arg(long, default_value_t = 0.999)]
    pub ema: f64,
    /// Noise network: direct (eps = F, Chi et al.) | preconditioned (EDM-style skip and
    /// scaling around F; see `diffusion::ddpm::EpsParametrization`).
    #[arg(long, default_value = "preconditioned")]
    pub parametrization: String,
}

struct Prepared {
    dataset: Dataset,
    windows: WindowSet,
    norm: Normalization,
    info: DatasetInfo,
}

fn prepare(common: &CommonArgs, history: usize, horizon: usize) -> anyhow::Result<Prepared> {
    let dataset = Dataset::load(&common.data).with_context(|| format!("loading {}", common.data.display()))?;
    let bytes = std::fs::read(&common.data)?;
    let (windows, norm) = dataset.windows(history, horizon)?;
    let info = DatasetInfo { task: dataset.task.clone(), path: common.data.display().to_string(), digest: fnv1a_hex(&bytes), windows: windows.len() };
    Ok(Prepared { dataset, windows, norm, info })
}

fn loop_config(c: &CommonArgs) -> LoopConfig {
    LoopConfig {
        steps: c.steps,
        batch_size: c.batch,
        seed: c.seed,
        optim: OptimConfig { lr: c.lr, weight_decay: c.weight_decay, warmup_steps: c.warmup, total_steps: c.steps, min_lr_ratio: 0.0 },
        log_every: c.log_every,
    }
}

fn model_config(c: &CommonArgs, p: &Prepared, head: HeadConfig) -> anyhow::Result<ModelConfig> {
    Ok(ModelConfig {
        obs_dim: p.dataset.obs_dim,
        history: c.history,
        action_dim: p.dataset.action_dim,
        horizon: c.horizon,
        control_dt: f64::from(p.dataset.dt),
        embed_dim: c.embed_dim,
        backbone: BackboneConfig::parse(&c.backbone)?,
        head,
    })
}

/// Progress bar + periodic evaluation, collecting the success curve.
struct Monitor<'a> {
    bar: ProgressBar,
    common: &'a CommonArgs,
    task: String,
    norm: Normalization,
    sigma: SigmaConfig,
    sampler: Sampler,
    /// Noise-network parametrization of a DP model (ignored for the other roles).
    dp_parametrization: EpsParametrization,
    success: Vec<(usize, f64)>,
    last_eval: Option<serde_json::Value>,
}

impl Monitor<'_> {
    fn evaluate(&mut self, step: usize, model: &OwnedNetwork) -> anyhow::Result<()> {
        if self.common.eval_episodes == 0 {
            return Ok(());
        }
        let mut policy = FloatPolicy::new(model.duplicate(&candle_core::Device::Cpu)?, self.norm.clone(), self.sigma, self.sampler)?.with_dp_parametrization(self.dp_parametrization);
        let cfg = EvalConfig { episodes: self.common.eval_episodes, exec_steps: self.common.exec_steps, history: model.net.config().history, ..EvalConfig::default() };
        let report = run_episodes(&self.task, &mut policy, &cfg)?;
        self.bar.println(format!(
            "step {step}: {} success {:.1} % over {} episodes, non-smooth {:.2}/episode, {:.0} us/chunk",
            report.policy, 100.0 * report.success_rate, report.episodes, report.non_smooth_ee_mean, report.latency_us_median
        ));
        self.success.push((step, report.success_rate));
        self.last_eval = Some(json!({ "step": step, "policy": report.policy, "success_rate": report.success_rate,
            "episodes": report.episodes, "non_smooth_ee_mean": report.non_smooth_ee_mean,
            "non_smooth_action_mean": report.non_smooth_action_mean, "latency_us_median": report.latency_us_median }));
        Ok(())
    }

    fn on_progress(&mut self, p: &Progress<'_>) -> anyhow::Result<()> {
        self.bar.set_position(p.step as u64);
        self.bar.set_message(format!("loss {:.5} lr {:.2e}", p.loss, p.lr));
        let every = self.common.eval_every;
        let at_end = p.step == self.common.steps;
        if (every > 0 && p.step % every < self.common.log_every.max(1) && p.step >= every) || at_end {
            self.evaluate(p.step, p.model)?;
        }
        Ok(())
    }
}

fn monitor<'a>(common: &'a CommonArgs, task: &str, norm: &Normalization, sampler: Sampler, label: &str) -> Monitor<'a> {
    let bar = ProgressBar::new(common.steps as u64);
    bar.set_style(ProgressStyle::with_template("{prefix} [{elapsed_precise}] {bar:30} {pos}/{len} {msg} (eta {eta})").unwrap_or_else(|_| ProgressStyle::default_bar()));
    bar.set_prefix(label.to_string());
    Monitor { bar, common, task: task.to_string(), norm: norm.clone(), sigma: SigmaConfig::default(), sampler, dp_parametrization: EpsParametrization::Direct, success: Vec::new(), last_eval: None }
}

#[allow(clippy::too_many_arguments)]
fn finish(
    out: &Path,
    role: Role,
    net: &OwnedNetwork,
    prepared: &Prepared,
    report: &TrainReport,
    mon: Monitor<'_>,
    mut extra: serde_json::Value,
) -> anyhow::Result<ExitCode> {
    mon.bar.finish_and_clear();
    let mut meta = CheckpointMeta::describe(role, net.net.config(), SigmaConfig::default());
    meta.normalization = Some(prepared.norm.clone());
    meta.dataset = prepared.info.clone();
    let common = mon.common;
    let summary = json!({
        "steps": report.steps, "seconds": report.seconds, "seed": common.seed, "batch_size": common.batch,
        "lr": common.lr, "weight_decay": common.weight_decay, "warmup_steps": common.warmup,
        "final_loss": report.final_loss(), "loss_curve": report.loss_curve, "success_curve": mon.success,
        "final_eval": mon.last_eval, "threads": std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "unset".into()),
    });
    if let (Some(obj), Some(add)) = (extra.as_object_mut(), summary.as_object()) {
        for (k, v) in add {
            obj.insert(k.clone(), v.clone());
        }
    }
    meta.training = extra;
    checkpoint::save(out, &meta, net)?;
    if role == Role::Student {
        // Calibration inputs for `frmd export` (a firmware build.rs then needs only this dir).
        let set = calibration_rows(&prepared.windows, CALIBRATION_ROWS, common.seed);
        frmd_export::calibration_file::write(&out.join(checkpoint::CALIBRATION_FILE), &set)?;
    }
    plot_learning_curve(&out.join("learning_curve.png"), &report.loss_curve, &mon.success)?;
    println!(
        "{role:?}: {} steps in {:.1} s, final loss {:.5}{}; checkpoint in {}",
        report.steps,
        report.seconds,
        report.final_loss().unwrap_or(f64::NAN),
        mon.last_eval.as_ref().and_then(|e| e["success_rate"].as_f64()).map(|r| format!(", success {:.1} %", 100.0 * r)).unwrap_or_default(),
        out.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// Calibration rows written beside a student checkpoint.
pub const CALIBRATION_ROWS: usize = 256;

/// Up to `rows` evenly spaced window conditions `[obs history, y0, v0]` (normalized), with a
/// noise seed derived from the training seed.
pub fn calibration_rows(windows: &WindowSet, rows: usize, seed: u64) -> frmd_export::calibrate::CalibrationSet {
    let (obs_w, k) = (windows.history * windows.obs_dim, windows.action_dim);
    let len = windows.len();
    let stride = (len / rows.max(1)).max(1);
    let mut cond = Vec::new();
    for i in (0..len).step_by(stride).take(rows) {
        cond.extend_from_slice(&windows.obs[i * obs_w..(i + 1) * obs_w]);
        cond.extend_from_slice(&windows.prev_action[i * k..(i + 1) * k]);
        cond.extend_from_slice(&windows.prev_rate[i * k..(i + 1) * k]);
    }
    frmd_export::calibrate::CalibrationSet { cond_dim: obs_w + 2 * k, cond, seed: seed ^ 0xca11_b4a7e }
}

pub fn run(cmd: TrainCommand) -> anyhow::Result<ExitCode> {
    let sigma = SigmaConfig::default();
    match cmd {
        TrainCommand::Teacher(args) => {
            let c = &args.common;
            let prepared = prepare(c, c.history, c.horizon)?;
            let model = model_config(c, &prepared, HeadConfig::ProDmp { num_basis: c.num_basis })?;
            let weight = LossWeight::parse(&args.loss_weight)?;
            let sampler = Sampler::for_role(Role::Teacher, c.eval_steps, Some(Solver::parse(&args.eval_solver)?))?;
            let mut mon = monitor(c, &prepared.dataset.task, &prepared.norm, sampler, "teacher");
            let sampling = SigmaSampling { uniform_fraction: args.sigma_uniform_fraction };
            let (net, report) = train_teacher(&prepared.windows, &model, &sigma, weight, sampling, &loop_config(c), &mut |p: &Progress| mon.on_progress(p))?;
            let extra = json!({ "loss_weight": weight, "sigma_sampling": sampling });
            finish(&c.out, Role::Teacher, &net, &prepared, &report, mon, extra)
        }
        TrainCommand::Student(args) => {
            let c = &args.common;
            let (tmeta, teacher) = checkpoint::load(&args.teacher).with_context(|| format!("loading teacher {}", args.teacher.display()))?;
            if tmeta.role != Role::Teacher {
                anyhow::bail!("{} holds a {:?} checkpoint, not a teacher", args.teacher.display(), tmeta.role);
            }
            let tcfg = teacher.net.config().clone();
            let prepared = prepare(c, tcfg.history, tcfg.horizon)?;
            if let Some(tnorm) = &tmeta.normalization {
                if tnorm != &prepared.norm {
                    anyhow::bail!("the data's normalization differs from the teacher's (different data set?)");
                }
            }
            let dcfg = DistillConfig { levels: args.levels, teacher_steps: args.k, solver: Solver::parse(&args.solver)?, target_ema: args.target_ema, eval_ema: args.eval_ema };
            let sampler = Sampler::for_role(Role::Student, c.eval_steps, None)?;
            let mut mon = monitor(c, &prepared.dataset.task, &prepared.norm, sampler, "student");
            let distilled = distill(&teacher, &prepared.windows, &sigma, &dcfg, &loop_config(c), &mut |p: &Progress| mon.on_progress(p))?;
            let extra = json!({ "distill": dcfg, "teacher": args.teacher.display().to_string(), "teacher_digest": tmeta.dataset.digest });
            finish(&c.out, Role::Student, &distilled.eval_student, &prepared, &distilled.report, mon, extra)
        }
        TrainCommand::Dp(args) => {
            let c = &args.common;
            let prepared = prepare(c, c.history, c.horizon)?;
            let model = model_config(c, &prepared, HeadConfig::Raw)?;
            let sampler = Sampler::for_role(Role::Dp, c.eval_steps, None)?;
            let dp = DpConfig { parametrization: EpsParametrization::parse(&args.parametrization)?, eval_ema: args.ema };
            let mut mon = monitor(c, &prepared.dataset.task, &prepared.norm, sampler, "dp");
            mon.dp_parametrization = dp.parametrization;
            let (net, report) = train_dp(&prepared.windows, &model, &loop_config(c), &dp, &mut |p: &Progress| mon.on_progress(p))?;
            let extra = json!({ "ddpm_train_steps": crate::train::dp::DP_TRAIN_STEPS, DP_TRAINING_KEY: dp });
            finish(&c.out, Role::Dp, &net, &prepared, &report, mon, extra)
        }
    }
}
