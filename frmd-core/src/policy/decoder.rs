//! The policy's ProDMP decoder: a view of the baked f32 tables ([`crate::prodmp::BakedProDmp`]
//! flattened, a blob section, or the exporter's owned tables) with run-time horizon `n` and
//! parameters per DoF `p`, decoded with [`apply_row_f32`] (the rounding every decode shares).

use super::dims::{all_finite, fixed_row_pairs, fixed_rows};
use super::PolicyError;
use crate::prodmp::{apply_row_f32, BakedProDmp, BoundaryRow, ProDmpError};

#[cfg(not(target_os = "none"))]
mod lockstep;

/// ProDMP decoder tables, row-major (`[n][p]` and `[n]`), as in [`BakedProDmp`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProDmpTables<'p> {
    /// `[n][p]` position coefficients of `[w.., g]`.
    pub pos_params: &'p [f32],
    /// `[n][p]` velocity coefficients (1/s).
    pub vel_params: &'p [f32],
    /// `[n]` position coefficient of `y0`.
    pub pos_y0: &'p [f32],
    /// `[n]` position coefficient of `v0` (s).
    pub pos_v0: &'p [f32],
    /// `[n]` velocity coefficient of `y0` (1/s).
    pub vel_y0: &'p [f32],
    /// `[n]` velocity coefficient of `v0`.
    pub vel_v0: &'p [f32],
}

impl<'p> ProDmpTables<'p> {
    /// The tables of a baked decoder.
    pub const fn from_baked<const N: usize, const P: usize>(baked: &'p BakedProDmp<N, P>) -> Self {
        Self {
            pos_params: baked.pos_params.as_flattened(),
            vel_params: baked.vel_params.as_flattened(),
            pos_y0: &baked.pos_y0,
            pos_v0: &baked.pos_v0,
            vel_y0: &baked.vel_y0,
            vel_v0: &baked.vel_v0,
        }
    }

    /// The six tables of `values`, laid out back to back in the order of the fields (the blob
    /// section); `None` unless `values` holds exactly `n (2 p + 4)` values.
    pub fn split(values: &'p [f32], horizon: usize, params_per_dof: usize) -> Option<Self> {
        let table = horizon.checked_mul(params_per_dof)?;
        let (pos_params, rest) = values.split_at_checked(table)?;
        let (vel_params, rest) = rest.split_at_checked(table)?;
        let (pos_y0, rest) = rest.split_at_checked(horizon)?;
        let (pos_v0, rest) = rest.split_at_checked(horizon)?;
        let (vel_y0, vel_v0) = rest.split_at_checked(horizon)?;
        (vel_v0.len() == horizon).then_some(Self {
            pos_params,
            vel_params,
            pos_y0,
            pos_v0,
            vel_y0,
            vel_v0,
        })
    }

    /// Number of values of the six tables for `n` query times and `p` parameters per DoF:
    /// `n (2 p + 4)`; `None` on overflow.
    pub fn len_for(horizon: usize, params_per_dof: usize) -> Option<usize> {
        params_per_dof
            .checked_mul(2)?
            .checked_add(4)?
            .checked_mul(horizon)
    }

    /// Query times `n`.
    pub fn horizon(&self) -> usize {
        self.pos_y0.len()
    }

    /// Parameters per DoF `p` (0 for empty tables).
    pub fn params_per_dof(&self) -> usize {
        self.pos_params
            .len()
            .checked_div(self.horizon())
            .unwrap_or(0)
    }

    /// Checks that the tables agree: `n >= 1`, both parameter tables `n p` long, every column
    /// `n` long, all values finite.
    pub fn validate(&self) -> Result<(), PolicyError> {
        let n = self.horizon();
        let np = n.checked_mul(self.params_per_dof());
        let columns = [self.pos_v0, self.vel_y0, self.vel_v0];
        let consistent = n > 0
            && Some(self.pos_params.len()) == np
            && Some(self.vel_params.len()) == np
            && columns.iter().all(|c| c.len() == n);
        let finite = self
            .pos_params
            .iter()
            .chain(self.vel_params)
            .chain(self.pos_y0)
            .chain(self.pos_v0)
            .chain(self.vel_y0)
            .chain(self.vel_v0)
            .all(|v| v.is_finite());
        if consistent && finite {
            Ok(())
        } else {
            Err(PolicyError::Decode(ProDmpError::WrongLength))
        }
    }

    /// Initial-condition coefficients per query time, first to last.
    pub fn boundary_rows(&self) -> impl Iterator<Item = BoundaryRow> + '_ {
        self.pos_y0
            .iter()
            .zip(self.pos_v0)
            .zip(self.vel_y0.iter().zip(self.vel_v0))
            .map(|((&pos_y0, &pos_v0), (&vel_y0, &vel_v0))| BoundaryRow {
                pos_y0,
                pos_v0,
                vel_y0,
                vel_v0,
            })
    }

    /// Decodes `k = y0.len()` DoFs: `params` DoF-major (`[k][p]`, `[w_0 .. w_{p-2}, g]` each),
    /// `y0` (units), `v0` (units/s); writes `positions` and `velocities` (`[n][k]`, step-major).
    /// Rounds exactly as [`BakedProDmp::decode`]. `N`, `K` and `P` are the caller's capacities:
    /// when the sizes equal them (a firmware image), the loops have compile-time trip counts.
    /// Non-finite inputs or outputs are errors (outputs are then unspecified).
    pub fn decode<const N: usize, const K: usize, const P: usize>(
        &self,
        params: &[f32],
        y0: &[f32],
        v0: &[f32],
        positions: &mut [f32],
        velocities: &mut [f32],
    ) -> Result<(), ProDmpError> {
        let (k, p) = (y0.len(), self.params_per_dof());
        let nk = self.horizon().checked_mul(k);
        if v0.len() != k
            || Some(params.len()) != k.checked_mul(p)
            || Some(positions.len()) != nk
            || Some(velocities.len()) != nk
            || p == 0
            || k == 0
        {
            return Err(ProDmpError::WrongLength);
        }
        if !params.iter().chain(y0).chain(v0).all(|v| v.is_finite()) {
            return Err(ProDmpError::NonFiniteInput);
        }
        #[cfg(not(target_os = "none"))]
        if self.decode_on_host::<P>(params, y0, v0, positions, velocities) {
            return finite_outputs(positions, velocities);
        }
        let fixed = (
            fixed_rows::<N, P>(self.pos_params),
            fixed_rows::<N, P>(self.vel_params),
            fixed_rows::<K, P>(params),
        );
        if let ((Some(pos_rows), Some(vel_rows), Some(thetas)), true) = (fixed, (k, p) == (K, P)) {
            if let Some(outputs) = fixed_row_pairs::<N, K>(positions, velocities) {
                self.decode_rows(pos_rows, vel_rows, thetas, y0, v0, outputs);
            }
        } else {
            let thetas = params.chunks_exact(p);
            let outputs = positions
                .chunks_exact_mut(k)
                .zip(velocities.chunks_exact_mut(k));
            let (pos_rows, vel_rows) = (
                self.pos_params.chunks_exact(p),
                self.vel_params.chunks_exact(p),
            );
            self.decode_rows(pos_rows, vel_rows, thetas, y0, v0, outputs);
        }
        finite_outputs(positions, velocities)
    }

    /// The decode loop over rows of the tables, the parameters and the outputs.
    #[inline(always)]
    pub(super) fn decode_rows<'r, 'o>(
        &self,
        pos_rows: impl Iterator<Item = &'r [f32]>,
        vel_rows: impl Iterator<Item = &'r [f32]>,
        thetas: impl Iterator<Item = &'r [f32]> + Clone,
        y0: &[f32],
        v0: &[f32],
        outputs: impl Iterator<Item = (&'o mut [f32], &'o mut [f32])>,
    ) {
        let tables = pos_rows.zip(vel_rows).zip(self.boundary_rows());
        for (((pos_row, vel_row), b), (pos_t, vel_t)) in tables.zip(outputs) {
            let dofs = thetas.clone().zip(y0.iter().zip(v0));
            for ((theta, (y0, v0)), (pos_out, vel_out)) in
                dofs.zip(pos_t.iter_mut().zip(vel_t.iter_mut()))
            {
                *pos_out = apply_row_f32(pos_row, b.pos_y0, b.pos_v0, theta, *y0, *v0);
                *vel_out = apply_row_f32(vel_row, b.vel_y0, b.vel_v0, theta, *y0, *v0);
            }
        }
    }
}

/// `Ok` when every decoded value is finite.
fn finite_outputs(positions: &[f32], velocities: &[f32]) -> Result<(), ProDmpError> {
    if all_finite(positions, velocities) {
        Ok(())
    } else {
        Err(ProDmpError::NonFiniteResult)
    }
}
