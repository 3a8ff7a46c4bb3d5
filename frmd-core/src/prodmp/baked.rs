//! Baked policy decoder: the ProDMP as a fixed linear map in f32 for compile-time sizes.
//!
//! With query times `dt, 2 dt, .., N dt` (`dt = tau / N`) and initial time 0 the decoder is
//! `pos[t][d] = pos_params[t] . theta[d] + pos_y0[t] y0[d] + pos_v0[t] v0[d]` (and the same for
//! velocities), so the tables below are all the firmware needs. They are computed in f64 by
//! [`ProDmp::linear_row`] and rounded to f32 once.

use super::config::{ProDmpConfig, MAX_NUM_BASIS};
use super::decoder::ProDmp;
use super::ProDmpError;

/// f32 tables of the policy decoder for `N` query times and `P = num_basis + 1` parameters per
/// DoF. Fields are public so generated code can build it as a `const`.
#[derive(Clone, Debug, PartialEq)]
pub struct BakedProDmp<const N: usize, const P: usize> {
    /// Position coefficients of `[w_0 .. w_{P-2}, g]` per query time (scales folded in).
    pub pos_params: [[f32; P]; N],
    /// Velocity coefficients (1/s) of `[w_0 .. w_{P-2}, g]` per query time.
    pub vel_params: [[f32; P]; N],
    /// Position coefficient of `y0` (relative goal folded in) per query time.
    pub pos_y0: [f32; N],
    /// Position coefficient of `v0` (seconds) per query time.
    pub pos_v0: [f32; N],
    /// Velocity coefficient of `y0` (1/s) per query time.
    pub vel_y0: [f32; N],
    /// Velocity coefficient of `v0` per query time.
    pub vel_v0: [f32; N],
}

/// One output of the linear map in f32: `coeffs . theta + y0_coeff y0 + v0_coeff v0`, summed in a
/// fixed order (boundary terms, then parameters in order). Shared by [`BakedProDmp::decode`] and
/// host-side f32 checks so both round identically.
pub fn apply_row_f32(
    coeffs: &[f32],
    y0_coeff: f32,
    v0_coeff: f32,
    theta: &[f32],
    y0: f32,
    v0: f32,
) -> f32 {
    let mut acc = y0_coeff * y0 + v0_coeff * v0;
    for (coeff, value) in coeffs.iter().zip(theta) {
        acc += coeff * value;
    }
    acc
}

/// The initial-condition coefficients of one query time (see [`BakedProDmp::boundary_rows`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundaryRow {
    /// Position coefficient of `y0`.
    pub pos_y0: f32,
    /// Position coefficient of `v0` (s).
    pub pos_v0: f32,
    /// Velocity coefficient of `y0` (1/s).
    pub vel_y0: f32,
    /// Velocity coefficient of `v0`.
    pub vel_v0: f32,
}

impl BoundaryRow {
    /// The decoder's output for all-zero parameters at this time: `(position, velocity)` of the
    /// part fixed by `y0`, `v0`, rounded exactly as [`BakedProDmp::decode`] rounds it.
    #[inline]
    pub fn at(&self, y0: f32, v0: f32) -> (f32, f32) {
        (
            apply_row_f32(&[], self.pos_y0, self.pos_v0, &[], y0, v0),
            apply_row_f32(&[], self.vel_y0, self.vel_v0, &[], y0, v0),
        )
    }
}

fn narrow(value: f64) -> Result<f32, ProDmpError> {
    let narrowed = value as f32;
    if narrowed.is_finite() {
        Ok(narrowed)
    } else {
        Err(ProDmpError::NonFiniteResult)
    }
}

impl<const N: usize, const P: usize> BakedProDmp<N, P> {
    /// Query times of the policy convention: `k * tau / N` for `k = 1..=N` (seconds).
    pub fn query_time(cfg: &ProDmpConfig, step: usize) -> f64 {
        step as f64 * (cfg.tau / N as f64)
    }

    /// Bakes the tables for `cfg` (times `tau/N .. tau`, initial time 0). Requires `N >= 1` and
    /// `P == cfg.num_basis + 1`.
    pub fn from_config(cfg: &ProDmpConfig) -> Result<Self, ProDmpError> {
        if N == 0 {
            return Err(ProDmpError::ZeroHorizon);
        }
        if P != cfg.num_params_per_dof() || P > MAX_NUM_BASIS + 1 {
            return Err(ProDmpError::ParamCountMismatch);
        }
        let decoder = ProDmp::new(cfg)?;
        let mut baked = Self {
            pos_params: [[0.0; P]; N],
            vel_params: [[0.0; P]; N],
            pos_y0: [0.0; N],
            pos_v0: [0.0; N],
            vel_y0: [0.0; N],
            vel_v0: [0.0; N],
        };
        let rows = baked.pos_params.iter_mut().zip(baked.vel_params.iter_mut());
        let boundary = baked
            .pos_y0
            .iter_mut()
            .zip(baked.pos_v0.iter_mut())
            .zip(baked.vel_y0.iter_mut().zip(baked.vel_v0.iter_mut()));
        for (step, ((pos_row, vel_row), ((pos_y0, pos_v0), (vel_y0, vel_v0)))) in
            rows.zip(boundary).enumerate()
        {
            let mut pos64 = [0.0; P];
            let mut vel64 = [0.0; P];
            let time = Self::query_time(cfg, step + 1);
            let coeffs = decoder.linear_row(0.0, time, &mut pos64, &mut vel64)?;
            for (out, value) in pos_row.iter_mut().zip(pos64.iter()) {
                *out = narrow(*value)?;
            }
            for (out, value) in vel_row.iter_mut().zip(vel64.iter()) {
                *out = narrow(*value)?;
            }
            *pos_y0 = narrow(coeffs.pos_y0)?;
            *pos_v0 = narrow(coeffs.pos_v0)?;
            *vel_y0 = narrow(coeffs.vel_y0)?;
            *vel_v0 = narrow(coeffs.vel_v0)?;
        }
        Ok(baked)
    }

    /// Initial-condition coefficients per query time, first to last.
    pub fn boundary_rows(&self) -> impl Iterator<Item = BoundaryRow> + '_ {
        self.pos_y0
            .iter()
            .zip(self.pos_v0.iter())
            .zip(self.vel_y0.iter().zip(self.vel_v0.iter()))
            .map(|((&pos_y0, &pos_v0), (&vel_y0, &vel_v0))| BoundaryRow {
                pos_y0,
                pos_v0,
                vel_y0,
                vel_v0,
            })
    }

    /// Decodes `K` DoFs: `params[d] = [w_0 .. w_{P-2}, g]`, `y0[d]` (units), `v0[d]` (units/s);
    /// writes `pos[t][d]` (units) and `vel[t][d]` (units/s) for the `N` query times. Non-finite
    /// inputs or outputs are errors (outputs are then unspecified).
    pub fn decode<const K: usize>(
        &self,
        params: &[[f32; P]; K],
        y0: &[f32; K],
        v0: &[f32; K],
        pos: &mut [[f32; K]; N],
        vel: &mut [[f32; K]; N],
    ) -> Result<(), ProDmpError> {
        let inputs_finite = params
            .iter()
            .flatten()
            .chain(y0)
            .chain(v0)
            .all(|v| v.is_finite());
        if !inputs_finite {
            return Err(ProDmpError::NonFiniteInput);
        }
        let tables = self.pos_params.iter().zip(self.vel_params.iter()).zip(
            self.pos_y0
                .iter()
                .zip(self.pos_v0.iter())
                .zip(self.vel_y0.iter().zip(self.vel_v0.iter())),
        );
        for (((pos_row, vel_row), ((pos_y0, pos_v0), (vel_y0, vel_v0))), (pos_t, vel_t)) in
            tables.zip(pos.iter_mut().zip(vel.iter_mut()))
        {
            let dofs = params.iter().zip(y0.iter().zip(v0.iter()));
            for ((theta, (y0, v0)), (pos_out, vel_out)) in
                dofs.zip(pos_t.iter_mut().zip(vel_t.iter_mut()))
            {
                *pos_out = apply_row_f32(pos_row, *pos_y0, *pos_v0, theta, *y0, *v0);
                *vel_out = apply_row_f32(vel_row, *vel_y0, *vel_v0, theta, *y0, *v0);
            }
        }
        let outputs_finite = pos
            .iter()
            .flatten()
            .chain(vel.iter().flatten())
            .all(|v| v.is_finite());
        if outputs_finite {
            Ok(())
        } else {
            Err(ProDmpError::NonFiniteResult)
        }
    }
}
