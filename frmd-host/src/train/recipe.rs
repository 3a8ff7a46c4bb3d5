//! The training recipe: what a run of `frmd train teacher|student|dp` is given, as typed config
//! structs whose `Default` is the recipe. The command line maps its flags onto these structs
//! (its defaults are read from here), and the quick start and the tests build them in code. The
//! algorithm settings inside ([`TeacherConfig`], [`DistillConfig`], [`DpConfig`],
//! [`LoopConfig::paper`]) keep their own defaults; this module composes them.
use super::distill::DistillConfig;
use super::dp::DpConfig;
use super::optim::OptimConfig;
use super::teacher::TeacherConfig;
use super::LoopConfig;
use crate::diffusion::samplers::Solver;
use crate::eval::EvalConfig;
use crate::models::{BackboneConfig, ProDmpOutput};
use std::path::PathBuf;

/// Gradient steps of a run (the paper's 30k).
pub const PAPER_STEPS: usize = 30_000;

/// What every training run shares: data, output, model sizes, optimizer and the evaluation
/// during training.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainConfig {
    /// Demonstrations (`.safetensors`, docs/design.md section 4).
    pub data: PathBuf,
    /// Output checkpoint directory (must be missing or empty unless `force`).
    pub out: PathBuf,
    /// Write into a non-empty `out` (replacing the checkpoint files there).
    pub force: bool,
    pub backbone: BackboneConfig,
    /// Gradient steps.
    pub steps: usize,
    pub seed: u64,
    pub batch: usize,
    /// Peak learning rate (AdamW, linear warm-up, cosine decay to zero).
    pub lr: f64,
    pub weight_decay: f64,
    /// Warm-up steps.
    pub warmup: usize,
    /// Teacher and student: repeat each episode's final observation/action this many steps
    /// (`train::padding`).
    pub pad_end: usize,
    /// Learning-rate multiplier of the output (ProDMP parameter) layer
    /// (`train::optim::ScheduledAdamW::for_network`).
    pub head_lr_scale: f64,
    /// Observation history m.
    pub history: usize,
    /// Prediction horizon n.
    pub horizon: usize,
    /// ProDMP basis functions b.
    pub num_basis: usize,
    /// Length of the noise embedding.
    pub embed_dim: usize,
    /// The loss is averaged and reported every this many steps.
    pub log_every: usize,
    /// Closed-loop evaluation every this many steps (0: only at the end).
    pub eval_every: usize,
    /// Episodes per evaluation (0: no evaluation).
    pub eval_episodes: usize,
    /// Actions executed per chunk in evaluation.
    pub exec_steps: usize,
    /// Sampling steps of the evaluation (`None`: the role's default).
    pub eval_steps: Option<usize>,
    /// Held-out demonstrations (teacher and student): the open-loop chunk error on them and on
    /// training windows is reported at every evaluation.
    pub holdout: Option<PathBuf>,
}

impl Default for TrainConfig {
    /// The paper's optimizer and sizes (batch 128, AdamW lr 1e-4, weight decay 1e-6, 500 warm-up
    /// steps, 30k steps, m 2, n 12, 20 basis functions) with the MLP [256, 256, 256] backbone;
    /// data and output paths empty.
    fn default() -> Self {
        let paper = LoopConfig::paper(PAPER_STEPS, 0);
        let OptimConfig {
            lr,
            weight_decay,
            warmup_steps,
            head_lr_scale,
            ..
        } = paper.optim;
        TrainConfig {
            data: PathBuf::new(),
            out: PathBuf::new(),
            force: false,
            backbone: BackboneConfig::preset("mlp").expect("`mlp` is a preset"),
            steps: paper.steps,
            seed: paper.seed,
            batch: paper.batch_size,
            lr,
            weight_decay,
            warmup: warmup_steps,
            pad_end: 0,
            head_lr_scale,
            history: 2,
            horizon: 12,
            num_basis: 20,
            embed_dim: 16,
            log_every: paper.log_every,
            eval_every: 0,
            eval_episodes: 20,
            exec_steps: EvalConfig::default().exec_steps,
            eval_steps: None,
            holdout: None,
        }
    }
}

impl TrainConfig {
    /// The optimizer loop these settings describe.
    pub fn loop_config(&self) -> LoopConfig {
        LoopConfig {
            steps: self.steps,
            batch_size: self.batch,
            seed: self.seed,
            optim: OptimConfig {
                lr: self.lr,
                weight_decay: self.weight_decay,
                warmup_steps: self.warmup,
                total_steps: self.steps,
                min_lr_ratio: 0.0,
                head_lr_scale: self.head_lr_scale,
            },
            log_every: self.log_every,
        }
    }
}

impl TrainConfig {
    /// The teacher's schedule: 20k steps, lr 1e-3 (500 warm-up steps, cosine decay). The paper's
    /// lr 1e-4 left the MLP teachers imprecise at this budget (docs/experiments.md).
    pub fn teacher_recipe() -> Self {
        TrainConfig {
            steps: 20_000,
            lr: 1e-3,
            warmup: 500,
            ..TrainConfig::default()
        }
    }

    /// The student's schedule: 3,000 distillation steps, lr 1e-4, 100 warm-up steps (6,000 steps
    /// or lr 3e-4 measured no better, docs/design.md section 7).
    pub fn student_recipe() -> Self {
        TrainConfig {
            steps: 3_000,
            lr: 1e-4,
            warmup: 100,
            ..TrainConfig::default()
        }
    }

    /// The DP baseline's schedule: the teacher's (20k steps, lr 1e-3), so both get the same budget.
    pub fn dp_recipe() -> Self {
        Self::teacher_recipe()
    }
}

/// A teacher run (`frmd train teacher`).
#[derive(Clone, Debug, PartialEq)]
pub struct TeacherRun {
    pub train: TrainConfig,
    pub teacher: TeacherConfig,
    /// Output parametrization of the ProDMP head.
    pub output: ProDmpOutput,
    /// Scale every ProDMP basis column to a largest value of 1 (mp_pytorch's `auto_scale_basis`;
    /// `frmd_formats::checkpoint::HeadConfig::ProDmp`).
    pub auto_scale_basis: bool,
    /// ODE solver of the evaluation during training (`None`: the teacher sampler's default).
    pub eval_solver: Option<Solver>,
}

impl Default for TeacherRun {
    /// [`TrainConfig::teacher_recipe`], direct output (MPD's), basis scaling on (docs/design.md
    /// sections 2 and 3 give the measurements).
    fn default() -> Self {
        TeacherRun {
            train: TrainConfig::teacher_recipe(),
            teacher: TeacherConfig::default(),
            output: ProDmpOutput::Direct,
            auto_scale_basis: true,
            eval_solver: None,
        }
    }
}

/// A student run (`frmd train student`): consistency distillation of `teacher`.
#[derive(Clone, Debug, PartialEq)]
pub struct StudentRun {
    pub train: TrainConfig,
    /// Teacher checkpoint directory.
    pub teacher: PathBuf,
    pub distill: DistillConfig,
    /// Model options given for the student (they must equal the teacher's).
    pub shape: StudentShape,
    /// Recorded rollouts (`frmd collect --policy`) whose states the ODE-map term also labels
    /// with the teacher (empty: the demonstrations only).
    pub on_policy_data: Vec<PathBuf>,
    /// On-policy rounds run here (tasks frmd-host simulates): after distilling, the student's
    /// rollouts are recorded and the student is distilled again with their states. 0 in the
    /// recipe: one round lifted avoid and lowered insert (docs/experiments.md, "On-policy
    /// distillation").
    pub on_policy_rounds: usize,
    /// Rollouts recorded per round.
    pub on_policy_episodes: usize,
}

/// Model-shape options given for a student run. The student takes its shape from the teacher
/// (`train.history`, `train.horizon`, ... are not used); a value given here that differs from
/// the teacher's is an error rather than silently ignored
/// ([`StudentRun::validate_with_teacher`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StudentShape {
    pub history: Option<usize>,
    pub horizon: Option<usize>,
    pub num_basis: Option<usize>,
    pub backbone: Option<BackboneConfig>,
    pub embed_dim: Option<usize>,
}

impl Default for StudentRun {
    fn default() -> Self {
        StudentRun {
            train: TrainConfig::student_recipe(),
            teacher: PathBuf::new(),
            distill: DistillConfig::default(),
            shape: StudentShape::default(),
            on_policy_data: Vec::new(),
            on_policy_rounds: 0,
            on_policy_episodes: 100,
        }
    }
}

/// A DP-baseline run (`frmd train dp`).
#[derive(Clone, Debug, PartialEq)]
pub struct DpRun {
    pub train: TrainConfig,
    pub dp: DpConfig,
}

impl Default for DpRun {
    fn default() -> Self {
        DpRun {
            train: TrainConfig::dp_recipe(),
            dp: DpConfig::default(),
        }
    }
}

/// Open-loop chunk error of a teacher or student checkpoint on its training data and on held-out
/// demonstrations (`frmd train probe`).
#[derive(Clone, Debug, PartialEq)]
pub struct ProbeConfig {
    /// Teacher or student checkpoint directory.
    pub ckpt: PathBuf,
    /// The demonstrations it was trained on.
    pub data: PathBuf,
    /// Held-out demonstrations of the same task.
    pub holdout: PathBuf,
    /// Sampling steps (`None`: teacher 10, student 1).
    pub steps: Option<usize>,
    /// Teacher solver.
    pub solver: Solver,
    /// Windows measured per set (evenly spaced).
    pub windows: usize,
}

impl Default for ProbeConfig {
    fn default() -> Self {
        ProbeConfig {
            ckpt: PathBuf::new(),
            data: PathBuf::new(),
            holdout: PathBuf::new(),
            steps: None,
            solver: Solver::DpmPp2m,
            windows: 1024,
        }
    }
}
