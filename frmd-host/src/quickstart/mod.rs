//! The quick start: the whole pipeline on a built-in task, sized for minutes on two cores
//! (`frmd quickstart`). Stages, each the library function behind the matching command:
//!
//! 1. collect expert demonstrations ([`crate::data::collect`]),
//! 2. train the ProDMP diffusion teacher ([`crate::train::run::run_teacher`]),
//! 3. distill the one-step consistency student ([`crate::train::run::run_student`]),
//! 4. train the action-space DP baseline ([`crate::train::run::run_dp`]; skipped without
//!    [`QuickstartConfig::baseline`]),
//! 5. export the quantized student ([`crate::export`]: int16 activations for an MLP),
//! 6. evaluate expert, DP (DDPM 100 / DDIM 10), teacher (Heun 10), student (1 step) and the quantized
//!    student in closed loop with the metrics of docs/design.md section 6,
//!
//! then returns one table ([`render`]) and the paths of plots and artifacts (all under
//! [`QuickstartConfig::out`]). The step counts of [`QuickstartConfig::default`] follow
//! measurements on `reach` (docs/experiments.md, "Quick start").
use crate::data::collect::{collect_to_file, CollectConfig};
use crate::diffusion::samplers::Solver;
use crate::eval::plot::{plot_paths, PLOTTED_EPISODES};
use crate::eval::{evaluate as evaluate_episodes, expert_policy, EvalConfig, EvalReport};
use crate::limits::{self, OptionError};
use crate::models::BackboneConfig;
use crate::policy::float::FloatPolicy;
use crate::tasks::Policy;
use crate::train::recipe::{DpRun, StudentRun, TeacherRun, TrainConfig};
use crate::train::run::{run_dp, run_student, run_teacher};
use anyhow::Context;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

mod export_stage;
mod table;
#[cfg(test)]
mod tests;

pub use table::render;

/// Length and optimizer of one training stage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StageRecipe {
    /// Gradient steps.
    pub steps: usize,
    /// Peak learning rate.
    pub lr: f64,
    /// Warm-up steps (at most a fifth of the run).
    pub warmup: usize,
}

/// A quick-start run: the task, the sizes of every stage and where everything goes.
#[derive(Clone, Debug, PartialEq)]
pub struct QuickstartConfig {
    /// Built-in task: reach, avoid, push, insert.
    pub task: String,
    /// Directory for demonstrations, checkpoints, plots and reports.
    pub out: PathBuf,
    /// Expert demonstrations to collect.
    pub demos: usize,
    pub teacher: StageRecipe,
    /// Consistency distillation of the student.
    pub student: StageRecipe,
    /// The DP baseline.
    pub dp: StageRecipe,
    /// Backbone shared by teacher, student and DP.
    pub backbone: BackboneConfig,
    /// Batch size of every training run.
    pub batch: usize,
    /// Train and evaluate the DP baseline.
    pub baseline: bool,
    /// Closed-loop evaluation episodes per method (docs/design.md asks for >= 50).
    pub episodes: usize,
    /// Seed of collection and training.
    pub seed: u64,
    /// Write into a non-empty `out` (replacing an earlier run there).
    pub force: bool,
}

impl Default for QuickstartConfig {
    /// `reach`, 100 demonstrations, MLP [256, 256, 256] SiLU: teacher 15k steps at lr 1e-3,
    /// student 2.5k steps at lr 1e-4, DP 25k steps at lr 1e-3 (docs/experiments.md, "Quick
    /// start"), 50 evaluation episodes, into `runs/quickstart`.
    fn default() -> Self {
        let train = TrainConfig::default();
        QuickstartConfig {
            task: "reach".into(),
            out: PathBuf::from("runs/quickstart"),
            demos: CollectConfig::default().episodes,
            teacher: StageRecipe {
                steps: 15_000,
                lr: 1e-3,
                warmup: 500,
            },
            student: StageRecipe {
                steps: 2_500,
                lr: 1e-4,
                warmup: 100,
            },
            dp: StageRecipe {
                steps: 25_000,
                lr: 1e-3,
                warmup: 500,
            },
            backbone: BackboneConfig::preset("mlp-silu").expect("`mlp-silu` is a preset"),
            batch: train.batch,
            baseline: true,
            episodes: EvalConfig::default().episodes,
            seed: train.seed,
            force: false,
        }
    }
}

impl QuickstartConfig {
    /// The sizes of every stage, before any work.
    pub fn validate(&self) -> Result<(), OptionError> {
        limits::count("demos", self.demos, 1, limits::MAX_EPISODES)?;
        limits::count(
            "teacher-steps",
            self.teacher.steps,
            1,
            limits::MAX_TRAIN_STEPS,
        )?;
        limits::count(
            "student-steps",
            self.student.steps,
            1,
            limits::MAX_TRAIN_STEPS,
        )?;
        if self.baseline {
            limits::count("dp-steps", self.dp.steps, 1, limits::MAX_TRAIN_STEPS)?;
        }
        limits::count("batch", self.batch, 1, limits::MAX_BATCH)?;
        limits::count("episodes", self.episodes, 1, limits::MAX_EPISODES)?;
        CollectConfig {
            task: self.task.clone(),
            episodes: self.demos,
            seed: self.seed,
            ..CollectConfig::default()
        }
        .validate()
    }

    /// CI smoke-test sizes: 4 demonstrations, tens of steps, 3 episodes, batch 32 (numbers
    /// meaningless, the plumbing is what is tested).
    pub fn with_tiny_sizes(mut self) -> Self {
        (
            self.demos,
            self.teacher.steps,
            self.student.steps,
            self.dp.steps,
            self.episodes,
            self.batch,
        ) = (4, 30, 10, 30, 3, 32);
        self
    }

    /// The training settings of one stage: the recipe's, with this run's backbone, batch, seed
    /// and stage length; no evaluation during training (every method is evaluated afterwards
    /// with more episodes).
    fn train_config(&self, data: &Path, out: &Path, stage: StageRecipe) -> TrainConfig {
        TrainConfig {
            data: data.to_path_buf(),
            out: out.to_path_buf(),
            backbone: self.backbone.clone(),
            steps: stage.steps,
            seed: self.seed,
            batch: self.batch,
            lr: stage.lr,
            warmup: stage.warmup.min(stage.steps / 5),
            eval_episodes: 0,
            log_every: (stage.steps / 50).clamp(1, 100),
            // `run_pipeline` checked `out` as a whole.
            force: true,
            ..TrainConfig::default()
        }
    }
}

/// One method's line of the table.
#[derive(Debug, Serialize)]
pub struct MethodRow {
    /// Method label, e.g. `student-1`.
    pub method: String,
    /// Closed-loop report (None when the method was not available).
    pub report: Option<EvalReport>,
    /// Why the method was not evaluated.
    pub missing: Option<String>,
    /// Quantized-vs-float error (the quantized row only), e.g. `max 0.004 / mean 0.001 m`.
    pub quantized_error: Option<String>,
}

/// Everything a quickstart run produced.
#[derive(Debug, Serialize)]
pub struct QuickstartSummary {
    pub task: String,
    pub episodes: usize,
    pub rows: Vec<MethodRow>,
    /// (what, path) of every artifact.
    pub artifacts: Vec<(String, PathBuf)>,
    /// (stage, seconds).
    pub stage_seconds: Vec<(String, f64)>,
    pub total_seconds: f64,
    pub threads: String,
}

/// Prints the overall stage line before each stage and keeps the stage timings.
struct Stages {
    total: usize,
    done: usize,
    start: Instant,
    current: Option<(String, Instant)>,
    seconds: Vec<(String, f64)>,
}

impl Stages {
    fn new(total: usize) -> Self {
        Stages {
            total,
            done: 0,
            start: Instant::now(),
            current: None,
            seconds: Vec::new(),
        }
    }

    fn begin(&mut self, what: &str) {
        self.end();
        self.done += 1;
        let t = self.start.elapsed().as_secs();
        eprintln!(
            "==> quickstart [{}/{}] {what}   ({}:{:02} elapsed)",
            self.done,
            self.total,
            t / 60,
            t % 60
        );
        self.current = Some((what.to_string(), Instant::now()));
    }

    fn end(&mut self) {
        if let Some((what, started)) = self.current.take() {
            self.seconds.push((what, started.elapsed().as_secs_f64()));
        }
    }
}

/// Evaluates one policy, writes its JSON report and path plot, and returns its table row.
fn evaluate(
    a: &QuickstartConfig,
    method: &str,
    policy: &mut dyn Policy,
    history: usize,
    artifacts: &mut Vec<(String, PathBuf)>,
) -> anyhow::Result<MethodRow> {
    let cfg = EvalConfig {
        episodes: a.episodes,
        history,
        keep_paths: PLOTTED_EPISODES.min(a.episodes),
        ..EvalConfig::default()
    };
    let report =
        evaluate_episodes(&a.task, policy, &cfg).with_context(|| format!("evaluating {method}"))?;
    let plot = a.out.join("plots").join(format!("{method}.png"));
    plot_paths(&plot, &report)?;
    let json = a.out.join("eval").join(format!("{method}.json"));
    frmd_formats::artifact::write_atomic(&json, serde_json::to_string_pretty(&report)?.as_bytes())?;
    artifacts.push((format!("{method} paths plot"), plot));
    artifacts.push((format!("{method} report"), json));
    Ok(MethodRow {
        method: method.to_string(),
        report: Some(report),
        missing: None,
        quantized_error: None,
    })
}

fn float_row(
    a: &QuickstartConfig,
    dir: &Path,
    steps: usize,
    solver: Option<Solver>,
    artifacts: &mut Vec<(String, PathBuf)>,
) -> anyhow::Result<MethodRow> {
    let mut policy = FloatPolicy::load(dir, Some(steps), solver)
        .with_context(|| format!("loading {}", dir.display()))?;
    let history = policy.input_sizes().2;
    let name = policy.name();
    evaluate(a, &name, &mut policy, history, artifacts)
}

/// Runs every stage and returns the summary (does not print the table).
pub fn run_pipeline(a: &QuickstartConfig) -> anyhow::Result<QuickstartSummary> {
    a.validate()?;
    crate::tasks::make_task(&a.task)?;
    frmd_formats::artifact::check_output_dir(&a.out, "--out", a.force, &[])?;
    for dir in ["plots", "eval"] {
        std::fs::create_dir_all(a.out.join(dir))
            .with_context(|| format!("cannot create {}", a.out.join(dir).display()))?;
    }
    let mut stages = Stages::new(if a.baseline { 6 } else { 5 });
    let mut artifacts = Vec::new();
    let data = a.out.join(format!("{}-demos.safetensors", a.task));
    let (teacher, student, dp) = (
        a.out.join("teacher"),
        a.out.join("student"),
        a.out.join("dp"),
    );

    stages.begin(&format!(
        "collect {} expert demonstrations of `{}`",
        a.demos, a.task
    ));
    collect_to_file(&CollectConfig {
        task: a.task.clone(),
        episodes: a.demos,
        seed: a.seed,
        out: data.clone(),
        force: true,
        ..CollectConfig::default()
    })?;
    artifacts.push(("demonstrations".to_string(), data.clone()));

    stages.begin(&format!(
        "train teacher: {} steps, {}",
        a.teacher.steps, a.backbone
    ));
    let outcome = run_teacher(&TeacherRun {
        train: a.train_config(&data, &teacher, a.teacher),
        ..TeacherRun::default()
    })?;
    eprintln!("{outcome}");
    stages.begin(&format!("distill student: {} steps", a.student.steps));
    let outcome = run_student(&StudentRun {
        train: a.train_config(&data, &student, a.student),
        teacher: teacher.clone(),
        ..StudentRun::default()
    })?;
    eprintln!("{outcome}");
    if a.baseline {
        stages.begin(&format!(
            "train DP baseline: {} steps, {}",
            a.dp.steps, a.backbone
        ));
        let outcome = run_dp(&DpRun {
            train: a.train_config(&data, &dp, a.dp),
            ..DpRun::default()
        })?;
        eprintln!("{outcome}");
    }
    for (what, dir) in [("teacher", &teacher), ("student", &student), ("dp", &dp)] {
        if dir.exists() {
            artifacts.push((format!("{what} checkpoint + learning curve"), dir.clone()));
        }
    }

    stages.begin("export the quantized student");
    let quantized = export_stage::export_quantized(&student, &a.out);

    stages.begin(&format!("evaluate every method on {} episodes", a.episodes));
    let mut rows = Vec::new();
    let mut expert = expert_policy(&a.task)?;
    rows.push(evaluate(
        a,
        "expert",
        expert.as_mut(),
        EvalConfig::default().history,
        &mut artifacts,
    )?);
    if a.baseline {
        rows.push(float_row(a, &dp, 100, None, &mut artifacts)?);
        rows.push(float_row(a, &dp, 10, None, &mut artifacts)?);
    }
    rows.push(float_row(
        a,
        &teacher,
        10,
        Some(Solver::Heun),
        &mut artifacts,
    )?);
    rows.push(float_row(a, &student, 1, None, &mut artifacts)?);
    match quantized {
        Ok(mut export) => {
            artifacts.append(&mut export.artifacts);
            let mut row = evaluate(
                a,
                &export.label,
                export.policy.as_mut(),
                export.history,
                &mut artifacts,
            )?;
            row.quantized_error = Some(export.float_error);
            rows.push(row);
        }
        Err(reason) => rows.push(MethodRow {
            method: "quantized-student-1".into(),
            report: None,
            missing: Some(reason),
            quantized_error: None,
        }),
    }
    stages.end();
    let summary = QuickstartSummary {
        task: a.task.clone(),
        episodes: a.episodes,
        rows,
        artifacts,
        total_seconds: stages.start.elapsed().as_secs_f64(),
        stage_seconds: stages.seconds,
        threads: std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "unset".into()),
    };
    let json = a.out.join("summary.json");
    frmd_formats::artifact::write_atomic(
        &json,
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    frmd_formats::artifact::write_atomic(
        &a.out.join("summary.txt"),
        table::render(&summary).as_bytes(),
    )?;
    Ok(summary)
}
