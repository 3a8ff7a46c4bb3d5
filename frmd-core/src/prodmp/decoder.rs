//! The f64 ProDMP decoder: boundary conditions at `init_time` and the linear rows that map
//! `(theta, y0, v0)` to position and velocity at one query time.

use super::basis::{Phase, RbfBasis};
use super::config::{ProDmpConfig, MAX_NUM_BASIS, PRE_COMPUTE_LENGTH_FACTOR};
use super::table::{GeneralSolution, Grid, GridStream};
use super::ProDmpError;

/// Coefficients of `y0` (units) and `v0` (units/s) in the position (units) and velocity
/// (units/s) of one DoF at one query time. Relative-goal terms are folded into `pos_y0`/`vel_y0`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BoundaryCoefficients {
    /// Position per unit of `y0`.
    pub pos_y0: f64,
    /// Position per unit of `v0` (seconds).
    pub pos_v0: f64,
    /// Velocity per unit of `y0` (1/s).
    pub vel_y0: f64,
    /// Velocity per unit of `v0`.
    pub vel_v0: f64,
}

/// Boundary-condition functions in scaled time (mp_pytorch's `xi_1`, `xi_2` and their
/// s-derivatives), before the relative goal and the `1 / tau` of velocities:
/// `pos = xi1 y0 + xi2 tau v0 + H theta`, `d pos / ds = dxi1 y0 + dxi2 tau v0 + H' theta`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BoundaryTerms {
    /// `xi_1`: the homogeneous solution that starts at 1 with zero slope.
    pub xi1: f64,
    /// `xi_2`: the homogeneous solution that starts at 0 with unit slope.
    pub xi2: f64,
    /// `d xi_1 / ds`.
    pub dxi1: f64,
    /// `d xi_2 / ds`.
    pub dxi2: f64,
}

/// A validated ProDMP with its basis and (when `auto_scale_basis`) its per-column scales.
/// About 1.7 KiB; building it streams the whole grid once only when `auto_scale_basis` is set.
/// A row query streams the grid from 0 to the needed index (`O(index * num_basis)` time) and
/// uses about 4.5 KiB of stack (fixed `MAX_NUM_BASIS` buffers).
#[derive(Clone, Debug)]
pub struct ProDmp {
    cfg: ProDmpConfig,
    phase: Phase,
    basis: RbfBasis,
    grid: Grid,
    /// Per-column scale `c` of `[w_0 .. w_{b-1}, g]` (mp_pytorch `weights_goal_scale`).
    scale: [f64; MAX_NUM_BASIS + 1],
}

fn check_len(slice: &[f64], len: usize) -> Result<(), ProDmpError> {
    if slice.len() == len {
        Ok(())
    } else {
        Err(ProDmpError::WrongLength)
    }
}

impl ProDmp {
    /// Builds the decoder with mp_pytorch's default pre-computation length (6 tau).
    pub fn new(cfg: &ProDmpConfig) -> Result<Self, ProDmpError> {
        Self::with_length_factor(cfg, PRE_COMPUTE_LENGTH_FACTOR)
    }

    /// Builds the decoder with pre-computation length `length_factor * tau` (1..=6, as
    /// mp_pytorch's `pre_compute_length_factor`).
    pub fn with_length_factor(
        cfg: &ProDmpConfig,
        length_factor: usize,
    ) -> Result<Self, ProDmpError> {
        cfg.validate()?;
        let phase = Phase::new(cfg);
        let basis = RbfBasis::new(cfg)?;
        let grid = Grid::new(cfg, length_factor)?;
        let mut scale = [0.0; MAX_NUM_BASIS + 1];
        let num_basis = cfg.num_basis;
        if cfg.auto_scale_basis {
            GridStream::new(&grid, &basis, phase, cfg.alpha).column_max(&mut scale);
            for value in scale.iter_mut().take(num_basis + 1) {
                *value = 1.0 / *value;
            }
        } else {
            for value in scale.iter_mut().take(num_basis + 1) {
                *value = 1.0;
            }
        }
        for (index, value) in scale.iter_mut().take(num_basis + 1).enumerate() {
            *value *= if index < num_basis {
                cfg.weights_scale
            } else {
                cfg.goal_scale
            };
        }
        if !scale
            .iter()
            .take(num_basis + 1)
            .all(|value| value.is_finite())
        {
            return Err(ProDmpError::NonFiniteResult);
        }
        Ok(Self {
            cfg: *cfg,
            phase,
            basis,
            grid,
            scale,
        })
    }

    /// The configuration it was built from.
    pub fn config(&self) -> &ProDmpConfig {
        &self.cfg
    }

    /// Parameters per DoF, `num_basis + 1`.
    pub fn num_params_per_dof(&self) -> usize {
        self.cfg.num_params_per_dof()
    }

    /// Number of points of the (streamed) pre-computation grid.
    pub fn num_grid_points(&self) -> usize {
        self.grid.num_points
    }

    /// RBF centres in phase space (length `num_basis`).
    pub fn centers_phase(&self) -> &[f64] {
        self.basis.centers()
    }

    /// RBF bandwidths (length `num_basis`).
    pub fn bandwidths(&self) -> &[f64] {
        self.basis.bandwidths()
    }

    /// Column scales `c` folded into the coefficients (length `num_basis + 1`).
    pub fn weights_goal_scale(&self) -> &[f64] {
        self.scale.get(..self.cfg.num_basis + 1).unwrap_or(&[])
    }

    /// Column-wise maximum of the unscaled position table over the whole grid (what
    /// `auto_scale_basis` divides by), written to `out` (length `num_basis + 1`).
    pub fn position_table_max(&self, out: &mut [f64]) -> Result<(), ProDmpError> {
        check_len(out, self.num_params_per_dof())?;
        GridStream::new(&self.grid, &self.basis, self.phase, self.cfg.alpha).column_max(out);
        Ok(())
    }

    /// Unscaled basis rows `H(t)` (`pos_h`) and `H'(t)` (`vel_h`, derivative in scaled time), both
    /// of length `num_basis + 1` with the goal last, plus the boundary terms for initial time
    /// `init_time` and query time `time` (seconds).
    pub fn unscaled_rows(
        &self,
        init_time: f64,
        time: f64,
        pos_h: &mut [f64],
        vel_h: &mut [f64],
    ) -> Result<BoundaryTerms, ProDmpError> {
        let width = self.num_params_per_dof();
        check_len(pos_h, width)?;
        check_len(vel_h, width)?;
        if !init_time.is_finite() || !time.is_finite() {
            return Err(ProDmpError::NonFiniteInput);
        }
        let init_lookup = self.grid.locate(self.phase.scaled_time(init_time))?;
        let lookup = self.grid.locate(self.phase.scaled_time(time))?;
        let mut init_pos = [0.0; MAX_NUM_BASIS + 1];
        let mut init_vel = [0.0; MAX_NUM_BASIS + 1];
        let mut stream = GridStream::new(&self.grid, &self.basis, self.phase, self.cfg.alpha);
        // Visit the lower grid index first so one forward pass serves both lookups.
        let (init, here): (GeneralSolution, GeneralSolution) = if init_lookup.lower <= lookup.lower
        {
            let init = stream.sample(init_lookup, &mut init_pos, &mut init_vel)?;
            (init, stream.sample(lookup, pos_h, vel_h)?)
        } else {
            let here = stream.sample(lookup, pos_h, vel_h)?;
            (
                stream.sample(init_lookup, &mut init_pos, &mut init_vel)?,
                here,
            )
        };
        let det = init.y1 * init.dy2 - init.y2 * init.dy1;
        if det == 0.0 || !det.is_finite() {
            return Err(ProDmpError::SingularBoundary);
        }
        // Same association as mp_pytorch (divide by det first) to stay within rounding of it.
        let terms = BoundaryTerms {
            xi1: init.dy2 / det * here.y1 - init.dy1 / det * here.y2,
            xi2: init.y1 / det * here.y2 - init.y2 / det * here.y1,
            dxi1: init.dy2 / det * here.dy1 - init.dy1 / det * here.dy2,
            dxi2: init.y1 / det * here.dy2 - init.y2 / det * here.dy1,
        };
        // H = xi3 B(t0) + xi4 B'(t0) + B(t) with xi3 = -xi1, xi4 = -xi2.
        let init_rows = init_pos.iter().zip(init_vel.iter());
        for ((pos, vel), (b0, db0)) in pos_h.iter_mut().zip(vel_h.iter_mut()).zip(init_rows) {
            *pos += -terms.xi1 * b0 + -terms.xi2 * db0;
            *vel += -terms.dxi1 * b0 + -terms.dxi2 * db0;
        }
        let finite = pos_h.iter().chain(vel_h.iter()).all(|v| v.is_finite())
            && [terms.xi1, terms.xi2, terms.dxi1, terms.dxi2]
                .iter()
                .all(|v| v.is_finite());
        if finite {
            Ok(terms)
        } else {
            Err(ProDmpError::NonFiniteResult)
        }
    }

    /// Linear row of the decoder at query time `time` for initial time `init_time` (seconds):
    /// `pos = pos_params . theta + pos_y0 y0 + pos_v0 v0` (units), `vel = vel_params . theta +
    /// vel_y0 y0 + vel_v0 v0` (units/s), with `theta = [w_0 .. w_{b-1}, g]` of one DoF. Both
    /// slices must have length `num_basis + 1`. Scales and relative goal are folded in.
    pub fn linear_row(
        &self,
        init_time: f64,
        time: f64,
        pos_params: &mut [f64],
        vel_params: &mut [f64],
    ) -> Result<BoundaryCoefficients, ProDmpError> {
        let terms = self.unscaled_rows(init_time, time, pos_params, vel_params)?;
        let tau = self.cfg.tau;
        let (goal_pos, goal_vel) = match (pos_params.last(), vel_params.last()) {
            (Some(pos), Some(vel)) if self.cfg.relative_goal => (*pos, *vel),
            _ => (0.0, 0.0),
        };
        for ((pos, vel), scale) in pos_params
            .iter_mut()
            .zip(vel_params.iter_mut())
            .zip(self.weights_goal_scale())
        {
            *pos *= scale;
            *vel = *vel * scale / tau;
        }
        Ok(BoundaryCoefficients {
            pos_y0: terms.xi1 + goal_pos,
            pos_v0: terms.xi2 * tau,
            vel_y0: (terms.dxi1 + goal_vel) / tau,
            vel_v0: terms.dxi2,
        })
    }

    /// Decodes all DoFs at one query time: `params` is DoF-major (`num_dof * (num_basis + 1)`),
    /// `y0`, `v0`, `pos`, `vel` have length `num_dof` (units, units/s).
    #[allow(clippy::too_many_arguments)]
    pub fn decode_at(
        &self,
        init_time: f64,
        time: f64,
        params: &[f64],
        y0: &[f64],
        v0: &[f64],
        pos: &mut [f64],
        vel: &mut [f64],
    ) -> Result<(), ProDmpError> {
        let num_dof = self.cfg.num_dof;
        let width = self.num_params_per_dof();
        check_len(params, num_dof * width)?;
        for slice in [y0, v0, &*pos, &*vel] {
            check_len(slice, num_dof)?;
        }
        if !params.iter().chain(y0).chain(v0).all(|v| v.is_finite()) {
            return Err(ProDmpError::NonFiniteInput);
        }
        let mut pos_row = [0.0; MAX_NUM_BASIS + 1];
        let mut vel_row = [0.0; MAX_NUM_BASIS + 1];
        let pos_row = pos_row.get_mut(..width).ok_or(ProDmpError::TooManyBasis)?;
        let vel_row = vel_row.get_mut(..width).ok_or(ProDmpError::TooManyBasis)?;
        let coeffs = self.linear_row(init_time, time, pos_row, vel_row)?;
        let dofs = params.chunks_exact(width).zip(y0.iter().zip(v0.iter()));
        for ((theta, (y0, v0)), (pos, vel)) in dofs.zip(pos.iter_mut().zip(vel.iter_mut())) {
            *pos = apply_row(pos_row, coeffs.pos_y0, coeffs.pos_v0, theta, *y0, *v0);
            *vel = apply_row(vel_row, coeffs.vel_y0, coeffs.vel_v0, theta, *y0, *v0);
        }
        if pos.iter().chain(vel.iter()).all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(ProDmpError::NonFiniteResult)
        }
    }
}

/// One output of the linear map in f64: `coeffs . theta + y0_coeff y0 + v0_coeff v0` (boundary
/// terms first, then parameters in order).
pub fn apply_row(
    coeffs: &[f64],
    y0_coeff: f64,
    v0_coeff: f64,
    theta: &[f64],
    y0: f64,
    v0: f64,
) -> f64 {
    let mut acc = y0_coeff * y0 + v0_coeff * v0;
    for (coeff, value) in coeffs.iter().zip(theta) {
        acc += coeff * value;
    }
    acc
}

/// Convenience form of [`ProDmp::linear_row`] that builds the decoder from `cfg` each call.
pub fn linear_row(
    cfg: &ProDmpConfig,
    init_time: f64,
    time: f64,
    pos_params: &mut [f64],
    vel_params: &mut [f64],
) -> Result<BoundaryCoefficients, ProDmpError> {
    ProDmp::new(cfg)?.linear_row(init_time, time, pos_params, vel_params)
}
