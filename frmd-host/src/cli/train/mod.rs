//! `frmd train teacher|student|dp|probe`: the flags of [`crate::train::recipe`]'s run configs
//! (every default is read from their `Default`), handed to [`crate::train::run`].
use crate::diffusion::consistency::{Distance, Jump, LevelSampling, LevelWeight};
use crate::diffusion::ddpm::EpsParametrization;
use crate::diffusion::loss::{LossWeight, SigmaSampling};
use crate::diffusion::samplers::Solver;
use crate::models::{BackboneConfig, ProDmpOutput};
use crate::train::batch::CondAugment;
use crate::train::distill::DistillConfig;
use crate::train::dp::DpConfig;
use crate::train::recipe::{DpRun, ProbeConfig, StudentRun, StudentShape, TeacherRun, TrainConfig};
use crate::train::run::{run_dp, run_probe, run_student, run_teacher};
use crate::train::teacher::TeacherConfig;
use clap::{Args, Subcommand};
use std::path::PathBuf;
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
    #[arg(long, default_value_t = ProbeConfig::default().solver)]
    pub solver: Solver,
    /// Windows measured per set (evenly spaced).
    #[arg(long, default_value_t = ProbeConfig::default().windows)]
    pub windows: usize,
}

/// Flags every training run shares ([`TrainConfig`]).
#[derive(Args, Debug)]
pub struct CommonArgs {
    /// Demonstrations (.safetensors, docs/design.md section 4).
    #[arg(long)]
    pub data: PathBuf,
    /// Output checkpoint directory (must be missing or empty unless --force).
    #[arg(long)]
    pub out: PathBuf,
    /// Write into a non-empty --out directory, replacing the checkpoint there.
    #[arg(long)]
    pub force: bool,
    /// mlp | mlp-silu | mlp-paper | mlp:W1,W2,..[:silu|:mish] | transformer-lite | transformer |
    /// transformer:LAYERS,HEADS,WIDTH (default: mlp). A student takes its teacher's.
    #[arg(long)]
    pub backbone: Option<BackboneConfig>,
    /// Gradient steps [default: teacher and dp 20000, student 3000].
    #[arg(long)]
    pub steps: Option<usize>,
    /// Seed of initialization, batches and noise.
    #[arg(long, default_value_t = TrainConfig::default().seed)]
    pub seed: u64,
    /// Batch size.
    #[arg(long, default_value_t = TrainConfig::default().batch)]
    pub batch: usize,
    /// Peak learning rate (AdamW, linear warm-up, cosine decay to zero) [default: teacher and dp
    /// 1e-3, student 1e-4].
    #[arg(long)]
    pub lr: Option<f64>,
    /// AdamW weight decay.
    #[arg(long, default_value_t = TrainConfig::default().weight_decay)]
    pub weight_decay: f64,
    /// Warm-up steps of the learning rate [default: teacher and dp 500, student 100].
    #[arg(long)]
    pub warmup: Option<usize>,
    /// Teacher and student: repeat each episode's final observation/action this many steps
    /// (hold-at-goal windows, see `train::padding`). An error with `train dp`.
    #[arg(long, default_value_t = TrainConfig::default().pad_end)]
    pub pad_end: usize,
    /// Learning-rate multiplier of the output (ProDMP parameter) layer, teacher and student
    /// (see `train::optim::ScheduledAdamW::for_network`; docs/experiments.md has measurements).
    #[arg(long, default_value_t = TrainConfig::default().head_lr_scale)]
    pub head_lr_scale: f64,
    /// Observation history m (default 2). A student takes its teacher's.
    #[arg(long)]
    pub history: Option<usize>,
    /// Prediction horizon n (default 12). A student takes its teacher's.
    #[arg(long)]
    pub horizon: Option<usize>,
    /// ProDMP basis functions b (default 20). A student takes its teacher's.
    #[arg(long)]
    pub num_basis: Option<usize>,
    /// Noise-embedding length (default 16). A student takes its teacher's.
    #[arg(long)]
    pub embed_dim: Option<usize>,
    /// Loss is averaged and shown every this many steps.
    #[arg(long, default_value_t = TrainConfig::default().log_every)]
    pub log_every: usize,
    /// Closed-loop evaluation every this many steps (0: only at the end).
    #[arg(long, default_value_t = TrainConfig::default().eval_every)]
    pub eval_every: usize,
    /// Episodes per evaluation (0 disables evaluation).
    #[arg(long, default_value_t = TrainConfig::default().eval_episodes)]
    pub eval_episodes: usize,
    /// Actions executed per chunk in evaluation.
    #[arg(long, default_value_t = TrainConfig::default().exec_steps)]
    pub exec_steps: usize,
    /// Sampling steps used by evaluation (teacher default 10, student 1, DP 10).
    #[arg(long)]
    pub eval_steps: Option<usize>,
    /// Held-out demonstrations (teacher and student): at every evaluation, the open-loop chunk
    /// error on up to 512 training windows and on this file's windows is printed and saved.
    #[arg(long)]
    pub holdout: Option<PathBuf>,
}

impl CommonArgs {
    /// The flags over a role's recipe (`recipe` gives the flags left out).
    fn over(self, recipe: TrainConfig) -> TrainConfig {
        let a = self;
        TrainConfig {
            data: a.data,
            out: a.out,
            force: a.force,
            backbone: a.backbone.unwrap_or(recipe.backbone),
            steps: a.steps.unwrap_or(recipe.steps),
            seed: a.seed,
            batch: a.batch,
            lr: a.lr.unwrap_or(recipe.lr),
            weight_decay: a.weight_decay,
            warmup: a.warmup.unwrap_or(recipe.warmup),
            pad_end: a.pad_end,
            head_lr_scale: a.head_lr_scale,
            history: a.history.unwrap_or(recipe.history),
            horizon: a.horizon.unwrap_or(recipe.horizon),
            num_basis: a.num_basis.unwrap_or(recipe.num_basis),
            embed_dim: a.embed_dim.unwrap_or(recipe.embed_dim),
            log_every: a.log_every,
            eval_every: a.eval_every,
            eval_episodes: a.eval_episodes,
            exec_steps: a.exec_steps,
            eval_steps: a.eval_steps,
            holdout: a.holdout,
        }
    }
}

#[derive(Args, Debug)]
pub struct TeacherArgs {
    #[command(flatten)]
    pub common: CommonArgs,
    /// Per-sample weight of the denoising loss: edm | inv-sigma2 | uniform.
    #[arg(long, default_value_t = TeacherConfig::default().weight)]
    pub loss_weight: LossWeight,
    /// Fraction of noise levels drawn log-uniformly on [sigma_min, sigma_max] instead of from
    /// the log-normal (covers the levels samplers and the student start from).
    #[arg(long, default_value_t = TeacherConfig::default().sampling.uniform_fraction)]
    pub sigma_uniform_fraction: f64,
    /// Output parametrization: direct (the decoded ProDMP trajectory is D, as in MPD) |
    /// boundary-skip (EDM skip on the free part of the chunk; y0/v0 stay exact).
    #[arg(long, default_value_t = TeacherRun::default().output)]
    pub parametrization: ProDmpOutput,
    /// Scale every ProDMP basis column to a largest value of 1 (mp_pytorch's auto_scale_basis):
    /// true | false.
    #[arg(long, default_value_t = TeacherRun::default().auto_scale_basis, action = clap::ArgAction::Set)]
    pub auto_scale_basis: bool,
    /// Solver for evaluation: euler | heun | dpm++2m (default: heun).
    #[arg(long)]
    pub eval_solver: Option<Solver>,
    /// EMA decay of the saved teacher weights (0: the raw weights).
    #[arg(long, default_value_t = TeacherConfig::default().ema)]
    pub ema: f64,
    #[command(flatten)]
    pub augment: AugmentArgs,
}

/// Initial-condition perturbation of training windows (see `train::batch::CondAugment`).
#[derive(Args, Debug, Clone)]
pub struct AugmentArgs {
    /// Fraction of training windows whose chunk start (y0, v0) is perturbed.
    #[arg(long, default_value_t = CondAugment::default().prob)]
    pub aug_prob: f64,
    /// Standard deviation of the y0 perturbation, normalized action units.
    #[arg(long, default_value_t = CondAugment::default().y0_std)]
    pub aug_y0_std: f64,
    /// Standard deviation of the v0 perturbation, normalized action units per second.
    #[arg(long, default_value_t = CondAugment::default().v0_std)]
    pub aug_v0_std: f64,
    /// Standard deviation of an offset added to the observations of a perturbed window
    /// (normalized units, the same offset for every frame of the history).
    #[arg(long, default_value_t = CondAugment::default().obs_std)]
    pub aug_obs_std: f64,
}

impl From<AugmentArgs> for CondAugment {
    fn from(a: AugmentArgs) -> Self {
        CondAugment {
            prob: a.aug_prob,
            y0_std: a.aug_y0_std,
            v0_std: a.aug_v0_std,
            obs_std: a.aug_obs_std,
        }
    }
}

impl From<TeacherArgs> for TeacherRun {
    fn from(a: TeacherArgs) -> Self {
        TeacherRun {
            train: a.common.over(TrainConfig::teacher_recipe()),
            teacher: TeacherConfig {
                weight: a.loss_weight,
                sampling: SigmaSampling {
                    uniform_fraction: a.sigma_uniform_fraction,
                },
                augment: a.augment.into(),
                ema: a.ema,
            },
            output: a.parametrization,
            auto_scale_basis: a.auto_scale_basis,
            eval_solver: a.eval_solver,
        }
    }
}

#[derive(Args, Debug)]
pub struct StudentArgs {
    #[command(flatten)]
    pub common: CommonArgs,
    /// Teacher checkpoint directory.
    #[arg(long)]
    pub teacher: PathBuf,
    /// Karras levels N of the consistency discretization.
    #[arg(long, default_value_t = DistillConfig::default().levels)]
    pub levels: usize,
    /// Teacher ODE steps K between paired levels.
    #[arg(long, default_value_t = DistillConfig::default().teacher_steps)]
    pub k: usize,
    /// Teacher solver for those steps: euler | heun.
    #[arg(long, default_value_t = DistillConfig::default().solver)]
    pub solver: Solver,
    /// EMA decay of the target network.
    #[arg(long, default_value_t = DistillConfig::default().target_ema)]
    pub target_ema: f64,
    /// Slow EMA decay of the student that is evaluated and saved.
    #[arg(long, default_value_t = DistillConfig::default().eval_ema)]
    pub eval_ema: f64,
    /// Output parametrization of the student: direct | boundary-skip (consistency skip on the
    /// free part of the chunk). Default: the teacher's.
    #[arg(long)]
    pub parametrization: Option<ProDmpOutput>,
    #[command(flatten)]
    pub augment: AugmentArgs,
    #[command(flatten)]
    pub objective: ObjectiveArgs,
    /// Recorded rollouts of a policy on this task (`frmd collect --policy`): the ODE-map term
    /// also runs on their states, labelled by the teacher (on-policy distillation). Repeatable.
    #[arg(long, value_name = "FILE")]
    pub on_policy_data: Vec<PathBuf>,
    /// On-policy rounds (tasks frmd-host simulates): distill, record --on-policy-episodes
    /// rollouts of the student, distill again from the teacher with the ODE-map term also on
    /// the states it visited; repeated this many times (each round costs one more distillation).
    #[arg(long, default_value_t = StudentRun::default().on_policy_rounds)]
    pub on_policy_rounds: usize,
    /// Student rollouts recorded per on-policy round.
    #[arg(long, default_value_t = StudentRun::default().on_policy_episodes)]
    pub on_policy_episodes: usize,
    /// Weight of the ODE-map term on the on-policy states.
    #[arg(long, default_value_t = DistillConfig::default().on_policy_weight)]
    pub on_policy_weight: f64,
}

/// The distillation objective (`train::distill::DistillConfig`, `diffusion::consistency`).
#[derive(Args, Debug)]
pub struct ObjectiveArgs {
    /// Distance between student and target: l2 | pseudo-huber.
    #[arg(long, default_value_t = DistillConfig::default().distance)]
    pub distance: Distance,
    /// Weight of a pair of levels: uniform | inverse-gap (1 / (sigma_high - sigma_low), mean 1).
    #[arg(long, default_value_t = DistillConfig::default().level_weight)]
    pub level_weight: LevelWeight,
    /// How the higher level of a pair is drawn: uniform | log-normal (over the grid).
    #[arg(long, default_value_t = DistillConfig::default().level_sampling)]
    pub level_sampling: LevelSampling,
    /// Curriculum: start with this many levels and double up to --levels in equal stages
    /// (default: --levels throughout).
    #[arg(long)]
    pub levels_start: Option<usize>,
    /// Pair levels: adjacent (K grid steps apart) | far (any lower level or 0, the teacher
    /// integrating in K Heun steps).
    #[arg(long, default_value_t = DistillConfig::default().jump)]
    pub jump: Jump,
    /// Pairs whose lower level is at most this take the teacher's denoised output as target
    /// (0: off).
    #[arg(long, default_value_t = DistillConfig::default().anchor_sigma)]
    pub anchor_sigma: f64,
    /// Weight of the consistency term (0: the ODE-map term alone).
    #[arg(long, default_value_t = DistillConfig::default().consistency_weight)]
    pub consistency_weight: f64,
    /// Weight of the ODE-map term: one student step from sigma_max z regressed on the teacher's
    /// DPM-Solver++(2M) solution from the same z (0: off).
    #[arg(long, default_value_t = DistillConfig::default().map_weight)]
    pub map_weight: f64,
    /// Teacher steps of the ODE-map solution.
    #[arg(long, default_value_t = DistillConfig::default().map_steps)]
    pub map_steps: usize,
    /// Warm start: train the ODE-map term alone for the first this many steps.
    #[arg(long, default_value_t = DistillConfig::default().map_only_steps)]
    pub map_only_steps: usize,
    /// Weight of an auxiliary denoising term on the student at low levels (0: off).
    #[arg(long, default_value_t = DistillConfig::default().dsm_weight)]
    pub dsm_weight: f64,
    /// Highest noise level of the denoising term.
    #[arg(long, default_value_t = DistillConfig::default().dsm_max_sigma)]
    pub dsm_max_sigma: f64,
}

impl From<StudentArgs> for StudentRun {
    fn from(a: StudentArgs) -> Self {
        let c = &a.common;
        let o = a.objective;
        let shape = StudentShape {
            history: c.history,
            horizon: c.horizon,
            num_basis: c.num_basis,
            backbone: c.backbone.clone(),
            embed_dim: c.embed_dim,
        };
        StudentRun {
            shape,
            train: a.common.over(TrainConfig::student_recipe()),
            teacher: a.teacher,
            distill: DistillConfig {
                levels: a.levels,
                teacher_steps: a.k,
                solver: a.solver,
                target_ema: a.target_ema,
                eval_ema: a.eval_ema,
                augment: a.augment.into(),
                output: a.parametrization,
                distance: o.distance,
                level_weight: o.level_weight,
                level_sampling: o.level_sampling,
                levels_start: o.levels_start,
                jump: o.jump,
                anchor_sigma: o.anchor_sigma,
                consistency_weight: o.consistency_weight,
                map_weight: o.map_weight,
                map_steps: o.map_steps,
                map_only_steps: o.map_only_steps,
                dsm_weight: o.dsm_weight,
                dsm_max_sigma: o.dsm_max_sigma,
                on_policy_weight: a.on_policy_weight,
            },
            on_policy_data: a.on_policy_data,
            on_policy_rounds: a.on_policy_rounds,
            on_policy_episodes: a.on_policy_episodes,
        }
    }
}

#[derive(Args, Debug)]
pub struct DpArgs {
    #[command(flatten)]
    pub common: CommonArgs,
    /// Decay of the weight EMA that is evaluated and saved (0: the trained weights).
    #[arg(long, default_value_t = DpConfig::default().eval_ema)]
    pub ema: f64,
    /// Noise network: direct (eps = F, Chi et al.) | preconditioned (EDM-style skip and
    /// scaling around F; see `diffusion::ddpm::EpsParametrization`).
    #[arg(long, default_value_t = DpConfig::default().parametrization)]
    pub parametrization: EpsParametrization,
}

impl From<DpArgs> for DpRun {
    fn from(a: DpArgs) -> Self {
        DpRun {
            train: a.common.over(TrainConfig::dp_recipe()),
            dp: DpConfig {
                parametrization: a.parametrization,
                eval_ema: a.ema,
            },
        }
    }
}

pub fn run(cmd: TrainCommand) -> anyhow::Result<ExitCode> {
    let outcome = match cmd {
        TrainCommand::Teacher(args) => run_teacher(&args.into())?,
        TrainCommand::Student(args) => run_student(&args.into())?,
        TrainCommand::Dp(args) => run_dp(&args.into())?,
        TrainCommand::Probe(a) => {
            let cfg = ProbeConfig {
                ckpt: a.ckpt,
                data: a.data,
                holdout: a.holdout,
                steps: a.steps,
                solver: a.solver,
                windows: a.windows,
            };
            let (sampler, report) = run_probe(&cfg)?;
            println!("{} {sampler:?}: {report}", cfg.ckpt.display());
            return Ok(ExitCode::SUCCESS);
        }
    };
    println!("{outcome}");
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests;
