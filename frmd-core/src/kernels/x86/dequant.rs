//! AVX2 dequantization of int64 accumulators (the int16-activation layers' outputs), eight at a
//! time, with the bits of [`crate::quant::dequantize_wide`]: `hi = (acc + 2^23) >> 24` and
//! `lo = acc - hi 2^24` are taken in their low 32 bits (bits 24..55 of `acc + 2^23` are the
//! same for a logical and an arithmetic shift, and `lo` is defined modulo 2^32), converted with
//! `vcvtdq2ps` (round to nearest, as `as f32`) and combined as `hi (scale 2^24) + lo scale` by
//! separate `vmulps` and `vaddps` (each rounded once, as the scalar expression).
#![allow(unsafe_code)]

use super::wide::load_i64x4;
use super::{Avx2, BLOCK_ROWS};
use crate::quant::dequantize_wide;
use core::arch::x86_64::{
    __m128i, __m256, __m256i, _mm256_add_epi64, _mm256_add_ps, _mm256_castsi256_si128,
    _mm256_cvtepi32_ps, _mm256_loadu_ps, _mm256_mul_ps, _mm256_permutevar8x32_epi32,
    _mm256_set1_epi64x, _mm256_set1_ps, _mm256_set_m128i, _mm256_setr_epi32, _mm256_slli_epi32,
    _mm256_srli_epi64, _mm256_storeu_ps, _mm256_sub_epi32,
};

impl Avx2 {
    /// `out[o] = dequantize_wide(acc[o], scales[o])` over the common length.
    #[inline]
    pub(crate) fn dequantize_wide(self, acc: &[i64], scales: &[f32], out: &mut [f32]) {
        // SAFETY: the token exists only while AVX2 is supported and enabled (see `x86`).
        unsafe { dequantize_wide_avx2(acc, scales, out) }
    }
}

#[target_feature(enable = "avx2")]
fn dequantize_wide_avx2(acc: &[i64], scales: &[f32], out: &mut [f32]) {
    // The caller checked that the lengths agree; a shorter slice would end the blocks early.
    let (acc_blocks, acc_tail) = acc.as_chunks::<BLOCK_ROWS>();
    let (scale_blocks, scale_tail) = scales.as_chunks::<BLOCK_ROWS>();
    let (out_blocks, out_tail) = out.as_chunks_mut::<BLOCK_ROWS>();
    for ((a, s), o) in acc_blocks.iter().zip(scale_blocks).zip(out_blocks) {
        store(o, block(a, load_ps(s)));
    }
    for ((a, s), o) in acc_tail.iter().zip(scale_tail).zip(out_tail) {
        *o = dequantize_wide(*a, *s);
    }
}

/// Eight accumulators at eight scales.
#[inline]
#[target_feature(enable = "avx2")]
fn block(acc: &[i64; BLOCK_ROWS], scale: __m256) -> __m256 {
    let [a, b, c, d, e, f, g, h] = *acc;
    let (a0, a1) = (load_i64x4(&[a, b, c, d]), load_i64x4(&[e, f, g, h]));
    let half = _mm256_set1_epi64x(1 << 23);
    let hi = low_words(
        _mm256_srli_epi64::<24>(_mm256_add_epi64(a0, half)),
        _mm256_srli_epi64::<24>(_mm256_add_epi64(a1, half)),
    );
    let lo = _mm256_sub_epi32(low_words(a0, a1), _mm256_slli_epi32::<24>(hi));
    let wide_scale = _mm256_mul_ps(scale, _mm256_set1_ps(16_777_216.0));
    _mm256_add_ps(
        _mm256_mul_ps(_mm256_cvtepi32_ps(hi), wide_scale),
        _mm256_mul_ps(_mm256_cvtepi32_ps(lo), scale),
    )
}

/// The low 32 bits of the four int64 lanes of `a`, then of `b`, as eight int32 lanes in order.
#[inline]
#[target_feature(enable = "avx2")]
fn low_words(a: __m256i, b: __m256i) -> __m256i {
    let even = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
    let a: __m128i = _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(a, even));
    let b: __m128i = _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(b, even));
    _mm256_set_m128i(b, a)
}

#[inline]
#[target_feature(enable = "avx2")]
fn load_ps(values: &[f32; BLOCK_ROWS]) -> __m256 {
    // SAFETY: the pointer comes from a `&[f32; 8]`: 32 initialized, readable bytes; `loadu` has
    // no alignment requirement.
    unsafe { _mm256_loadu_ps(values.as_ptr()) }
}

#[inline]
#[target_feature(enable = "avx2")]
fn store(out: &mut [f32; BLOCK_ROWS], values: __m256) {
    // SAFETY: the pointer comes from a `&mut [f32; 8]`: 32 writable bytes; no alignment needed.
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), values) }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::rng::Rng;
    use std::vec::Vec;

    /// Every length up to 41 (each remainder of the eight-lane blocks), accumulators from small
    /// to beyond the exact domain (`2^47`, `2^55`, the i64 extremes, which wrap alike), scales
    /// from tiny to large: the AVX2 bits equal `dequantize_wide`'s.
    #[test]
    fn avx2_dequantization_equals_the_scalar_definition() {
        let Some(avx2) = Avx2::get() else {
            std::eprintln!("no AVX2 on this CPU: nothing to compare");
            return;
        };
        let mut rng = Rng::new(41);
        let specials = [
            0,
            1,
            -1,
            (1 << 23) - 1,
            1 << 23,
            -(1 << 23),
            (1 << 47) - 3,
            -(1 << 47),
            1 << 55,
            -(1 << 55) - 7,
            i64::MAX,
            i64::MIN,
        ];
        for len in 0..=41 {
            for round in 0..20 {
                let acc: Vec<i64> = (0..len)
                    .map(|i| match round {
                        0 => specials[i % specials.len()],
                        _ => {
                            let bits = rng.next_u32() % 63;
                            let magnitude = (u64::from(rng.next_u32()) << 32
                                | u64::from(rng.next_u32()))
                                >> (63 - bits);
                            let value = magnitude as i64;
                            if rng.next_u32().is_multiple_of(2) {
                                value
                            } else {
                                -value
                            }
                        }
                    })
                    .collect();
                let scales: Vec<f32> = (0..len)
                    .map(|_| 10f32.powi((rng.next_u32() % 16) as i32 - 12) * (0.5 + rng.uniform()))
                    .collect();
                let mut got = std::vec![f32::NAN; len];
                avx2.dequantize_wide(&acc, &scales, &mut got);
                for ((a, s), g) in acc.iter().zip(&scales).zip(&got) {
                    assert_eq!(
                        g.to_bits(),
                        dequantize_wide(*a, *s).to_bits(),
                        "acc {a} scale {s}"
                    );
                }
            }
        }
    }
}
