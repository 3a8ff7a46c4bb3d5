//! Float policies from checkpoints: the teacher (ODE solver, S steps), the consistency student
//! (1..4 steps) and the DP baseline (DDPM 100 / DDIM S), all behind `tasks::Policy`.
//! Sampling noise comes from `frmd_core::rng::Rng` seeded by the episode seed, the same
//! generator the firmware uses.
use crate::checkpoint::{self, CheckpointMeta, Role};
use crate::data::Normalization;
use crate::diffusion::ddpm::{
    sample_dp, DdpmSchedule, DpSampler, EpsParametrization, DP_TRAIN_STEPS,
};
use crate::diffusion::samplers::{gaussian, sample_consistency, sample_teacher, Solver};
use crate::limits::{self, OptionError};
use crate::models::{Condition, OwnedNetwork};
use crate::tasks::{Policy, PolicyInput};
use anyhow::{bail, Context};
use candle_core::Device;
use frmd_core::rng::Rng;
use frmd_core::sigma::SigmaConfig;
use std::path::Path;

/// Key of the DP settings (`train::dp::DpConfig`) in a checkpoint's training summary.
pub const DP_TRAINING_KEY: &str = "dp";

/// The noise-network parametrization recorded in a DP checkpoint's training summary; checkpoints
/// written before it was recorded used `Direct`.
pub fn dp_parametrization(meta: &CheckpointMeta) -> anyhow::Result<EpsParametrization> {
    match meta.training.get(DP_TRAINING_KEY).and_then(|dp| dp.get("parametrization")) {
        None => Ok(EpsParametrization::Direct),
        Some(value) => serde_json::from_value(value.clone()).with_context(|| format!("checkpoint training.{DP_TRAINING_KEY}.parametrization {value} is not a DP parametrization")),
    }
}

/// How a float policy turns noise into a chunk.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Sampler {
    Teacher { solver: Solver, steps: usize },
    Student { steps: usize },
    Dp { sampler: DpSampler, steps: usize },
}

impl Sampler {
    /// Default sampler for a role: teacher Heun 10 steps (the solver can be overridden),
    /// student 1 step, DP DDIM 10 steps; `steps` overrides the count (DP: 100 means DDPM).
    /// Teacher and DP take 1 to `limits::MAX_SAMPLER_STEPS` steps; a solver is the teacher's
    /// alone (an error for the other roles, which have none to set).
    pub fn for_role(
        role: Role,
        steps: Option<usize>,
        solver: Option<Solver>,
    ) -> Result<Self, OptionError> {
        if let (Some(solver), Role::Student | Role::Dp) = (solver, role) {
            let sampler = if role == Role::Dp {
                "DDPM/DDIM (chosen by --steps)"
            } else {
                "the consistency sampler"
            };
            return Err(limits::conflict("solver", format!("a {role} checkpoint"), format!("only a teacher has an ODE solver to choose ({solver} given; this checkpoint uses {sampler})")));
        }
        Ok(match role {
            Role::Teacher => {
                let steps = steps.unwrap_or(10);
                limits::count("steps", steps, 1, limits::MAX_SAMPLER_STEPS)?;
                Sampler::Teacher {
                    solver: solver.unwrap_or(Solver::Heun),
                    steps,
                }
            }
            Role::Student => {
                let steps = steps.unwrap_or(1);
                limits::count("steps", steps, 1, 4)?;
                Sampler::Student { steps }
            }
            Role::Dp => match steps.unwrap_or(10) {
                0 => {
                    return Err(limits::range(
                        "steps",
                        0,
                        format!(
                            "1 to {} (DDIM; {DP_TRAIN_STEPS} = DDPM)",
                            limits::MAX_SAMPLER_STEPS
                        ),
                    ))
                }
                s if s > limits::MAX_SAMPLER_STEPS => {
                    return Err(limits::range(
                        "steps",
                        s,
                        format!(
                            "1 to {} (DDIM; {DP_TRAIN_STEPS} = DDPM)",
                            limits::MAX_SAMPLER_STEPS
                        ),
                    ))
                }
                DP_TRAIN_STEPS => Sampler::Dp {
                    sampler: DpSampler::Ddpm,
                    steps: DP_TRAIN_STEPS,
                },
                s => Sampler::Dp {
                    sampler: DpSampler::Ddim,
                    steps: s,
                },
            },
        })
    }

    pub fn label(&self) -> String {
        match self {
            Sampler::Teacher { solver, steps } => format!(
                "teacher-{}-{steps}",
                serde_json::to_value(solver)
                    .ok()
                    .and_then(|v| v.as_str().map(String::from))
                    .unwrap_or_default()
            ),
            Sampler::Student { steps } => format!("student-{steps}"),
            Sampler::Dp {
                sampler: DpSampler::Ddpm,
                steps,
            } => format!("dp-ddpm-{steps}"),
            Sampler::Dp {
                sampler: DpSampler::Ddim,
                steps,
            } => format!("dp-ddim-{steps}"),
        }
    }
}

/// A float model acting as a closed-loop policy.
pub struct FloatPolicy {
    net: OwnedNetwork,
    norm: Normalization,
    sigma: SigmaConfig,
    sampler: Sampler,
    schedule: DdpmSchedule,
    rng: Rng,
    device: Device,
}

impl FloatPolicy {
    /// Wraps an in-memory network (e.g. during training) with its normalization.
    pub fn new(
        net: OwnedNetwork,
        norm: Normalization,
        sigma: SigmaConfig,
        sampler: Sampler,
    ) -> anyhow::Result<Self> {
        let cfg = net.net.config();
        if norm.obs.min.len() != cfg.obs_dim || norm.action.min.len() != cfg.action_dim {
            bail!("normalization sizes (obs {}, action {}) do not match the model (obs {}, action {})", norm.obs.min.len(), norm.action.min.len(), cfg.obs_dim, cfg.action_dim);
        }
        match (sampler, cfg.prodmp().is_some()) {
            (Sampler::Dp { .. }, true) => bail!("DP sampling needs a raw-head model"),
            (Sampler::Teacher { .. } | Sampler::Student { .. }, false) => {
                bail!("teacher/student sampling needs a ProDMP-head model")
            }
            _ => {}
        }
        Ok(FloatPolicy {
            net,
            norm,
            sigma,
            sampler,
            schedule: DdpmSchedule::cosine(DP_TRAIN_STEPS),
            rng: Rng::new(0),
            device: Device::Cpu,
        })
    }

    /// Sets the noise-network parametrization used by DP sampling (default `Direct`).
    pub fn with_dp_parametrization(mut self, parametrization: EpsParametrization) -> Self {
        self.schedule = self.schedule.with_parametrization(parametrization);
        self
    }

    /// Loads a checkpoint directory; `steps`/`solver` override the role's default sampler.
    pub fn load(dir: &Path, steps: Option<usize>, solver: Option<Solver>) -> anyhow::Result<Self> {
        let (meta, net): (CheckpointMeta, OwnedNetwork) = checkpoint::load(dir)?;
        let norm = meta
            .normalization
            .clone()
            .with_context(|| format!("{}: checkpoint has no normalization", dir.display()))?;
        let sampler = Sampler::for_role(meta.role, steps, solver)?;
        let parametrization =
            dp_parametrization(&meta).with_context(|| format!("{}", dir.display()))?;
        Ok(FloatPolicy::new(net, norm, meta.sigma, sampler)?
            .with_dp_parametrization(parametrization))
    }

    /// (obs_dim, action_dim, history) the policy expects.
    pub fn input_sizes(&self) -> (usize, usize, usize) {
        let cfg = self.net.net.config();
        (cfg.obs_dim, cfg.action_dim, cfg.history)
    }

    /// The network's configuration (backbone, sizes).
    pub fn config(&self) -> &crate::models::ModelConfig {
        self.net.net.config()
    }

    pub fn sampler(&self) -> Sampler {
        self.sampler
    }

    /// The candle network.
    pub fn network(&self) -> &OwnedNetwork {
        &self.net
    }

    /// Observation and action normalization (raw units <-> [-1, 1]).
    pub fn normalization(&self) -> &Normalization {
        &self.norm
    }

    /// Noise levels of teacher and student sampling.
    pub fn sigma(&self) -> &SigmaConfig {
        &self.sigma
    }

    /// The DDPM schedule of DP sampling.
    pub fn schedule(&self) -> &DdpmSchedule {
        &self.schedule
    }

    /// One chunk in normalized units from normalized inputs: `obs` [m O], `y0`, `v0` \[k\].
    pub fn sample_normalized(
        &mut self,
        obs: &[f32],
        y0: &[f32],
        v0: &[f32],
    ) -> anyhow::Result<Vec<f32>> {
        let cfg = self.net.net.config().clone();
        let cond = Condition::from_slices(&cfg, obs, y0, v0, &self.device)?;
        let net = &self.net.net;
        let z = gaussian(&mut self.rng, 1, cfg.traj_dim(), &self.device)?;
        let out = match self.sampler {
            Sampler::Teacher { solver, steps } => sample_teacher(
                net,
                &self.sigma,
                &cond,
                (z * self.sigma.sigma_max)?,
                steps,
                solver,
            )?,
            Sampler::Student { steps } => {
                sample_consistency(net, &self.sigma, &cond, &z, steps, &mut self.rng)?
            }
            Sampler::Dp { sampler, steps } => {
                sample_dp(net, &self.schedule, &cond, z, sampler, steps, &mut self.rng)?
            }
        };
        Ok(out.flatten_all()?.to_vec1::<f32>()?)
    }
}

impl Policy for FloatPolicy {
    fn name(&self) -> String {
        self.sampler.label()
    }

    fn reset(&mut self, seed: u64) {
        self.rng = Rng::new(seed);
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> anyhow::Result<Vec<Vec<f32>>> {
        let cfg = self.net.net.config().clone();
        if input.obs_history.len() != cfg.history {
            bail!(
                "policy expects an observation history of {}, got {}",
                cfg.history,
                input.obs_history.len()
            );
        }
        let mut obs = Vec::with_capacity(cfg.history * cfg.obs_dim);
        for o in input.obs_history {
            if o.len() != cfg.obs_dim {
                bail!(
                    "observation has {} values, the model expects {}",
                    o.len(),
                    cfg.obs_dim
                );
            }
            let mut row = o.clone();
            self.norm.obs.normalize(&mut row);
            obs.extend(row);
        }
        if input.prev_action.len() != cfg.action_dim || input.prev_rate.len() != cfg.action_dim {
            bail!("previous action/rate must have {} values", cfg.action_dim);
        }
        let mut y0 = input.prev_action.to_vec();
        self.norm.action.normalize(&mut y0);
        let v0: Vec<f32> = input
            .prev_rate
            .iter()
            .zip(self.norm.action.scale())
            .map(|(r, s)| r * s)
            .collect();
        let mut chunk = self.sample_normalized(&obs, &y0, &v0)?;
        self.norm.action.denormalize(&mut chunk);
        Ok(chunk
            .chunks_exact(cfg.action_dim)
            .map(|a| a.to_vec())
            .collect())
    }

    fn horizon(&self) -> Option<usize> {
        Some(self.net.net.config().horizon)
    }
}

/// Loads a checkpoint as a boxed policy plus the observation history it needs.
pub fn boxed(
    dir: &Path,
    steps: Option<usize>,
    solver: Option<Solver>,
) -> anyhow::Result<(Box<dyn Policy>, usize)> {
    let policy = FloatPolicy::load(dir, steps, solver)?;
    let history = policy.net.net.config().history;
    Ok((Box::new(policy), history))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::toy::{toy_config, toy_normalization, toy_prodmp_config};
    use crate::models::{HeadConfig, ModelConfig};

    fn toy_policy(cfg: ModelConfig, sampler: Sampler) -> anyhow::Result<FloatPolicy> {
        let net = OwnedNetwork::new_seeded(&cfg, 2, &Device::Cpu)?;
        FloatPolicy::new(net, toy_normalization(), SigmaConfig::default(), sampler)
    }

    #[test]
    fn chunks_have_the_model_shape_and_are_reproducible_per_seed() {
        for (cfg, sampler) in [
            (toy_prodmp_config(), Sampler::Student { steps: 1 }),
            (toy_prodmp_config(), Sampler::Student { steps: 3 }),
            (
                toy_prodmp_config(),
                Sampler::Teacher {
                    solver: Solver::DpmPp2m,
                    steps: 4,
                },
            ),
            (
                toy_config(HeadConfig::Raw),
                Sampler::Dp {
                    sampler: DpSampler::Ddim,
                    steps: 10,
                },
            ),
        ] {
            let mut policy = toy_policy(cfg, sampler).unwrap();
            let obs = vec![vec![0.5f32]];
            let input = PolicyInput {
                obs_history: &obs,
                prev_action: &[15.0],
                prev_rate: &[1.0],
            };
            policy.reset(7);
            let a = policy.act(&input).unwrap();
            policy.reset(7);
            let b = policy.act(&input).unwrap();
            assert_eq!(a.len(), 4);
            assert!(a.iter().all(|row| row.len() == 1 && row[0].is_finite()));
            assert_eq!(a, b, "{}", policy.name());
            // Wrong history length is an error, not a panic.
            let two = vec![vec![0.5f32], vec![0.5f32]];
            assert!(policy
                .act(&PolicyInput {
                    obs_history: &two,
                    prev_action: &[15.0],
                    prev_rate: &[1.0]
                })
                .is_err());
        }
        assert!(Sampler::for_role(Role::Student, Some(5), None).is_err());
        assert!(toy_policy(toy_config(HeadConfig::Raw), Sampler::Student { steps: 1 }).is_err());
    }
}
