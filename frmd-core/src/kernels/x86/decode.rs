//! The hosts' ProDMP decode of eight DoFs at once in 256-bit registers (`policy::decoder`'s
//! lockstep decode on CPUs with AVX2): one lane per DoF, each output summed in
//! `prodmp::apply_row_f32`'s order (the boundary products added, then each parameter's product
//! in turn) with separate `vmulps` / `vaddps`, so every lane rounds as the scalar decode does.
#![allow(unsafe_code)]

use super::Avx2;
use crate::prodmp::BoundaryRow;
use core::arch::x86_64::{
    __m256, _mm256_add_ps, _mm256_loadu_ps, _mm256_mul_ps, _mm256_set1_ps, _mm256_storeu_ps,
};

/// DoFs per pass.
pub(crate) const DECODE_LANES: usize = 8;

/// Loads eight floats.
#[inline]
#[target_feature(enable = "avx2")]
fn load(values: &[f32; DECODE_LANES]) -> __m256 {
    // SAFETY: the pointer comes from a `&[f32; 8]`: 32 initialized, readable bytes; `loadu` has
    // no alignment requirement.
    unsafe { _mm256_loadu_ps(values.as_ptr()) }
}

/// Stores eight floats.
#[inline]
#[target_feature(enable = "avx2")]
fn store(out: &mut [f32; DECODE_LANES], lanes: __m256) {
    // SAFETY: the pointer comes from a `&mut [f32; 8]`: 32 writable bytes; no alignment needed.
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), lanes) }
}

/// `coeff_y0 y0 + coeff_v0 v0`, lane by lane, rounded as `apply_row_f32` rounds it.
#[inline]
#[target_feature(enable = "avx2")]
fn boundary(coeff_y0: f32, coeff_v0: f32, y0: __m256, v0: __m256) -> __m256 {
    _mm256_add_ps(
        _mm256_mul_ps(_mm256_set1_ps(coeff_y0), y0),
        _mm256_mul_ps(_mm256_set1_ps(coeff_v0), v0),
    )
}

/// One query time's coefficient rows and boundary coefficients.
type Row<'r> = ((&'r [f32], &'r [f32]), BoundaryRow);

/// The `(position, velocity)` lanes of the query times `rows` (one or two: two run as four
/// independent chains of adds, which the latency of `vaddps` leaves room for).
#[inline]
#[target_feature(enable = "avx2")]
fn query_times<const T: usize>(
    rows: [&Row<'_>; T],
    theta: &[[f32; DECODE_LANES]],
    (y0, v0): (__m256, __m256),
) -> [(__m256, __m256); T] {
    let mut acc = rows.map(|(_, b)| {
        (
            boundary(b.pos_y0, b.pos_v0, y0, v0),
            boundary(b.vel_y0, b.vel_v0, y0, v0),
        )
    });
    for (j, theta) in theta.iter().enumerate() {
        let theta = load(theta);
        for (((pos_row, vel_row), _), (pos, vel)) in rows.iter().zip(&mut acc) {
            let (Some(pos_coeff), Some(vel_coeff)) = (pos_row.get(j), vel_row.get(j)) else {
                continue;
            };
            *pos = _mm256_add_ps(*pos, _mm256_mul_ps(_mm256_set1_ps(*pos_coeff), theta));
            *vel = _mm256_add_ps(*vel, _mm256_mul_ps(_mm256_set1_ps(*vel_coeff), theta));
        }
    }
    acc
}

#[target_feature(enable = "avx2")]
fn decode_lanes<'r>(
    rows: impl Iterator<Item = Row<'r>>,
    theta: &[[f32; DECODE_LANES]],
    (y0, v0): (&[f32; DECODE_LANES], &[f32; DECODE_LANES]),
    mut emit: impl FnMut(&[f32; DECODE_LANES], &[f32; DECODE_LANES]),
) {
    let initial = (load(y0), load(v0));
    let mut emit_lanes = |(pos, vel): (__m256, __m256)| {
        let (mut pos_out, mut vel_out) = ([0.0; DECODE_LANES], [0.0; DECODE_LANES]);
        store(&mut pos_out, pos);
        store(&mut vel_out, vel);
        emit(&pos_out, &vel_out);
    };
    let mut rows = rows;
    while let Some(first) = rows.next() {
        match rows.next() {
            Some(second) => {
                let [a, b] = query_times([&first, &second], theta, initial);
                emit_lanes(a);
                emit_lanes(b);
            }
            None => {
                let [a] = query_times([&first], theta, initial);
                emit_lanes(a);
            }
        }
    }
}

impl Avx2 {
    /// For every query time of `rows` (its position and velocity coefficient rows and boundary
    /// coefficients), in order: `emit(pos, vel)` where lane `d` is
    /// `apply_row_f32(row, .., theta[..][d], y0[d], v0[d])` (`theta[j][d]`: parameter `j` of
    /// DoF `d`; rows longer than `theta` use its length). Query times run in pairs.
    pub(crate) fn decode_lanes<'r>(
        self,
        rows: impl Iterator<Item = Row<'r>>,
        theta: &[[f32; DECODE_LANES]],
        initial: (&[f32; DECODE_LANES], &[f32; DECODE_LANES]),
        emit: impl FnMut(&[f32; DECODE_LANES], &[f32; DECODE_LANES]),
    ) {
        // SAFETY: an `Avx2` token exists only after `avx2_active()` detected AVX2.
        unsafe { decode_lanes(rows, theta, initial, emit) }
    }
}
