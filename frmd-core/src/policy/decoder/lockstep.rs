//! The hosts' decode: the positions and velocities of several DoFs at one query time summed in
//! lockstep, one lane per DoF, each lane in [`apply_row_f32`]'s order (separate multiplies and
//! adds, which SIMD units round lane by lane): the same bits as the firmware's
//! [`ProDmpTables::decode_rows`], where one dependent chain runs after the other (0.9-1.4 us of
//! a 4.4 us x86 MLP-256 int8 chunk with it). Eight lanes in AVX2 registers on x86-64 CPUs with
//! AVX2 (`kernels::x86`), four lanes (SSE, NEON through LLVM) elsewhere. The firmware keeps
//! `decode_rows` and its instruction counts.

use super::ProDmpTables;
use crate::prodmp::{apply_row_f32, BoundaryRow};

/// A decode of `LANES` DoFs at once.
trait Lanes<const LANES: usize> {
    /// For every query time of `rows` (position and velocity coefficient rows, boundary
    /// coefficients), in order: `emit(pos, vel)` where lane `d` is the [`apply_row_f32`] of DoF
    /// `d` (`theta[j][d]`: its parameter `j`; `initial`: the lanes' `y0`, `v0`).
    fn run<'r>(
        &self,
        rows: impl Iterator<Item = ((&'r [f32], &'r [f32]), BoundaryRow)>,
        theta: &[[f32; LANES]],
        initial: (&[f32; LANES], &[f32; LANES]),
        emit: impl FnMut(&[f32; LANES], &[f32; LANES]),
    );
}

/// The lanes as plain arrays (vectorized by LLVM for the target's baseline).
struct Portable;

impl<const LANES: usize> Lanes<LANES> for Portable {
    #[inline(always)]
    fn run<'r>(
        &self,
        rows: impl Iterator<Item = ((&'r [f32], &'r [f32]), BoundaryRow)>,
        theta: &[[f32; LANES]],
        (y0, v0): (&[f32; LANES], &[f32; LANES]),
        mut emit: impl FnMut(&[f32; LANES], &[f32; LANES]),
    ) {
        for ((pos_row, vel_row), b) in rows {
            let (mut pos, mut vel) = ([0.0_f32; LANES], [0.0_f32; LANES]);
            for (((pos, vel), y0), v0) in pos.iter_mut().zip(&mut vel).zip(y0).zip(v0) {
                *pos = apply_row_f32(&[], b.pos_y0, b.pos_v0, &[], *y0, *v0);
                *vel = apply_row_f32(&[], b.vel_y0, b.vel_v0, &[], *y0, *v0);
            }
            for ((pos_coeff, vel_coeff), theta) in pos_row.iter().zip(vel_row).zip(theta) {
                for ((pos, vel), theta) in pos.iter_mut().zip(&mut vel).zip(theta) {
                    *pos += pos_coeff * theta;
                    *vel += vel_coeff * theta;
                }
            }
            emit(&pos, &vel);
        }
    }
}

#[cfg(target_arch = "x86_64")]
impl Lanes<{ crate::kernels::x86::DECODE_LANES }> for crate::kernels::x86::Avx2 {
    #[inline(always)]
    fn run<'r>(
        &self,
        rows: impl Iterator<Item = ((&'r [f32], &'r [f32]), BoundaryRow)>,
        theta: &[[f32; crate::kernels::x86::DECODE_LANES]],
        initial: (
            &[f32; crate::kernels::x86::DECODE_LANES],
            &[f32; crate::kernels::x86::DECODE_LANES],
        ),
        emit: impl FnMut(
            &[f32; crate::kernels::x86::DECODE_LANES],
            &[f32; crate::kernels::x86::DECODE_LANES],
        ),
    ) {
        self.decode_lanes(rows, theta, initial, emit);
    }
}

impl ProDmpTables<'_> {
    /// The lockstep decode with this host's lanes; false (nothing written) when `p > P`.
    /// Callers checked the lengths.
    pub(super) fn decode_on_host<const P: usize>(
        &self,
        params: &[f32],
        y0: &[f32],
        v0: &[f32],
        positions: &mut [f32],
        velocities: &mut [f32],
    ) -> bool {
        let outputs = (positions, velocities);
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = crate::kernels::x86::Avx2::get() {
            return self.decode_lockstep::<P, _, { crate::kernels::x86::DECODE_LANES }>(
                &avx2, params, y0, v0, outputs,
            );
        }
        self.decode_lockstep::<P, _, 4>(&Portable, params, y0, v0, outputs)
    }

    /// Decodes the DoFs in groups of `LANES` with `lanes`; false (nothing written) when
    /// `p > P`.
    #[inline(always)]
    fn decode_lockstep<const P: usize, L: Lanes<LANES>, const LANES: usize>(
        &self,
        lanes: &L,
        params: &[f32],
        y0: &[f32],
        v0: &[f32],
        (positions, velocities): (&mut [f32], &mut [f32]),
    ) -> bool {
        let (k, p) = (y0.len(), self.params_per_dof());
        if p > P || p == 0 || k == 0 {
            return false;
        }
        let mut rows = params.chunks_exact(p);
        let groups = y0.chunks(LANES).zip(v0.chunks(LANES));
        for (first, (y0, v0)) in (0..).step_by(LANES).zip(groups) {
            // theta[j] = parameter j of the group's DoFs (0 in unused lanes).
            let mut theta = [[0.0_f32; LANES]; P];
            for (lane, row) in rows.by_ref().take(y0.len()).enumerate() {
                for (slot, value) in theta.iter_mut().zip(row) {
                    if let Some(slot) = slot.get_mut(lane) {
                        *slot = *value;
                    }
                }
            }
            let (mut y0_lanes, mut v0_lanes) = ([0.0_f32; LANES], [0.0_f32; LANES]);
            for ((slot, value), (v_slot, v_value)) in
                y0_lanes.iter_mut().zip(y0).zip(v0_lanes.iter_mut().zip(v0))
            {
                (*slot, *v_slot) = (*value, *v_value);
            }
            let tables = (self.pos_params.chunks_exact(p))
                .zip(self.vel_params.chunks_exact(p))
                .zip(self.boundary_rows());
            let mut outputs = positions
                .chunks_exact_mut(k)
                .zip(velocities.chunks_exact_mut(k));
            let theta = theta.get(..p).unwrap_or(&[]);
            lanes.run(tables, theta, (&y0_lanes, &v0_lanes), |pos, vel| {
                if let Some((pos_t, vel_t)) = outputs.next() {
                    let out = pos_t.iter_mut().zip(vel_t).skip(first).take(y0.len());
                    for ((pos_out, vel_out), (pos, vel)) in out.zip(pos.iter().zip(vel)) {
                        (*pos_out, *vel_out) = (*pos, *vel);
                    }
                }
            });
        }
        true
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::{Portable, ProDmpTables};
    use std::vec::Vec;

    /// The host's lockstep decode gives the bits of the firmware's row-by-row decode.
    #[test]
    fn lockstep_decode_equals_row_decode() {
        let mut state = 0x9E37_79B9_u32;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state as f32 / u32::MAX as f32 - 0.5) * 7.0
        };
        for (n, p, k) in [(12, 21, 2), (12, 21, 7), (1, 1, 1), (30, 9, 16)] {
            let mut values = |len: usize| (0..len).map(|_| next()).collect::<Vec<f32>>();
            let (pos_params, vel_params) = (values(n * p), values(n * p));
            let columns = [values(n), values(n), values(n), values(n)];
            let tables = ProDmpTables {
                pos_params: &pos_params,
                vel_params: &vel_params,
                pos_y0: &columns[0],
                pos_v0: &columns[1],
                vel_y0: &columns[2],
                vel_v0: &columns[3],
            };
            let (params, y0, v0) = (values(k * p), values(k), values(k));
            // Four lanes, eight lanes, and the host's own choice (eight in AVX2 registers on
            // x86-64 CPUs with AVX2).
            let mut four = (std::vec![0.0; n * k], std::vec![0.0; n * k]);
            let mut eight = four.clone();
            let mut host = four.clone();
            let (a, b) = (&mut four.0[..], &mut four.1[..]);
            assert!(tables.decode_lockstep::<32, _, 4>(&Portable, &params, &y0, &v0, (a, b)));
            let (a, b) = (&mut eight.0[..], &mut eight.1[..]);
            assert!(tables.decode_lockstep::<32, _, 8>(&Portable, &params, &y0, &v0, (a, b)));
            assert!(tables.decode_on_host::<32>(&params, &y0, &v0, &mut host.0, &mut host.1));
            let mut rows = (std::vec![0.0; n * k], std::vec![0.0; n * k]);
            let outputs = rows.0.chunks_exact_mut(k).zip(rows.1.chunks_exact_mut(k));
            let (pos_rows, vel_rows) = (pos_params.chunks_exact(p), vel_params.chunks_exact(p));
            tables.decode_rows(
                pos_rows,
                vel_rows,
                params.chunks_exact(p),
                &y0,
                &v0,
                outputs,
            );
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<u32>>();
            for (lanes, lockstep) in [(4, &four), (8, &eight), (0, &host)] {
                assert_eq!(
                    bits(&lockstep.0),
                    bits(&rows.0),
                    "positions n {n} p {p} k {k} lanes {lanes}"
                );
                assert_eq!(
                    bits(&lockstep.1),
                    bits(&rows.1),
                    "velocities n {n} p {p} k {k} lanes {lanes}"
                );
            }
        }
        // More parameters per DoF than the capacity: refused, nothing written.
        let wide = ProDmpTables::split(&[0.0; 40], 1, 18).unwrap();
        let mut out = [7.0];
        assert!(!wide.decode_on_host::<16>(&[0.0; 18], &[0.0], &[0.0], &mut out, &mut [7.0]));
        assert_eq!(out, [7.0]);
    }
}
