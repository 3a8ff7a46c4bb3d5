//! ProDMP configuration (the subset of mp_pytorch 0.1.4's ProDMP settings that FRMD uses) and
//! its validation.

use super::ProDmpError;

/// Largest number of basis functions the decoder supports. The table construction keeps a few
/// `[f64; MAX_NUM_BASIS]` buffers on the stack (no allocator), so this bounds stack use.
pub const MAX_NUM_BASIS: usize = 64;

/// mp_pytorch's default (and maximum) pre-computation length: the grid covers
/// `s in [0, PRE_COMPUTE_LENGTH_FACTOR]` in scaled time `s = (t - delay) / tau`.
pub const PRE_COMPUTE_LENGTH_FACTOR: usize = 6;

/// Largest accepted `round(tau / dt)`. The grid has `6 * round(tau / dt) + 1` points and is
/// streamed point by point, so this bounds the cost of one table query.
pub const MAX_GRID_STEPS_PER_TAU: usize = 1_000_000;

/// Configuration of a ProDMP (integral-form DMP with an exponential-decay phase and normalized
/// Gaussian RBFs in phase space), matching `mp_pytorch.mp.ProDMP` 0.1.4 with float64 tensors.
///
/// Units: `tau`, `delay` and `dt` are in seconds. `alpha` (spring constant of the critically
/// damped system, `beta = alpha / 4`), `alpha_phase` and `bandwidth_factor` are dimensionless.
/// Serialized as is in a checkpoint's `frmd.json` (`prodmp`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ProDmpConfig {
    /// Number of degrees of freedom (independent output channels). At least 1.
    pub num_dof: usize,
    /// Number of RBF weights per DoF (`b`), `1..=MAX_NUM_BASIS`. Each DoF also has one goal.
    pub num_basis: usize,
    /// Duration scale in seconds (`s = (t - delay) / tau`), finite and > 0.
    pub tau: f64,
    /// Start delay in seconds, finite.
    pub delay: f64,
    /// DMP spring constant, finite and > 0.
    pub alpha: f64,
    /// Phase decay `x = exp(-alpha_phase * s)`, finite and > 0.
    pub alpha_phase: f64,
    /// RBF width factor (`bw_i = bandwidth_factor / (c_{i+1} - c_i)^2`), finite and > 0.
    pub bandwidth_factor: f64,
    /// Number of RBF centres placed outside `[delay, delay + tau]` on each side.
    pub num_basis_outside: usize,
    /// Pre-computation time step in seconds (grid spacing `dt / tau` in `s`), finite and > 0.
    pub dt: f64,
    /// Scale applied to every weight (mp_pytorch `weights_scale` as a scalar), finite.
    pub weights_scale: f64,
    /// Scale applied to the goal, finite.
    pub goal_scale: f64,
    /// If true the goal parameter is relative to the initial position `y0`.
    pub relative_goal: bool,
    /// If true every basis column is also scaled by `1 / max over the grid` of that column.
    pub auto_scale_basis: bool,
}

impl ProDmpConfig {
    /// Policy convention of docs/design.md s.2: `tau = horizon * control_dt` (query times
    /// `control_dt, 2 control_dt, .., horizon * control_dt`), relative goal, `alpha = 25`,
    /// `alpha_phase = 2`, `bandwidth_factor = 3`, pre-computation `dt = 0.01` s, unit scales,
    /// no auto scaling, no delay, no outside basis.
    pub fn policy(num_dof: usize, num_basis: usize, horizon: usize, control_dt: f64) -> Self {
        Self {
            num_dof,
            num_basis,
            tau: horizon as f64 * control_dt,
            delay: 0.0,
            alpha: 25.0,
            alpha_phase: 2.0,
            bandwidth_factor: 3.0,
            num_basis_outside: 0,
            dt: 0.01,
            weights_scale: 1.0,
            goal_scale: 1.0,
            relative_goal: true,
            auto_scale_basis: false,
        }
    }

    /// Number of parameters per DoF: `num_basis` weights followed by one goal.
    pub fn num_params_per_dof(&self) -> usize {
        self.num_basis + 1
    }

    /// Checks every field; the decoder calls this before building anything.
    pub fn validate(&self) -> Result<(), ProDmpError> {
        if self.num_dof == 0 {
            return Err(ProDmpError::ZeroDof);
        }
        if self.num_basis == 0 {
            return Err(ProDmpError::ZeroBasis);
        }
        if self.num_basis > MAX_NUM_BASIS {
            return Err(ProDmpError::TooManyBasis);
        }
        let all_finite = [
            self.tau,
            self.delay,
            self.alpha,
            self.alpha_phase,
            self.bandwidth_factor,
            self.dt,
            self.weights_scale,
            self.goal_scale,
        ]
        .iter()
        .all(|value| value.is_finite());
        if !all_finite {
            return Err(ProDmpError::NonFiniteConfig);
        }
        if self.tau <= 0.0 {
            return Err(ProDmpError::NonPositiveTau);
        }
        if self.dt <= 0.0 {
            return Err(ProDmpError::NonPositiveDt);
        }
        if self.alpha <= 0.0 {
            return Err(ProDmpError::NonPositiveAlpha);
        }
        if self.alpha_phase <= 0.0 {
            return Err(ProDmpError::NonPositiveAlphaPhase);
        }
        if self.bandwidth_factor <= 0.0 {
            return Err(ProDmpError::NonPositiveBandwidth);
        }
        // For b > 1 the centre spacing is tau / (b - 2 o - 1); it must be positive and finite.
        if self.num_basis > 1
            && self.num_basis_outside.saturating_mul(2).saturating_add(1) >= self.num_basis
        {
            return Err(ProDmpError::TooManyOutsideBasis);
        }
        Ok(())
    }
}
