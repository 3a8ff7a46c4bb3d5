//! The pre-computation grid of mp_pytorch's `ProDMPBasisGenerator`, streamed instead of stored.
//!
//! The reference tabulates, on `s_k = linspace(0, L, L N + 1)` (`N = round(tau / dt)`, `L = 6`),
//! the cumulative trapezoid integrals `p1_i(s) = int_0^s u e^{alpha u / 2} x(u) phi_i(x(u)) du`
//! and `p2_i(s) = int_0^s e^{alpha u / 2} x(u) phi_i(x(u)) du`, and from them the position and
//! velocity basis tables `B = [y2 p2_i - y1 p1_i | y2 q2 - y1 q1]`, `B' = [dy2 p2_i - dy1 p1_i |
//! dy2 q2 - dy1 q1]` with `y1 = e^{-alpha s / 2}`, `y2 = s y1`, `q1 = (alpha s / 2 - 1)
//! e^{alpha s / 2} + 1`, `q2 = (alpha / 2)(e^{alpha s / 2} - 1)`. Queries interpolate linearly at
//! the fractional index `s / (dt / tau)` (note: not `s * N`; the two differ when `tau / dt` is not
//! an integer), with the lower index clipped to `[0, L N - 1]` (so the weight may exceed 1).
//!
//! Without an allocator the grid (up to `6 * MAX_GRID_STEPS_PER_TAU + 1` rows) is never stored:
//! [`GridStream`] walks it forward keeping only the running integrals, `O(num_basis)` memory.

use super::basis::{torch_lerp, torch_linspace, Phase, RbfBasis};
use super::config::{
    ProDmpConfig, MAX_GRID_STEPS_PER_TAU, MAX_NUM_BASIS, PRE_COMPUTE_LENGTH_FACTOR,
};
use super::ProDmpError;

/// Size and spacing of the pre-computation grid.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Grid {
    /// Number of grid points, `length_factor * steps_per_tau + 1` (at least 2).
    pub num_points: usize,
    /// Grid end in scaled time `s`.
    pub length_factor: usize,
    /// Lookup spacing `dt / tau` in scaled time.
    pub scaled_dt: f64,
}

/// Where a scaled time falls on the grid: rows `lower` and `lower + 1`, interpolation weight.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Lookup {
    pub lower: usize,
    pub weight: f64,
}

impl Grid {
    pub fn new(cfg: &ProDmpConfig, length_factor: usize) -> Result<Self, ProDmpError> {
        if length_factor == 0 || length_factor > PRE_COMPUTE_LENGTH_FACTOR {
            return Err(ProDmpError::InvalidLengthFactor);
        }
        let scaled_dt = cfg.dt / cfg.tau;
        // torch.round rounds half to even, as does rint in the default rounding mode.
        let steps = libm::rint(1.0 / scaled_dt);
        if steps.is_nan() || steps < 1.0 {
            return Err(ProDmpError::GridTooCoarse);
        }
        if steps > MAX_GRID_STEPS_PER_TAU as f64 {
            return Err(ProDmpError::GridTooFine);
        }
        let num_points = length_factor * (steps as usize) + 1;
        Ok(Self {
            num_points,
            length_factor,
            scaled_dt,
        })
    }

    /// Scaled time of grid point `index`.
    pub fn point(&self, index: usize) -> f64 {
        torch_linspace(0.0, self.length_factor as f64, self.num_points, index)
    }

    /// Grid position of scaled time `s >= 0`; errors beyond the pre-computed range like the
    /// reference (`s > length_factor`).
    pub fn locate(&self, s: f64) -> Result<Lookup, ProDmpError> {
        if !s.is_finite() {
            return Err(ProDmpError::NonFiniteInput);
        }
        if s > self.length_factor as f64 {
            return Err(ProDmpError::TimeBeyondPrecompute);
        }
        let index = s / self.scaled_dt;
        let floor = libm::floor(index);
        let max_lower = self.num_points.saturating_sub(2);
        let lower = if floor <= 0.0 {
            0
        } else if floor >= max_lower as f64 {
            max_lower
        } else {
            floor as usize
        };
        Ok(Lookup {
            lower,
            weight: index - lower as f64,
        })
    }
}

/// Values of the homogeneous solutions `y1 = e^{-alpha s/2}`, `y2 = s y1` and their
/// s-derivatives.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct GeneralSolution {
    pub y1: f64,
    pub y2: f64,
    pub dy1: f64,
    pub dy2: f64,
}

impl GeneralSolution {
    fn at(alpha: f64, s: f64) -> Self {
        let y1 = libm::exp(-0.5 * alpha * s);
        let y2 = s * y1;
        Self {
            y1,
            y2,
            dy1: -0.5 * alpha * y1,
            dy2: -0.5 * alpha * y2 + y1,
        }
    }

    fn lerp(self, next: Self, weight: f64) -> Self {
        Self {
            y1: torch_lerp(self.y1, next.y1, weight),
            y2: torch_lerp(self.y2, next.y2, weight),
            dy1: torch_lerp(self.dy1, next.dy1, weight),
            dy2: torch_lerp(self.dy2, next.dy2, weight),
        }
    }
}

/// Forward walk over the grid holding the cumulative trapezoid integrals at the current point.
pub(crate) struct GridStream<'a> {
    grid: &'a Grid,
    basis: &'a RbfBasis,
    phase: Phase,
    alpha: f64,
    index: usize,
    s: f64,
    /// Running integrals `p1_i`, `p2_i` at `s`.
    p1: [f64; MAX_NUM_BASIS],
    p2: [f64; MAX_NUM_BASIS],
    /// Integrands at `s` (needed for the next trapezoid).
    dp1: [f64; MAX_NUM_BASIS],
    dp2: [f64; MAX_NUM_BASIS],
}

impl<'a> GridStream<'a> {
    pub fn new(grid: &'a Grid, basis: &'a RbfBasis, phase: Phase, alpha: f64) -> Self {
        let mut stream = Self {
            grid,
            basis,
            phase,
            alpha,
            index: 0,
            s: grid.point(0),
            p1: [0.0; MAX_NUM_BASIS],
            p2: [0.0; MAX_NUM_BASIS],
            dp1: [0.0; MAX_NUM_BASIS],
            dp2: [0.0; MAX_NUM_BASIS],
        };
        let s = stream.s;
        let mut dp1 = [0.0; MAX_NUM_BASIS];
        let mut dp2 = [0.0; MAX_NUM_BASIS];
        stream.integrands(s, &mut dp1, &mut dp2);
        stream.dp1 = dp1;
        stream.dp2 = dp2;
        stream
    }

    /// Integrands `s e^{alpha s/2} x phi_i` and `e^{alpha s/2} x phi_i` at scaled time `s`.
    fn integrands(&self, s: f64, dp1: &mut [f64], dp2: &mut [f64]) {
        // The reference maps the grid to times and back through the phase generator.
        let time = s * self.phase.tau + self.phase.delay;
        let x = self.phase.phase(time);
        let growth = libm::exp(self.alpha * s / 2.0);
        self.basis.values(x, dp2);
        for (first, second) in dp1
            .iter_mut()
            .zip(dp2.iter_mut())
            .take(self.basis.num_basis())
        {
            let phi = *second;
            *first = s * growth * x * phi;
            *second = growth * x * phi;
        }
    }

    /// Moves one grid point forward; returns false at the last point.
    fn advance(&mut self) -> bool {
        let next_index = self.index + 1;
        if next_index >= self.grid.num_points {
            return false;
        }
        let next_s = self.grid.point(next_index);
        let mut next1 = [0.0; MAX_NUM_BASIS];
        let mut next2 = [0.0; MAX_NUM_BASIS];
        self.integrands(next_s, &mut next1, &mut next2);
        let ds = next_s - self.s;
        let columns = self
            .p1
            .iter_mut()
            .zip(self.p2.iter_mut())
            .zip(self.dp1.iter_mut().zip(self.dp2.iter_mut()))
            .zip(next1.iter().zip(next2.iter()))
            .take(self.basis.num_basis());
        for (((p1, p2), (dp1, dp2)), (new1, new2)) in columns {
            *p1 += ds * (*dp1 + new1) / 2.0;
            *p2 += ds * (*dp2 + new2) / 2.0;
            *dp1 = *new1;
            *dp2 = *new2;
        }
        self.index = next_index;
        self.s = next_s;
        true
    }

    /// Positions the stream at grid point `index` (restarting from 0 if it lies behind).
    pub fn seek(&mut self, index: usize) -> Result<(), ProDmpError> {
        if index >= self.grid.num_points {
            return Err(ProDmpError::TimeBeyondPrecompute);
        }
        if index < self.index {
            *self = Self::new(self.grid, self.basis, self.phase, self.alpha);
        }
        while self.index < index {
            if !self.advance() {
                return Err(ProDmpError::TimeBeyondPrecompute);
            }
        }
        Ok(())
    }

    pub fn solution(&self) -> GeneralSolution {
        GeneralSolution::at(self.alpha, self.s)
    }

    /// `(B_k, B'_k)` of the current grid point for the `num_basis` weights, then the goal.
    pub fn row(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        let solution = self.solution();
        let half_alpha = 0.5 * self.alpha;
        let growth = libm::exp(half_alpha * self.s);
        let q1 = (half_alpha * self.s - 1.0) * growth + 1.0;
        let q2 = half_alpha * (growth - 1.0);
        let weights = self
            .p1
            .iter()
            .zip(self.p2.iter())
            .take(self.basis.num_basis());
        weights
            .map(move |(p1, p2)| {
                (
                    p2 * solution.y2 - p1 * solution.y1,
                    p2 * solution.dy2 - p1 * solution.dy1,
                )
            })
            .chain(core::iter::once((
                q2 * solution.y2 - q1 * solution.y1,
                q2 * solution.dy2 - q1 * solution.dy1,
            )))
    }

    /// Interpolated `B`, `B'` rows (written to `pos`, `vel`, length `num_basis + 1`) and general
    /// solution values at `lookup`.
    pub fn sample(
        &mut self,
        lookup: Lookup,
        pos: &mut [f64],
        vel: &mut [f64],
    ) -> Result<GeneralSolution, ProDmpError> {
        self.seek(lookup.lower)?;
        let lower = self.solution();
        for ((pos_out, vel_out), (pos_value, vel_value)) in
            pos.iter_mut().zip(vel.iter_mut()).zip(self.row())
        {
            *pos_out = pos_value;
            *vel_out = vel_value;
        }
        self.seek(lookup.lower + 1)?;
        let upper = self.solution();
        for ((pos_out, vel_out), (pos_value, vel_value)) in
            pos.iter_mut().zip(vel.iter_mut()).zip(self.row())
        {
            *pos_out = torch_lerp(*pos_out, pos_value, lookup.weight);
            *vel_out = torch_lerp(*vel_out, vel_value, lookup.weight);
        }
        Ok(lower.lerp(upper, lookup.weight))
    }

    /// Column-wise maximum of the position table `B` over the whole grid (mp_pytorch's
    /// `pc_pos_basis.max(axis=0)`), written to `out[..num_basis + 1]`.
    pub fn column_max(mut self, out: &mut [f64]) {
        for value in out.iter_mut() {
            *value = f64::NEG_INFINITY;
        }
        loop {
            for (max, (pos_value, _)) in out.iter_mut().zip(self.row()) {
                if pos_value > *max || pos_value.is_nan() {
                    *max = pos_value;
                }
            }
            if !self.advance() {
                break;
            }
        }
    }
}
