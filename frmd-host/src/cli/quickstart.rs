//! `frmd quickstart`: the whole pipeline on a built-in task in one command ([`crate::quickstart`]),
//! then one table and the paths of plots and artifacts (all under `--out`).
use crate::models::BackboneConfig;
use crate::quickstart::{render, run_pipeline, QuickstartConfig};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug, Clone)]
pub struct QuickstartArgs {
    /// Built-in task: reach, avoid, push, insert.
    #[arg(long, default_value_t = QuickstartConfig::default().task)]
    pub task: String,
    /// Directory for demonstrations, checkpoints, plots and reports.
    #[arg(long, default_value_os_t = QuickstartConfig::default().out)]
    pub out: PathBuf,
    /// Expert demonstrations to collect.
    #[arg(long, default_value_t = QuickstartConfig::default().demos)]
    pub demos: usize,
    /// Teacher gradient steps.
    #[arg(long, default_value_t = QuickstartConfig::default().teacher.steps)]
    pub teacher_steps: usize,
    /// Student (consistency distillation) gradient steps.
    #[arg(long, default_value_t = QuickstartConfig::default().student.steps)]
    pub student_steps: usize,
    /// DP baseline gradient steps.
    #[arg(long, default_value_t = QuickstartConfig::default().dp.steps)]
    pub dp_steps: usize,
    /// Backbone shared by teacher, student and DP (see `frmd train --backbone`).
    #[arg(long, default_value_t = QuickstartConfig::default().backbone)]
    pub backbone: BackboneConfig,
    /// Batch size of every training run.
    #[arg(long, default_value_t = QuickstartConfig::default().batch)]
    pub batch: usize,
    /// Skip the DP baseline (training and evaluation).
    #[arg(long)]
    pub no_baseline: bool,
    /// Closed-loop evaluation episodes per method (docs/design.md asks for >= 50).
    #[arg(long, default_value_t = QuickstartConfig::default().episodes)]
    pub episodes: usize,
    /// Seed of collection and training.
    #[arg(long, default_value_t = QuickstartConfig::default().seed)]
    pub seed: u64,
    /// Write into a non-empty --out directory, replacing the run there.
    #[arg(long)]
    pub force: bool,
    /// CI smoke-test sizes: a few demos, tens of steps, a few episodes (numbers meaningless).
    #[arg(long, hide = true)]
    pub tiny: bool,
}

impl From<QuickstartArgs> for QuickstartConfig {
    fn from(a: QuickstartArgs) -> Self {
        let d = QuickstartConfig::default();
        let cfg = QuickstartConfig {
            task: a.task,
            out: a.out,
            demos: a.demos,
            teacher: crate::quickstart::StageRecipe {
                steps: a.teacher_steps,
                ..d.teacher
            },
            student: crate::quickstart::StageRecipe {
                steps: a.student_steps,
                ..d.student
            },
            dp: crate::quickstart::StageRecipe {
                steps: a.dp_steps,
                ..d.dp
            },
            backbone: a.backbone,
            batch: a.batch,
            baseline: d.baseline && !a.no_baseline,
            episodes: a.episodes,
            seed: a.seed,
            force: a.force,
        };
        if a.tiny {
            cfg.with_tiny_sizes()
        } else {
            cfg
        }
    }
}

pub fn run(args: QuickstartArgs) -> anyhow::Result<ExitCode> {
    let summary = run_pipeline(&args.into())?;
    println!();
    print!("{}", render(&summary));
    Ok(ExitCode::SUCCESS)
}
