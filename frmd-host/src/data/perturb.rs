//! Perturbed demonstrations (DART, Laskey et al. 2017): during collection the executed action is
//! the expert's action plus smooth random noise, while the dataset records the expert's clean
//! action at the state the noise led to. The demonstrations then show how the expert recovers
//! from small deviations, which a policy trained on unperturbed demonstrations never sees.
//!
//! The noise is an Ornstein-Uhlenbeck process per action dimension, sampled once per control
//! period: stationary standard deviation `std` (metres, since actions are position targets) and
//! correlation time `correlation_time` (seconds). Its stream is fixed by the episode seed.
use crate::tasks::rng::TaskRng;
use crate::tasks::{Policy, PolicyInput};
use std::cell::RefCell;
use std::rc::Rc;

/// Settings of the action noise; `std == 0` reproduces unperturbed collection exactly.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ActionNoise {
    /// Stationary standard deviation of the offset added to each action component, metres.
    pub std: f64,
    /// Time over which the offset's autocorrelation falls to 1/e, seconds.
    pub correlation_time: f64,
}

impl Default for ActionNoise {
    /// No perturbation (std 0) with a 0.5 s correlation time.
    fn default() -> Self {
        ActionNoise {
            std: 0.0,
            correlation_time: 0.5,
        }
    }
}

impl ActionNoise {
    /// Checks that both settings are finite and usable.
    pub fn validate(&self) -> anyhow::Result<()> {
        anyhow::ensure!(
            self.std.is_finite() && self.std >= 0.0,
            "perturbation std must be finite and >= 0 metres, got {}",
            self.std
        );
        anyhow::ensure!(
            self.correlation_time.is_finite() && self.correlation_time > 0.0,
            "perturbation correlation time must be finite and > 0 seconds, got {}",
            self.correlation_time
        );
        Ok(())
    }
}

/// One Ornstein-Uhlenbeck offset per action dimension, advanced once per control period.
struct OuProcess {
    rng: TaskRng,
    /// Per-period decay exp(-dt / correlation_time).
    decay: f64,
    std: f64,
    offset: Vec<f64>,
}

impl OuProcess {
    /// Starts in the stationary distribution, so the first steps are perturbed like the rest.
    fn new(noise: ActionNoise, dt: f64, dims: usize, seed: u64) -> Self {
        let mut rng = TaskRng::new(seed, b"collect/perturb");
        let offset = (0..dims).map(|_| noise.std * rng.gaussian()).collect();
        Self {
            rng,
            decay: (-dt / noise.correlation_time).exp(),
            std: noise.std,
            offset,
        }
    }

    fn advance(&mut self) {
        let innovation = self.std * (1.0 - self.decay * self.decay).sqrt();
        for x in &mut self.offset {
            *x = self.decay * *x + innovation * self.rng.gaussian();
        }
    }
}

/// Wraps an expert: returns perturbed chunks to the rollout and keeps the clean first action of
/// the latest chunk in a shared cell for the recorder. Meant for one executed step per chunk
/// (as collection runs experts).
pub struct PerturbedExpert {
    expert: Box<dyn Policy>,
    noise: ActionNoise,
    dt: f64,
    action_dim: usize,
    process: Option<OuProcess>,
    clean: Rc<RefCell<Vec<f32>>>,
}

impl PerturbedExpert {
    /// `dt` is the task's control period, seconds. The returned cell holds the expert's clean
    /// action for the step being executed.
    pub fn new(
        expert: Box<dyn Policy>,
        noise: ActionNoise,
        dt: f64,
        action_dim: usize,
    ) -> (Self, Rc<RefCell<Vec<f32>>>) {
        let clean = Rc::new(RefCell::new(Vec::new()));
        let wrapper = Self {
            expert,
            noise,
            dt,
            action_dim,
            process: None,
            clean: Rc::clone(&clean),
        };
        (wrapper, clean)
    }
}

impl Policy for PerturbedExpert {
    fn name(&self) -> String {
        format!("{}+noise", self.expert.name())
    }

    fn reset(&mut self, seed: u64) {
        self.expert.reset(seed);
        self.process = Some(OuProcess::new(self.noise, self.dt, self.action_dim, seed));
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> anyhow::Result<Vec<Vec<f32>>> {
        let mut chunk = self.expert.act(input)?;
        let first = chunk
            .first()
            .ok_or_else(|| anyhow::anyhow!("expert returned an empty chunk"))?;
        *self.clean.borrow_mut() = first.clone();
        let process = self
            .process
            .as_mut()
            .ok_or_else(|| anyhow::anyhow!("perturbed expert used before reset"))?;
        for action in &mut chunk {
            anyhow::ensure!(
                action.len() == process.offset.len(),
                "expert action has {} values, the noise has {}",
                action.len(),
                process.offset.len()
            );
            for (a, offset) in action.iter_mut().zip(&process.offset) {
                *a = (f64::from(*a) + offset) as f32;
            }
        }
        process.advance();
        Ok(chunk)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_have_the_requested_spread_and_memory() {
        let noise = ActionNoise {
            std: 0.02,
            correlation_time: 0.5,
        };
        let (mut values, mut lagged) = (Vec::new(), 0.0);
        for seed in 0..40 {
            let mut process = OuProcess::new(noise, 0.1, 2, seed);
            for _ in 0..500 {
                let before = process.offset.clone();
                process.advance();
                lagged += before[0] * process.offset[0];
                values.extend_from_slice(&process.offset);
            }
        }
        let n = values.len() as f64;
        let var = values.iter().map(|x| x * x).sum::<f64>() / n;
        assert!((var.sqrt() - 0.02).abs() < 0.002, "std {}", var.sqrt());
        // Lag-one autocorrelation exp(-0.1 / 0.5) = 0.819.
        let rho = lagged / (n / 2.0) / var;
        assert!((rho - 0.819).abs() < 0.03, "lag-1 autocorrelation {rho}");
    }
}
