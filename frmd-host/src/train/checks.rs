//! Checks of a training run before any work: every option of the run configs against
//! [`crate::limits`], a student's model options against its teacher, the data against the task
//! it names, and the output directory (see `frmd_formats::artifact`).
use super::batch::CondAugment;
use super::recipe::{DpRun, ProbeConfig, StudentRun, StudentShape, TeacherRun, TrainConfig};
use crate::data::Dataset;
use crate::diffusion::samplers::Solver;
use crate::limits::{
    self, conflict, count, decay, non_negative, positive, probability, OptionError,
};
use crate::models::ModelConfig;
use anyhow::Context;
use std::path::Path;

impl TrainConfig {
    /// Counts, rates and the evaluation settings (the model's horizon is checked by the runs:
    /// a student takes its teacher's).
    pub fn validate(&self) -> Result<(), OptionError> {
        count("steps", self.steps, 1, limits::MAX_TRAIN_STEPS)?;
        count("batch", self.batch, 1, limits::MAX_BATCH)?;
        positive("lr", self.lr)?;
        non_negative("weight-decay", self.weight_decay)?;
        count("warmup", self.warmup, 0, limits::MAX_TRAIN_STEPS)?;
        count("pad-end", self.pad_end, 0, limits::MAX_PAD_END)?;
        positive("head-lr-scale", self.head_lr_scale)?;
        count("history", self.history, 1, limits::MAX_HISTORY)?;
        count("horizon", self.horizon, 1, limits::MAX_HORIZON)?;
        count("num-basis", self.num_basis, 1, limits::MAX_NUM_BASIS)?;
        if self.embed_dim == 0
            || !self.embed_dim.is_multiple_of(2)
            || self.embed_dim > limits::MAX_EMBED_DIM
        {
            return Err(limits::range(
                "embed-dim",
                self.embed_dim,
                format!("an even number from 2 to {}", limits::MAX_EMBED_DIM),
            ));
        }
        count("log-every", self.log_every, 1, limits::MAX_TRAIN_STEPS)?;
        count("eval-every", self.eval_every, 0, limits::MAX_TRAIN_STEPS)?;
        count("eval-episodes", self.eval_episodes, 0, limits::MAX_EPISODES)?;
        if let Some(steps) = self.eval_steps {
            count("eval-steps", steps, 1, limits::MAX_SAMPLER_STEPS)?;
        }
        Ok(())
    }

    /// Evaluation executes at most `horizon` actions of a chunk.
    fn validate_exec(&self, horizon: usize) -> Result<(), OptionError> {
        if (1..=horizon).contains(&self.exec_steps) {
            Ok(())
        } else {
            Err(limits::range(
                "exec-steps",
                self.exec_steps,
                format!("1 to the model's horizon {horizon}"),
            ))
        }
    }

    /// The output directory (empty or missing unless `force`, never holding an input) and the
    /// input files (they exist).
    pub fn check_paths(&self, extra_inputs: &[&Path]) -> anyhow::Result<()> {
        let mut inputs: Vec<&Path> = vec![&self.data];
        inputs.extend(self.holdout.as_deref());
        inputs.extend(extra_inputs);
        for input in &inputs {
            anyhow::ensure!(
                input.exists(),
                "{}: no such file or directory",
                input.display()
            );
        }
        frmd_formats::artifact::check_output_dir(&self.out, "--out", self.force, &inputs)
    }
}

fn validate_augment(a: &CondAugment) -> Result<(), OptionError> {
    probability("aug-prob", a.prob)?;
    non_negative("aug-y0-std", a.y0_std)?;
    non_negative("aug-v0-std", a.v0_std)?;
    non_negative("aug-obs-std", a.obs_std)
}

impl TeacherRun {
    pub fn validate(&self) -> Result<(), OptionError> {
        self.train.validate()?;
        self.train.validate_exec(self.train.horizon)?;
        probability(
            "sigma-uniform-fraction",
            self.teacher.sampling.uniform_fraction,
        )?;
        validate_augment(&self.teacher.augment)?;
        decay("ema", self.teacher.ema)
    }
}

impl DpRun {
    /// Also refuses the teacher/student-only options, which the DP baseline would ignore.
    pub fn validate(&self) -> Result<(), OptionError> {
        self.train.validate()?;
        if self.train.pad_end != 0 {
            return Err(conflict(
                "pad-end",
                "train dp",
                "end padding applies to the teacher and the student only",
            ));
        }
        if self.train.holdout.is_some() {
            return Err(conflict(
                "holdout",
                "train dp",
                "the held-out chunk error is measured for the teacher and the student only",
            ));
        }
        self.train.validate_exec(self.train.horizon)?;
        decay("ema", self.dp.eval_ema)
    }
}

impl StudentRun {
    /// The options alone; [`Self::validate_with_teacher`] checks them against the teacher.
    pub fn validate(&self) -> Result<(), OptionError> {
        self.train.validate()?;
        count("levels", self.distill.levels, 2, limits::MAX_SAMPLER_STEPS)?;
        count(
            "k",
            self.distill.teacher_steps,
            1,
            limits::MAX_SAMPLER_STEPS,
        )?;
        decay("target-ema", self.distill.target_ema)?;
        decay("eval-ema", self.distill.eval_ema)?;
        validate_augment(&self.distill.augment)?;
        count(
            "on-policy-rounds",
            self.on_policy_rounds,
            0,
            super::on_policy::MAX_ON_POLICY_ROUNDS,
        )?;
        count(
            "on-policy-episodes",
            self.on_policy_episodes,
            1,
            limits::MAX_EPISODES,
        )?;
        self.validate_objective()
    }

    /// The distillation objective's options (`train::distill::DistillConfig`).
    fn validate_objective(&self) -> Result<(), OptionError> {
        let d = &self.distill;
        if d.solver == Solver::DpmPp2m {
            return Err(conflict(
                "solver",
                "train student",
                "the steps between paired levels use euler or heun",
            ));
        }
        let start = d.levels_start.unwrap_or(d.levels);
        count("levels-start", start, 2, d.levels)?;
        count("k", d.teacher_steps, 1, start - 1)?;
        non_negative("anchor-sigma", d.anchor_sigma)?;
        non_negative("consistency-weight", d.consistency_weight)?;
        non_negative("map-weight", d.map_weight)?;
        non_negative("dsm-weight", d.dsm_weight)?;
        non_negative("on-policy-weight", d.on_policy_weight)?;
        positive("dsm-max-sigma", d.dsm_max_sigma)?;
        count("map-steps", d.map_steps, 1, limits::MAX_SAMPLER_STEPS)?;
        count("map-only-steps", d.map_only_steps, 0, self.train.steps)?;
        if d.consistency_weight == 0.0 && d.map_weight == 0.0 {
            return Err(conflict(
                "consistency-weight",
                "--map-weight 0",
                "with both terms off nothing is trained",
            ));
        }
        Ok(())
    }

    /// The student takes its shape from the teacher: a model option given for it must equal the
    /// teacher's (else it would be ignored).
    pub fn validate_with_teacher(&self, teacher: &ModelConfig) -> Result<(), OptionError> {
        let StudentShape {
            history,
            horizon,
            num_basis,
            backbone,
            embed_dim,
        } = &self.shape;
        let teacher_basis = teacher.prodmp().map(|p| p.num_basis);
        let differs: [(&'static str, Option<String>, String); 5] = [
            differing("history", *history, teacher.history),
            differing("horizon", *horizon, teacher.horizon),
            (
                "num-basis",
                num_basis
                    .filter(|&b| Some(b) != teacher_basis)
                    .map(|b| b.to_string()),
                teacher_basis.map(|b| b.to_string()).unwrap_or_default(),
            ),
            differing("backbone", backbone.as_ref(), &teacher.backbone),
            differing("embed-dim", *embed_dim, teacher.embed_dim),
        ];
        if let Some((option, Some(given), theirs)) = differs.into_iter().find(|d| d.1.is_some()) {
            return Err(conflict(option, "--teacher", format!("the student takes the teacher's model shape ({option} {theirs}), {given} would be ignored; drop --{option}")));
        }
        self.train.validate_exec(teacher.horizon)
    }
}

/// `(option, the student's value if given and not the teacher's, the teacher's value)`.
fn differing<T: PartialEq + std::fmt::Display>(
    option: &'static str,
    given: Option<T>,
    teacher: T,
) -> (&'static str, Option<String>, String) {
    let given = given.filter(|g| *g != teacher).map(|g| g.to_string());
    (option, given, teacher.to_string())
}

impl ProbeConfig {
    pub fn validate(&self) -> Result<(), OptionError> {
        count("windows", self.windows, 1, limits::MAX_CHECKS)?;
        if let Some(steps) = self.steps {
            count("steps", steps, 1, limits::MAX_SAMPLER_STEPS)?;
        }
        Ok(())
    }
}

/// The data fits the task it names when closed-loop evaluation will run on that task (checked
/// before training, not at the final evaluation): its observation and action sizes and control
/// period are the simulated task's. Data of tasks frmd-host does not simulate (e.g. MetaWorld)
/// trains without closed-loop evaluation (`train::monitor` says so).
pub fn check_data_task(data: &Dataset, path: &Path, eval_episodes: usize) -> anyhow::Result<()> {
    if eval_episodes == 0 || !crate::tasks::is_simulated(&data.task) {
        return Ok(());
    }
    let task = crate::tasks::make_task(&data.task)
        .with_context(|| format!("{}: metadata `task`", path.display()))?;
    for (field, have, want) in [
        ("obs_dim", data.obs_dim, task.obs_dim()),
        ("action_dim", data.action_dim, task.action_dim()),
    ] {
        anyhow::ensure!(
            have == want,
            "{}: {field} is {have}, task `{}` expects {want} (data of another task or version?)",
            path.display(),
            data.task
        );
    }
    let dt = f64::from(data.dt);
    anyhow::ensure!(
        (dt - task.dt()).abs() <= 1e-6 * task.dt(),
        "{}: metadata `dt` is {dt}, task `{}` runs at {}",
        path.display(),
        data.task,
        task.dt()
    );
    Ok(())
}
