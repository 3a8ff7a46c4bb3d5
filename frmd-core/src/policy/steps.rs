//! The step table: the constants of each sampling step, folded by the exporter from the sigma
//! schedule (see [`super::Sampler`]).

use super::PolicyError;
use crate::sigma::{SigmaConfig, SigmaError};

/// Most sampling steps a table may hold.
pub const MAX_STEPS: usize = 4;

/// Constants of one sampling step, folded by the exporter from the sigma schedule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepConstants {
    /// Noise level of this step (normalized action units).
    pub sigma: f32,
    /// Standard deviation of the fresh noise added to the previous output:
    /// `sqrt(sigma^2 - sigma_min^2)`; 0 for the first step (which starts from `sigma * z`).
    pub renoise_std: f32,
    /// Input scale `c_in(sigma) = 1 / sqrt(sigma^2 + sigma_data^2)`.
    pub c_in: f32,
    /// Skip scale `c_skip(sigma)`.
    pub c_skip: f32,
    /// Output scale `c_out(sigma)`.
    pub c_out: f32,
    /// Which of the network's noise-level variants this step uses (the noise embedding at
    /// `sigma` folded in: an MLP's first-layer bias, a transformer's noise token).
    pub noise_variant: u32,
}

impl StepConstants {
    /// All zero (a placeholder that fails [`Self::validate`]).
    pub const ZERO: Self = Self {
        sigma: 0.0,
        renoise_std: 0.0,
        c_in: 0.0,
        c_skip: 0.0,
        c_out: 0.0,
        noise_variant: 0,
    };

    /// The constants of consistency-sampling step `index` at noise level `sigma` under `config`
    /// (computed in f64): `c_in`, `c_skip`, `c_out` of [`SigmaConfig`], and for every step but the
    /// first (`index == 0`) `renoise_std = sqrt(sigma^2 - sigma_min^2)` (0 below `sigma_min`).
    pub fn consistency(config: &SigmaConfig, sigma: f64, index: u32) -> Result<Self, SigmaError> {
        let renoise = if index == 0 {
            0.0
        } else {
            libm::sqrt((sigma * sigma - config.sigma_min * config.sigma_min).max(0.0))
        };
        Ok(Self {
            sigma: sigma as f32,
            renoise_std: renoise as f32,
            c_in: config.c_in(sigma)? as f32,
            c_skip: config.c_skip(sigma)? as f32,
            c_out: config.c_out(sigma)? as f32,
            noise_variant: index,
        })
    }

    /// Checks one step: all values finite, `sigma > 0`, `c_in > 0`, `renoise_std >= 0`, and
    /// `renoise_std == 0` for the first step.
    pub fn validate(&self, first: bool) -> Result<(), PolicyError> {
        let values = [
            self.sigma,
            self.renoise_std,
            self.c_in,
            self.c_skip,
            self.c_out,
        ];
        let finite = values.iter().all(|v| v.is_finite());
        if !finite
            || self.sigma <= 0.0
            || self.c_in <= 0.0
            || self.renoise_std < 0.0
            || (first && self.renoise_std != 0.0)
        {
            return Err(PolicyError::InvalidStepConstants);
        }
        Ok(())
    }
}

/// Checks a whole table: `1..=MAX_STEPS` steps, each valid.
pub fn validate_steps(steps: &[StepConstants]) -> Result<(), PolicyError> {
    if steps.is_empty() || steps.len() > MAX_STEPS {
        return Err(PolicyError::StepCount);
    }
    steps
        .iter()
        .enumerate()
        .try_for_each(|(i, step)| step.validate(i == 0))
}

/// A step table held by value: up to [`MAX_STEPS`] steps (heapless style, so that a loaded blob's
/// configuration borrows nothing but the blob).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepTable {
    steps: [StepConstants; MAX_STEPS],
    len: usize,
}

impl StepTable {
    /// A copy of `steps` (a longer table keeps its first [`MAX_STEPS`] steps and fails
    /// [`Self::validate`]).
    pub fn new(steps: &[StepConstants]) -> Self {
        let mut table = Self {
            steps: [StepConstants::ZERO; MAX_STEPS],
            len: steps.len(),
        };
        for (slot, step) in table.steps.iter_mut().zip(steps) {
            *slot = *step;
        }
        table
    }

    /// The steps in order.
    pub fn as_slice(&self) -> &[StepConstants] {
        self.steps.get(..self.len).unwrap_or(&self.steps)
    }

    /// [`validate_steps`] of the table.
    pub fn validate(&self) -> Result<(), PolicyError> {
        if self.len > MAX_STEPS {
            return Err(PolicyError::StepCount);
        }
        validate_steps(self.as_slice())
    }
}
