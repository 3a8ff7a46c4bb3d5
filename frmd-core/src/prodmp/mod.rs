//! ProDMP decoder compatible with mp_pytorch 0.1.4 (docs/design.md s.2), no_std and no alloc.
//!
//! - [`config`]: [`ProDmpConfig`] and its validation.
//! - `basis`: exponential-decay phase and normalized RBFs (centres, bandwidths, special cases).
//! - `table`: the pre-computation grid, streamed (cumulative trapezoid integrals, interpolation).
//! - [`decoder`]: boundary conditions and [`linear_row`] in f64 ([`ProDmp`]).
//! - [`baked`]: [`BakedProDmp`], the f32 policy decoder with compile-time sizes.
//!
//! The decoder is linear in `(theta, y0, v0)`: for one DoF with initial time `init_time` and
//! query time `time`, `pos = pos_params . theta + pos_y0 y0 + pos_v0 v0` and
//! `vel = vel_params . theta + vel_y0 y0 + vel_v0 v0` (vel and v0 in units/s). Tables are built in
//! f64 (`e^{alpha s / 2}` overflows f32) and reproduce the reference's grid, trapezoid rule and
//! interpolation, so results match mp_pytorch (float64) to rounding.

pub mod baked;
mod basis;
pub mod config;
pub mod decoder;
mod table;

pub use baked::{apply_row_f32, BakedProDmp, BoundaryRow};
pub use config::{ProDmpConfig, MAX_GRID_STEPS_PER_TAU, MAX_NUM_BASIS, PRE_COMPUTE_LENGTH_FACTOR};
pub use decoder::{apply_row, linear_row, BoundaryCoefficients, BoundaryTerms, ProDmp};

/// Why a ProDMP could not be built or evaluated. Each variant names one problem.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ProDmpError {
    /// `num_dof` is 0.
    ZeroDof,
    /// `num_basis` is 0.
    ZeroBasis,
    /// `num_basis` exceeds [`MAX_NUM_BASIS`].
    TooManyBasis,
    /// `2 * num_basis_outside + 1 >= num_basis` (centre spacing not positive) with `num_basis > 1`.
    TooManyOutsideBasis,
    /// A config float (tau, delay, alpha, alpha_phase, bandwidth, dt, scales) is NaN or infinite,
    /// or the RBF centres/bandwidths derived from it are.
    NonFiniteConfig,
    /// `tau <= 0`.
    NonPositiveTau,
    /// `dt <= 0`.
    NonPositiveDt,
    /// `alpha <= 0`.
    NonPositiveAlpha,
    /// `alpha_phase <= 0`.
    NonPositiveAlphaPhase,
    /// `bandwidth_factor <= 0`.
    NonPositiveBandwidth,
    /// `round(tau / dt)` is 0: the grid has no step.
    GridTooCoarse,
    /// `round(tau / dt)` exceeds [`MAX_GRID_STEPS_PER_TAU`].
    GridTooFine,
    /// Pre-computation length factor not in `1..=6`.
    InvalidLengthFactor,
    /// A query or initial time maps beyond the pre-computed range (`(t - delay) / tau > 6`).
    TimeBeyondPrecompute,
    /// A time, parameter, `y0` or `v0` is NaN or infinite.
    NonFiniteInput,
    /// A slice has the wrong length (rows need `num_basis + 1`, per-DoF slices `num_dof`, params
    /// `num_dof * (num_basis + 1)`).
    WrongLength,
    /// The baked `P` is not `num_basis + 1`.
    ParamCountMismatch,
    /// The baked horizon `N` is 0.
    ZeroHorizon,
    /// The boundary-condition determinant at the initial time is 0 or not finite (underflow of
    /// `e^{-alpha s}` for a very late initial time).
    SingularBoundary,
    /// NaN or infinite result: `e^{alpha s / 2}` overflowed, every RBF underflowed to 0 somewhere
    /// on the grid (0/0 normalization, as in the reference; auto scaling scans the whole grid),
    /// or an f32 table entry or output is not finite.
    NonFiniteResult,
}

impl core::fmt::Display for ProDmpError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let text = match self {
            Self::ZeroDof => "num_dof must be at least 1",
            Self::ZeroBasis => "num_basis must be at least 1",
            Self::TooManyBasis => "num_basis exceeds MAX_NUM_BASIS (64)",
            Self::TooManyOutsideBasis => "2 * num_basis_outside + 1 must be < num_basis",
            Self::NonFiniteConfig => "config contains a NaN or infinite value",
            Self::NonPositiveTau => "tau must be > 0",
            Self::NonPositiveDt => "dt must be > 0",
            Self::NonPositiveAlpha => "alpha must be > 0",
            Self::NonPositiveAlphaPhase => "alpha_phase must be > 0",
            Self::NonPositiveBandwidth => "bandwidth_factor must be > 0",
            Self::GridTooCoarse => "round(tau / dt) is 0: dt too large for tau",
            Self::GridTooFine => "round(tau / dt) exceeds MAX_GRID_STEPS_PER_TAU",
            Self::InvalidLengthFactor => "pre-compute length factor must be in 1..=6",
            Self::TimeBeyondPrecompute => "time beyond the pre-computed range (t - delay > 6 tau)",
            Self::NonFiniteInput => "time, params, y0 or v0 is NaN or infinite",
            Self::WrongLength => "slice has the wrong length",
            Self::ParamCountMismatch => "baked P differs from num_basis + 1",
            Self::ZeroHorizon => "baked horizon N must be at least 1",
            Self::SingularBoundary => "boundary-condition determinant is zero or not finite",
            Self::NonFiniteResult => {
                "result is NaN or infinite (exp overflow, all RBFs underflowing on the grid, or \
                 f32 overflow)"
            }
        };
        f.write_str(text)
    }
}

/// No variant wraps another error.
impl core::error::Error for ProDmpError {}
