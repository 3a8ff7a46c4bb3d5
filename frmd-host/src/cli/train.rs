//! `frmd train teacher|student|dp`: trains a model on a demonstration file, evaluates it in
//! closed loop on the task the data came from every `--eval-every` steps, and writes a checkpoint
//! (model.safetensors + frmd.json) and learning_curve.png into `--out`.
use crate::checkpoint::{self, fnv1a_hex, CheckpointMeta, DatasetInfo, Role};
use crate::data::{Dataset, Normalization, WindowSet};
use crate::diffusion::ddpm::EpsParametrization;
use crate::diffusion::loss::{LossWeight, SigmaSampling};
use crate::diffusion::samplers::Solver;
use crate::eval::{run_episodes, EvalConfig};
use crate::models::{BackboneConfig, HeadConfig, ProDmpOutput, ModelConfig, OwnedNetwork};
use crate::policy::float::{FloatPolicy, Sampler, DP_TRAINING_KEY};
use crate::train::distill::{distill, DistillConfig};
use crate::train::holdout::{generalization, windows_in, ChunkSampler, GeneralizationReport};
use crate::train::batch::CondAugment;
use crate::train::optim::OptimConfig;
use crate::train::padding::pad_episode_ends;
use crate::train::{curve::plot_learning_curve, dp::{train_dp, DpConfig}, teacher::{train_teacher, TeacherConfig}, LoopConfig, Progress, TrainReport};
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
    /// Open-loop chunk error of a teacher or student checkpoint on its training data and on
    /// held-out demonstrations (generalization vs underfitting).
    Probe(ProbeArgs),
}

#[derive(Args, Debug)]
pub struct ProbeArgs {
    /// Teacher or student checkpoint directory.
    #[arg(long)]
    pub ckpt: PathBuf,
    /// The demonstrations it was trained on.
    #[arg(long)]
    pub data: PathBuf,
    /// Held-out demonstrations of the same task (`frmd collect` with other seeds).
    #[arg(long)]
    pub holdout: PathBuf,
    /// Sampling steps (teacher default 10, student 1).
    #[arg(long)]
    pub steps: Option<usize>,
    /// Teacher solver: euler | heun | dpm++2m.
    #[arg(long, default_value = "dpm++2m")]
    pub solver: String,
    /// Windows measured per set (evenly spaced).
    #[arg(long, default_value_t = 1024)]
    pub windows: usize,
}

fn probe(args: &ProbeArgs) -> anyhow::Result<ExitCode> {
    let (meta, net) = checkpoint::load(&args.ckpt).with_context(|| format!("loading {}", args.ckpt.display()))?;
    let norm = meta.normalization.clone().with_context(|| format!("{}: checkpoint has no normalization", args.ckpt.display()))?;
    let cfg = net.net.config().clone();
    let sampler = match meta.role {
        Role::Teacher => ChunkSampler::Teacher { solver: Solver::parse(&args.solver)?, steps: args.steps.unwrap_or(10) },
        Role::Student => ChunkSampler::Student { steps: args.steps.unwrap_or(1) },
        Role::Dp => anyhow::bail!("probe measures ProDMP teachers and students, not the DP baseline"),
    };
    let train = windows_in(&Dataset::load(&args.data)?, cfg.history, cfg.horizon, &norm)?;
    let held_out = windows_in(&Dataset::load(&args.holdout)?, cfg.history, cfg.horizon, &norm)?;
    let report = generalization(&net.net, &meta.sigma.into(), sampler, &train, &held_out, &norm.action.scale(), args.windows, 0)?;
    println!("{} {:?}: {report}", args.ckpt.display(), sampler);
    Ok(ExitCode::SUCCESS)
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
    /// Teacher and student: repeat each episode's final observation/action this many steps
    /// (hold-at-goal windows, see `train::padding`). Not used by the DP baseline.
    #[arg(long, default_value_t = 0)]
    pub pad_end: usize,
    /// Learning-rate multiplier of the output (ProDMP parameter) layer, teacher and student
    /// (see `train::optim::ScheduledAdamW::for_network`). Measured (20k-step teacher,
    /// DPM++(2M)-10, 50 episodes): insert 18 / 22 % with 1 vs 46 / 30 % with 10 (seeds 0 / 1);
    /// push 6 % vs 12 % (seed 0); avoid 60 / 64 % with 1 vs 20 % with 10 (30 episodes). Use 10
    /// for the precision task (insert); the default stays 1.
    #[arg(long, default_value_t = 1.0)]
    pub head_lr_scale: f64,
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
    /// Held-out demonstrations (teacher and student): at every evaluation, the open-loop chunk
    /// error on up to 512 training windows and on this file's windows is printed and saved.
    #[arg(long)]
    pub holdout: Option<PathBuf>,
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
    /// Output parametrization: direct (the decoded ProDMP trajectory is D, as in MPD) |
    /// boundary-skip (EDM skip on the free part of the chunk; y0/v0 stay exact).
    #[arg(long, default_value = "direct")]
    pub parametrization: String,
    /// Scale every ProDMP basis column to a largest value of 1 (mp_pytorch's auto_scale_basis).
    #[arg(long)]
    pub auto_scale_basis: bool,
    /// Solver for evaluation: euler | heun | dpm++2m.
    #[arg(long, default_value = "heun")]
    pub eval_solver: String,
    /// EMA decay of the saved teacher weights (0: the raw weights). Measured on insert (8k
    /// steps, head lr x10): 0.999 gave held-out chunk error 8.5 vs 8.3 mm and the same 20 %
    /// success (30 episodes) — the cosine decay to zero already averages the last steps.
    #[arg(long, default_value_t = 0.0)]
    pub ema: f64,
    #[command(flatten)]
    pub augment: AugmentArgs,
}

/// Initial-condition perturbation of training windows (see `train::batch::CondAugment`).
#[derive(Args, Debug, Clone)]
pub struct AugmentArgs {
    /// Fraction of training windows whose chunk start (y0, v0) is perturbed.
    #[arg(long, default_value_t = 0.0)]
    pub aug_prob: f64,
    /// Standard deviation of the y0 perturbation, normalized action units.
    #[arg(long, default_value_t = 0.0)]
    pub aug_y0_std: f64,
    /// Standard deviation of the v0 perturbation, normalized action units per second.
    #[arg(long, default_value_t = 0.0)]
    pub aug_v0_std: f64,
}

impl Default for AugmentArgs {
    /// The command-line defaults (no perturbation).
    fn default() -> Self {
        AugmentArgs { aug_prob: 0.0, aug_y0_std: 0.0, aug_v0_std: 0.0 }
    }
}

impl AugmentArgs {
    fn config(&self) -> CondAugment {
        CondAugment { prob: self.aug_prob, y0_std: self.aug_y0_std, v0_std: self.aug_v0_std }
    }
}

#[derive(Args, Debug)]
pub struct StudentArgs {
    #[command(flatten)]
    pub common: CommonArgs,
    /// Teacher checkpoint directory.
    #[arg(long)]
    pub teacher: PathBuf,
    /// Karras levels N of the consistency discretization. Measured on avoid (v2 teacher, 3000
    /// steps, lr 1e-3, eval EMA 0.99, 30 episodes, one step): N = 10 0 %, 18 26.7 %, 40 36.7 %,
    /// 80 36.7 % (coarse levels make the K teacher steps between paired levels inaccurate).
    #[arg(long, default_value_t = 40)]
    pub levels: usize,
    /// Teacher ODE steps K between paired levels.
    #[arg(long, default_value_t = 2)]
    pub k: usize,
    /// Teacher solver for those steps: euler | heun.
    #[arg(long, default_value = "heun")]
    pub solver: String,
    #[arg(long, default_value_t = 0.95)]
    pub target_ema: f64,
    /// Slow EMA of the student that is evaluated and saved. 0.99 (an average over the last
    /// ~100 steps): with 0.999 and a 2-3k step run the saved EMA still holds a few percent of the
    /// initial weights, i.e. of the teacher's denoiser, whose one-step output is the mode average.
    #[arg(long, default_value_t = 0.99)]
    pub eval_ema: f64,
    /// Output parametrization of the student: direct | boundary-skip (consistency skip on the
    /// free part of the chunk). Default: the teacher's.
    #[arg(long)]
    pub parametrization: Option<String>,
    #[command(flatten)]
    pub augment: AugmentArgs,
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
    prepare_padded(common, history, horizon, 0)
}

/// [`prepare`] with each episode's end padded by `pad_end` steps (teacher and student, see
/// `train::padding`).
fn prepare_padded(common: &CommonArgs, history: usize, horizon: usize, pad_end: usize) -> anyhow::Result<Prepared> {
    let dataset = Dataset::load(&common.data).with_context(|| format!("loading {}", common.data.display()))?;
    let bytes = std::fs::read(&common.data)?;
    let (windows, norm) = pad_episode_ends(&dataset, pad_end)?.windows(history, horizon)?;
    let info = DatasetInfo { task: dataset.task.clone(), path: common.data.display().to_string(), digest: fnv1a_hex(&bytes), windows: windows.len() };
    Ok(Prepared { dataset, windows, norm, info })
}

fn loop_config(c: &CommonArgs) -> LoopConfig {
    LoopConfig {
        steps: c.steps,
        batch_size: c.batch,
        seed: c.seed,
        optim: OptimConfig { lr: c.lr, weight_decay: c.weight_decay, warmup_steps: c.warmup, total_steps: c.steps, min_lr_ratio: 0.0, head_lr_scale: c.head_lr_scale },
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
    probe: Option<HoldoutProbe>,
    generalization: Vec<(usize, GeneralizationReport)>,
}

/// Training and held-out windows for the open-loop generalization check.
struct HoldoutProbe {
    train: WindowSet,
    held_out: WindowSet,
    sampler: ChunkSampler,
    action_scale: Vec<f32>,
}

/// Windows per set used by the generalization check.
const PROBE_WINDOWS: usize = 512;

fn holdout_probe(common: &CommonArgs, prepared: &Prepared, history: usize, horizon: usize, sampler: ChunkSampler) -> anyhow::Result<Option<HoldoutProbe>> {
    let Some(path) = &common.holdout else { return Ok(None) };
    let data = Dataset::load(path).with_context(|| format!("loading held-out data {}", path.display()))?;
    if data.obs_dim != prepared.dataset.obs_dim || data.action_dim != prepared.dataset.action_dim {
        anyhow::bail!("held-out data {} has obs/action dims {}/{}, training data {}/{}", path.display(), data.obs_dim, data.action_dim, prepared.dataset.obs_dim, prepared.dataset.action_dim);
    }
    let held_out = windows_in(&data, history, horizon, &prepared.norm)?;
    Ok(Some(HoldoutProbe { train: prepared.windows.clone(), held_out, sampler, action_scale: prepared.norm.action.scale() }))
}

impl Monitor<'_> {
    fn evaluate(&mut self, step: usize, model: &OwnedNetwork) -> anyhow::Result<()> {
        if let Some(probe) = &self.probe {
            let report = generalization(&model.net, &self.sigma, probe.sampler, &probe.train, &probe.held_out, &probe.action_scale, PROBE_WINDOWS, self.common.seed)?;
            self.bar.println(format!("step {step}: {report}"));
            self.generalization.push((step, report));
        }
        if self.common.eval_episodes == 0 || !crate::tasks::is_simulated(&self.task) {
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
    if common.eval_episodes > 0 && !crate::tasks::is_simulated(task) {
        eprintln!("{label}: task {task:?} of {} is not simulated by frmd-host ({}): closed-loop evaluation skipped; evaluate the checkpoint with `frmd serve` and the task's own simulator", common.data.display(), crate::tasks::TASK_NAMES.join(", "));
    }
    Monitor { bar, common, task: task.to_string(), norm: norm.clone(), sigma: SigmaConfig::default(), sampler, dp_parametrization: EpsParametrization::Direct, success: Vec::new(), last_eval: None, probe: None, generalization: Vec::new() }
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
        "final_eval": mon.last_eval, "generalization": mon.generalization, "threads": std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "unset".into()),
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
            let prepared = prepare_padded(c, c.history, c.horizon, c.pad_end)?;
            let output = ProDmpOutput::parse(&args.parametrization)?;
            let model = model_config(c, &prepared, HeadConfig::ProDmp { num_basis: c.num_basis, output, auto_scale_basis: args.auto_scale_basis })?;
            let weight = LossWeight::parse(&args.loss_weight)?;
            let sampler = Sampler::for_role(Role::Teacher, c.eval_steps, Some(Solver::parse(&args.eval_solver)?))?;
            let mut mon = monitor(c, &prepared.dataset.task, &prepared.norm, sampler, "teacher");
            let (solver, steps) = match sampler {
                Sampler::Teacher { solver, steps } => (solver, steps),
                _ => (Solver::Heun, 10),
            };
            mon.probe = holdout_probe(c, &prepared, c.history, c.horizon, ChunkSampler::Teacher { solver, steps })?;
            let sampling = SigmaSampling { uniform_fraction: args.sigma_uniform_fraction };
            let tcfg = TeacherConfig { weight, sampling, augment: args.augment.config(), ema: args.ema };
            let (net, report) = train_teacher(&prepared.windows, &model, &sigma, &tcfg, &loop_config(c), &mut |p: &Progress| mon.on_progress(p))?;
            let extra = json!({ "loss_weight": weight, "sigma_sampling": sampling, "augment": tcfg.augment, "teacher_ema": tcfg.ema });
            finish(&c.out, Role::Teacher, &net, &prepared, &report, mon, extra)
        }
        TrainCommand::Student(args) => {
            let c = &args.common;
            let (tmeta, teacher) = checkpoint::load(&args.teacher).with_context(|| format!("loading teacher {}", args.teacher.display()))?;
            if tmeta.role != Role::Teacher {
                anyhow::bail!("{} holds a {:?} checkpoint, not a teacher", args.teacher.display(), tmeta.role);
            }
            let tcfg = teacher.net.config().clone();
            let prepared = prepare_padded(c, tcfg.history, tcfg.horizon, c.pad_end)?;
            if let Some(tnorm) = &tmeta.normalization {
                if tnorm != &prepared.norm {
                    anyhow::bail!("the data's normalization differs from the teacher's (different data set?)");
                }
            }
            let dcfg = DistillConfig { levels: args.levels, teacher_steps: args.k, solver: Solver::parse(&args.solver)?, target_ema: args.target_ema, eval_ema: args.eval_ema, augment: args.augment.config(), output: args.parametrization.as_deref().map(ProDmpOutput::parse).transpose()? };
            let sampler = Sampler::for_role(Role::Student, c.eval_steps, None)?;
            let mut mon = monitor(c, &prepared.dataset.task, &prepared.norm, sampler, "student");
            mon.probe = holdout_probe(c, &prepared, tcfg.history, tcfg.horizon, ChunkSampler::Student { steps: c.eval_steps.unwrap_or(1) })?;
            let distilled = distill(&teacher, &prepared.windows, &sigma, &dcfg, &loop_config(c), &mut |p: &Progress| mon.on_progress(p))?;
            let extra = json!({ "distill": dcfg, "teacher": args.teacher.display().to_string(), "teacher_digest": tmeta.dataset.digest });
            finish(&c.out, Role::Student, &distilled.eval_student, &prepared, &distilled.report, mon, extra)
        }
        TrainCommand::Probe(args) => probe(&args),
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
