//! A training run from a demonstration file to a checkpoint directory (what `frmd train` does):
//! load and window the data, build the model of the recipe, train while the `Monitor` shows
//! progress and evaluates, then write the checkpoint (`model.safetensors` + `frmd.json` with the
//! training summary), the calibration rows beside a student (`calibration.safetensors`, so that
//! exporting needs only the checkpoint directory) and `learning_curve.png`.
use super::checks::check_data_task;
use super::curve::plot_learning_curve;
use super::distill::distill;
use super::dp::train_dp;
use super::holdout::{generalization, windows_in, ChunkSampler, GeneralizationReport};
use super::monitor::{HoldoutProbe, Monitor};
use super::on_policy::{add_windows, recorded_windows, student_round};
use super::padding::pad_episode_ends;
use super::recipe::{DpRun, ProbeConfig, StudentRun, TeacherRun, TrainConfig};
use super::teacher::train_teacher;
use super::{Progress, TrainReport};
use crate::checkpoint::{self, fnv1a_hex, CheckpointMeta, DatasetInfo, Role, CALIBRATION_FILE};
use crate::data::windows::CALIBRATION_ROWS;
use crate::data::{Dataset, Normalization, WindowSet};
use crate::diffusion::ddpm::DP_TRAIN_STEPS;
use crate::diffusion::samplers::Solver;
use crate::models::{HeadConfig, ModelConfig, OwnedNetwork};
use crate::policy::float::{Sampler, DP_TRAINING_KEY};
use anyhow::Context;
use frmd_core::sigma::SigmaConfig;
use serde_json::json;
use std::path::{Path, PathBuf};

/// What a finished run reports.
#[derive(Clone, Debug)]
pub struct RunOutcome {
    pub role: Role,
    pub steps: usize,
    pub seconds: f64,
    pub final_loss: Option<f64>,
    /// Success rate of the last closed-loop evaluation, if there was one.
    pub success: Option<f64>,
    /// The checkpoint directory.
    pub out: PathBuf,
}

impl std::fmt::Display for RunOutcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let success = self
            .success
            .map(|r| format!(", success {:.1} %", 100.0 * r))
            .unwrap_or_default();
        write!(
            f,
            "{:?}: {} steps in {:.1} s, final loss {:.5}{success}; checkpoint in {}",
            self.role,
            self.steps,
            self.seconds,
            self.final_loss.unwrap_or(f64::NAN),
            self.out.display()
        )
    }
}

/// The windowed demonstrations of a run.
struct Prepared {
    dataset: Dataset,
    windows: WindowSet,
    norm: Normalization,
    info: DatasetInfo,
}

/// Loads `cfg.data`, pads each episode's end by `pad_end` steps (`train::padding`) and cuts
/// windows of `history` and `horizon`.
fn prepare(
    cfg: &TrainConfig,
    history: usize,
    horizon: usize,
    pad_end: usize,
) -> anyhow::Result<Prepared> {
    let bytes = std::fs::read(&cfg.data)
        .with_context(|| format!("cannot read dataset {}", cfg.data.display()))?;
    let dataset = Dataset::from_bytes(&bytes)
        .with_context(|| format!("invalid dataset {}", cfg.data.display()))?;
    check_data_task(&dataset, &cfg.data, cfg.eval_episodes)?;
    let (windows, norm) = pad_episode_ends(&dataset, pad_end)?.windows(history, horizon)?;
    let info = DatasetInfo {
        task: dataset.task.clone(),
        path: cfg.data.display().to_string(),
        digest: fnv1a_hex(&bytes),
        windows: windows.len(),
    };
    Ok(Prepared {
        dataset,
        windows,
        norm,
        info,
    })
}

fn model_config(cfg: &TrainConfig, p: &Prepared, head: HeadConfig) -> ModelConfig {
    ModelConfig {
        obs_dim: p.dataset.obs_dim,
        history: cfg.history,
        action_dim: p.dataset.action_dim,
        horizon: cfg.horizon,
        control_dt: f64::from(p.dataset.dt),
        embed_dim: cfg.embed_dim,
        backbone: cfg.backbone.clone(),
        head,
    }
}

/// Writes the checkpoint and the student's calibration rows, then runs the final evaluation
/// (so that a failing evaluation never costs the trained model), records it in `frmd.json` and
/// draws the learning curve.
fn finish(
    role: Role,
    net: &OwnedNetwork,
    prepared: &Prepared,
    report: &TrainReport,
    mut mon: Monitor<'_>,
    extra: serde_json::Value,
) -> anyhow::Result<RunOutcome> {
    let cfg = mon.cfg;
    let mut meta = training_meta(role, net, prepared, report, &mon, extra.clone());
    checkpoint::save(&cfg.out, &meta, net)?;
    if role == Role::Student {
        let set = prepared
            .windows
            .calibration_rows(CALIBRATION_ROWS, cfg.seed);
        frmd_formats::calibration::write(&cfg.out.join(CALIBRATION_FILE), &set)?;
    }
    let evaluated = mon.evaluate(report.steps, net);
    mon.finish();
    evaluated.with_context(|| {
        format!(
            "final evaluation (the checkpoint is saved in {})",
            cfg.out.display()
        )
    })?;
    meta.training = training_meta(role, net, prepared, report, &mon, extra).training;
    checkpoint::save_meta(&cfg.out, &meta)?;
    plot_learning_curve(
        &cfg.out.join("learning_curve.png"),
        &prepared.info.task,
        role,
        &report.loss_curve,
        &mon.success,
    )?;
    Ok(RunOutcome {
        role,
        steps: report.steps,
        seconds: report.seconds,
        final_loss: report.final_loss(),
        success: mon
            .last_eval
            .as_ref()
            .and_then(|e| e["success_rate"].as_f64()),
        out: cfg.out.clone(),
    })
}

/// The checkpoint description of a finished run with its training summary so far.
fn training_meta(
    role: Role,
    net: &OwnedNetwork,
    prepared: &Prepared,
    report: &TrainReport,
    mon: &Monitor<'_>,
    mut extra: serde_json::Value,
) -> CheckpointMeta {
    let cfg = mon.cfg;
    let mut meta = CheckpointMeta::describe(role, net.net.config(), SigmaConfig::default());
    meta.normalization = Some(prepared.norm.clone());
    meta.dataset = prepared.info.clone();
    let summary = json!({
        "steps": report.steps, "seconds": report.seconds, "seed": cfg.seed, "batch_size": cfg.batch,
        "lr": cfg.lr, "weight_decay": cfg.weight_decay, "warmup_steps": cfg.warmup,
        "final_loss": report.final_loss(), "loss_curve": report.loss_curve, "success_curve": mon.success,
        "final_eval": mon.last_eval, "generalization": mon.generalization, "threads": std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "unset".into()),
    });
    if let (Some(obj), Some(add)) = (extra.as_object_mut(), summary.as_object()) {
        for (k, v) in add {
            obj.insert(k.clone(), v.clone());
        }
    }
    meta.training = extra;
    meta
}

/// Trains the ProDMP diffusion teacher of `run` and writes its checkpoint.
pub fn run_teacher(run: &TeacherRun) -> anyhow::Result<RunOutcome> {
    run.validate()?;
    let c = &run.train;
    c.check_paths(&[])?;
    let sigma = SigmaConfig::default();
    let prepared = prepare(c, c.history, c.horizon, c.pad_end)?;
    let model = model_config(
        c,
        &prepared,
        HeadConfig::ProDmp {
            num_basis: c.num_basis,
            output: run.output,
            auto_scale_basis: run.auto_scale_basis,
        },
    );
    let sampler = Sampler::for_role(Role::Teacher, c.eval_steps, run.eval_solver)?;
    let mut mon = Monitor::new(
        c,
        &prepared.dataset.task,
        &prepared.norm,
        sigma,
        sampler,
        "teacher",
    );
    let (solver, steps) = match sampler {
        Sampler::Teacher { solver, steps } => (solver, steps),
        _ => (Solver::Heun, 10),
    };
    mon.probe = HoldoutProbe::new(
        c,
        &prepared.dataset,
        &prepared.windows,
        &prepared.norm,
        ChunkSampler::Teacher { solver, steps },
    )?;
    let tcfg = run.teacher;
    let (net, report) = train_teacher(
        &prepared.windows,
        &model,
        &sigma,
        &tcfg,
        &c.loop_config(),
        &mut |p: &Progress| mon.on_progress(p),
    )?;
    let extra = json!({ "loss_weight": tcfg.weight, "sigma_sampling": tcfg.sampling, "augment": tcfg.augment, "teacher_ema": tcfg.ema });
    finish(Role::Teacher, &net, &prepared, &report, mon, extra)
}

/// Distills the one-step consistency student of `run` from its teacher and writes its
/// checkpoint with the calibration rows.
pub fn run_student(run: &StudentRun) -> anyhow::Result<RunOutcome> {
    run.validate()?;
    let c = &run.train;
    let mut inputs: Vec<&Path> = vec![&run.teacher];
    inputs.extend(run.on_policy_data.iter().map(|p| p.as_path()));
    c.check_paths(&inputs)?;
    let sigma = SigmaConfig::default();
    let (tmeta, teacher) = checkpoint::load(&run.teacher)
        .with_context(|| format!("loading teacher {}", run.teacher.display()))?;
    if tmeta.role != Role::Teacher {
        anyhow::bail!(
            "--teacher {}: this is a {} checkpoint, not a teacher",
            run.teacher.display(),
            tmeta.role
        );
    }
    let tcfg = teacher.net.config().clone();
    run.validate_with_teacher(&tcfg)?;
    let prepared = prepare(c, tcfg.history, tcfg.horizon, c.pad_end)?;
    let data = &prepared.dataset;
    if (data.obs_dim, data.action_dim) != (tcfg.obs_dim, tcfg.action_dim)
        || data.task != tmeta.dataset.task
    {
        anyhow::bail!("{}: task `{}` with obs_dim {} and action_dim {}; the teacher was trained on task `{}` with obs_dim {} and action_dim {}", c.data.display(), data.task, data.obs_dim, data.action_dim, tmeta.dataset.task, tcfg.obs_dim, tcfg.action_dim);
    }
    if let Some(tnorm) = &tmeta.normalization {
        if tnorm != &prepared.norm {
            anyhow::bail!(
                "the data's normalization differs from the teacher's (different data set?)"
            );
        }
    }
    let mut on_policy = recorded_windows(
        &run.on_policy_data,
        &data.task,
        tcfg.history,
        tcfg.horizon,
        &prepared.norm,
    )?;
    let rounds = run.on_policy_rounds;
    if rounds > 0 && !crate::tasks::is_simulated(&data.task) {
        anyhow::bail!("--on-policy-rounds: task `{}` is not simulated by frmd-host (reach, avoid, push, insert); record the student's rollouts with the task's own simulator and pass them with --on-policy-data", data.task);
    }
    let sampler = Sampler::for_role(Role::Student, c.eval_steps, None)?;
    let mut round = 0;
    let (distilled, mon) = loop {
        let mut mon = Monitor::new(
            c,
            &prepared.dataset.task,
            &prepared.norm,
            sigma,
            sampler,
            "student",
        );
        mon.probe = HoldoutProbe::new(
            c,
            &prepared.dataset,
            &prepared.windows,
            &prepared.norm,
            ChunkSampler::Student {
                steps: c.eval_steps.unwrap_or(1),
            },
        )?;
        let distilled = distill(
            &teacher,
            &prepared.windows,
            on_policy.as_ref(),
            &sigma,
            &run.distill,
            &c.loop_config(),
            &mut |p: &Progress| mon.on_progress(p),
        )?;
        if round == rounds {
            break (distilled, mon);
        }
        round += 1;
        let (visited, stats) = student_round(
            distilled.eval_student,
            &prepared.norm,
            sigma,
            &data.task,
            run.on_policy_episodes,
            round,
        )?;
        eprintln!(
            "student: on-policy round {round} of {}: the student succeeded in {} of {} recorded rollouts; distilling again from the teacher with the states it visited",
            rounds, stats.successes, run.on_policy_episodes
        );
        add_windows(&mut on_policy, visited)?;
    };
    let on_policy_data: Vec<String> = run
        .on_policy_data
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    let extra = json!({ "distill": run.distill, "teacher": run.teacher.display().to_string(), "teacher_digest": tmeta.dataset.digest, "on_policy_data": on_policy_data, "on_policy_rounds": rounds, "on_policy_episodes": run.on_policy_episodes });
    finish(
        Role::Student,
        &distilled.eval_student,
        &prepared,
        &distilled.report,
        mon,
        extra,
    )
}

/// Trains the action-space DP baseline of `run` and writes its checkpoint.
pub fn run_dp(run: &DpRun) -> anyhow::Result<RunOutcome> {
    run.validate()?;
    let c = &run.train;
    c.check_paths(&[])?;
    let prepared = prepare(c, c.history, c.horizon, 0)?;
    let model = model_config(c, &prepared, HeadConfig::Raw);
    let sampler = Sampler::for_role(Role::Dp, c.eval_steps, None)?;
    let mut mon = Monitor::new(
        c,
        &prepared.dataset.task,
        &prepared.norm,
        SigmaConfig::default(),
        sampler,
        "dp",
    );
    mon.dp_parametrization = run.dp.parametrization;
    let (net, report) = train_dp(
        &prepared.windows,
        &model,
        &c.loop_config(),
        &run.dp,
        &mut |p: &Progress| mon.on_progress(p),
    )?;
    let extra = json!({ "ddpm_train_steps": DP_TRAIN_STEPS, DP_TRAINING_KEY: run.dp });
    finish(Role::Dp, &net, &prepared, &report, mon, extra)
}

/// Open-loop chunk error of a teacher or student checkpoint on its training data and on
/// held-out demonstrations; returns the sampler used and the report.
pub fn run_probe(cfg: &ProbeConfig) -> anyhow::Result<(ChunkSampler, GeneralizationReport)> {
    cfg.validate()?;
    let (meta, net) =
        checkpoint::load(&cfg.ckpt).with_context(|| format!("loading {}", cfg.ckpt.display()))?;
    let norm = meta
        .normalization
        .clone()
        .with_context(|| format!("{}: checkpoint has no normalization", cfg.ckpt.display()))?;
    let model = net.net.config().clone();
    let sampler = match meta.role {
        Role::Teacher => ChunkSampler::Teacher {
            solver: cfg.solver,
            steps: cfg.steps.unwrap_or(10),
        },
        Role::Student => ChunkSampler::Student {
            steps: cfg.steps.unwrap_or(1),
        },
        Role::Dp => {
            anyhow::bail!("probe measures ProDMP teachers and students, not the DP baseline")
        }
    };
    let windows = |path: &Path| -> anyhow::Result<WindowSet> {
        windows_in(&Dataset::load(path)?, model.history, model.horizon, &norm)
    };
    let (train, held_out) = (windows(&cfg.data)?, windows(&cfg.holdout)?);
    let report = generalization(
        &net.net,
        &meta.sigma,
        sampler,
        &train,
        &held_out,
        &norm.action.scale(),
        cfg.windows,
        0,
    )?;
    Ok((sampler, report))
}
