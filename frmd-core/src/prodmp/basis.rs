//! Exponential-decay phase and normalized Gaussian RBFs in phase space, as in mp_pytorch 0.1.4
//! (`ExpDecayPhaseGenerator`, `NormalizedRBFBasisGenerator`), in f64.

use super::config::{ProDmpConfig, MAX_NUM_BASIS};
use super::ProDmpError;

/// Value `index` of `torch.linspace(start, end, steps)` (float64, CPU): the first half counts up
/// from `start`, the second half down from `end`, so both ends are exact.
pub(crate) fn torch_linspace(start: f64, end: f64, steps: usize, index: usize) -> f64 {
    if steps <= 1 {
        return start;
    }
    let step = (end - start) / (steps - 1) as f64;
    if index < steps / 2 {
        start + step * index as f64
    } else {
        end - step * (steps - 1 - index) as f64
    }
}

/// `torch.lerp(a, b, w)` as evaluated by PyTorch on CPU (two forms depending on `|w| < 0.5`).
pub(crate) fn torch_lerp(a: f64, b: f64, weight: f64) -> f64 {
    if libm::fabs(weight) < 0.5 {
        a + weight * (b - a)
    } else {
        b - (b - a) * (1.0 - weight)
    }
}

/// Phase-space timing of a config: `s = max((t - delay) / tau, 0)`, `x = exp(-alpha_phase s)`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Phase {
    pub tau: f64,
    pub delay: f64,
    pub alpha_phase: f64,
}

impl Phase {
    pub fn new(cfg: &ProDmpConfig) -> Self {
        Self {
            tau: cfg.tau,
            delay: cfg.delay,
            alpha_phase: cfg.alpha_phase,
        }
    }

    /// Left-bounded linear phase `s = max((t - delay) / tau, 0)` (dimensionless).
    pub fn scaled_time(&self, time: f64) -> f64 {
        let s = (time - self.delay) / self.tau;
        if s > 0.0 {
            s
        } else {
            0.0
        }
    }

    /// Canonical phase `x = exp(-alpha_phase * s)` at time `time` (seconds).
    pub fn phase(&self, time: f64) -> f64 {
        libm::exp(-self.alpha_phase * self.scaled_time(time))
    }

    /// Phase without the `s >= 0` clamp (used to place the RBF centres).
    fn unbound_phase(&self, time: f64) -> f64 {
        libm::exp(-self.alpha_phase * ((time - self.delay) / self.tau))
    }
}

/// Normalized Gaussian RBFs in phase space: `phi_i(x) = exp(-bw_i (x - c_i)^2 / 2)`, divided by
/// their sum when there is more than one basis.
#[derive(Clone, Debug)]
pub(crate) struct RbfBasis {
    num_basis: usize,
    /// Phase centres `c_i` (first `num_basis` entries used).
    centers: [f64; MAX_NUM_BASIS],
    /// Bandwidths `bw_i` (first `num_basis` entries used).
    bandwidths: [f64; MAX_NUM_BASIS],
}

impl RbfBasis {
    /// Centres and bandwidths of mp_pytorch's `NormalizedRBFBasisGenerator`, including its special
    /// cases (b = 2 doubles the last centre distance; b = 1 has one centre at `delay + tau / 2` and
    /// bandwidth `bandwidth_factor`). `cfg` must be validated.
    pub fn new(cfg: &ProDmpConfig) -> Result<Self, ProDmpError> {
        let phase = Phase::new(cfg);
        let num_basis = cfg.num_basis;
        let mut centers = [0.0; MAX_NUM_BASIS];
        let mut bandwidths = [0.0; MAX_NUM_BASIS];
        if num_basis == 1 {
            if let (Some(center), Some(bandwidth)) = (centers.first_mut(), bandwidths.first_mut()) {
                *center = phase.unbound_phase(cfg.delay + 0.5 * cfg.tau);
                *bandwidth = cfg.bandwidth_factor;
            }
        } else if num_basis > 1 && num_basis <= MAX_NUM_BASIS {
            let outside = cfg.num_basis_outside as f64;
            let spacing = cfg.tau / (num_basis as f64 - 2.0 * outside - 1.0);
            let first = -outside * spacing + cfg.delay;
            let last = outside * spacing + cfg.tau + cfg.delay;
            let center_time = |index: usize| torch_linspace(first, last, num_basis, index);
            let delta = center_time(1) - center_time(0);
            let extra_time = center_time(num_basis - 1) + delta;
            for (index, (center, bandwidth)) in centers
                .iter_mut()
                .zip(bandwidths.iter_mut())
                .take(num_basis)
                .enumerate()
            {
                let here = phase.unbound_phase(center_time(index));
                let next_time = if index + 1 < num_basis {
                    center_time(index + 1)
                } else {
                    extra_time
                };
                let mut distance = phase.unbound_phase(next_time) - here;
                if num_basis == 2 && index + 1 == num_basis {
                    distance *= 2.0;
                }
                *center = here;
                *bandwidth = cfg.bandwidth_factor / (distance * distance);
            }
        } else if num_basis == 0 {
            return Err(ProDmpError::ZeroBasis);
        } else {
            return Err(ProDmpError::TooManyBasis);
        }
        let all_finite = centers
            .iter()
            .chain(bandwidths.iter())
            .all(|v| v.is_finite());
        if !all_finite {
            return Err(ProDmpError::NonFiniteConfig);
        }
        Ok(Self {
            num_basis,
            centers,
            bandwidths,
        })
    }

    pub fn num_basis(&self) -> usize {
        self.num_basis
    }

    /// Phase centres `c_i` (length `num_basis`).
    pub fn centers(&self) -> &[f64] {
        self.centers.get(..self.num_basis).unwrap_or(&[])
    }

    /// Bandwidths `bw_i` (length `num_basis`).
    pub fn bandwidths(&self) -> &[f64] {
        self.bandwidths.get(..self.num_basis).unwrap_or(&[])
    }

    /// Writes the (normalized) basis values at phase `x` into `out[..num_basis]`.
    pub fn values(&self, x: f64, out: &mut [f64]) {
        let mut sum = 0.0;
        for ((value, center), bandwidth) in
            out.iter_mut().zip(self.centers()).zip(self.bandwidths())
        {
            let diff = x - center;
            *value = libm::exp(-(diff * diff * bandwidth) / 2.0);
            sum += *value;
        }
        if self.num_basis > 1 {
            for value in out.iter_mut().take(self.num_basis) {
                *value /= sum;
            }
        }
    }
}
