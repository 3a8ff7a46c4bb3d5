//! AVX2 four-row int8 matrix-vector kernel (see the module docs of `kernels::x86`).
//!
//! Per 16 input columns the input is loaded and sign-extended to 16 halfwords once
//! (`vpmovsxbw`), and for each of the four rows: one `vpmovsxbw` of 16 weights, one `vpmaddwd`
//! (16 products summed in pairs into 8 int32 lanes) and one `vpaddd`: 13 instructions per 64
//! multiply-accumulates. The last `columns % 16` columns use [`dot_i8_prefix`].
//!
//! Bit-exactness: an int8 x int8 product lies in `[-16256, 16384]`, so a `vpmaddwd` pair sum (at
//! most 32768 in magnitude) is exact in int32; `vpaddd` and `vphaddd` add modulo 2^32. Every row
//! sum is the wrapping int32 sum of the same products as the portable kernel, and wrapping
//! addition does not depend on order.
#![allow(unsafe_code)]

use super::avx2_active;
use crate::kernels::dot::dot_i8_prefix;
use crate::kernels::matvec::{for_each_row_block, for_each_row_dot_portable, ROWS};
use core::arch::x86_64::{
    __m128i, __m256i, _mm256_add_epi32, _mm256_castsi256_si128, _mm256_cvtepi8_epi16,
    _mm256_extracti128_si256, _mm256_hadd_epi32, _mm256_madd_epi16, _mm256_setzero_si256,
    _mm_add_epi32, _mm_cvtsi128_si32, _mm_extract_epi32, _mm_loadu_si128,
};

/// The matrix-vector product `emit(dot(row, input))` per row, in row order, with the AVX2
/// four-row kernel (callers checked [`avx2_active`]; without AVX2 this runs the portable kernel).
#[inline]
pub(crate) fn for_each_row_dot_avx2(weights: &[i8], input: &[i8], emit: &mut impl FnMut(i32)) {
    if !avx2_active() {
        for_each_row_dot_portable(weights, input, emit);
        return;
    }
    for_each_row_block(weights, input, emit, |rows, input| {
        // SAFETY: `avx2_active()` returned true, so the CPU supports AVX2 and the OS saves the
        // YMM registers (see `detect_avx2`).
        unsafe { dot_four_rows_avx2(rows, input) }
    });
}

/// Columns per `vpmaddwd` step.
const COLUMNS: usize = 16;

/// `[dot(rows[r], input) for r in 0..4]` (rows as long as `input`), wrapping int32 sums.
#[target_feature(enable = "avx2")]
fn dot_four_rows_avx2(rows: [&[i8]; ROWS], input: &[i8]) -> [i32; ROWS] {
    let (x_blocks, x_tail) = input.as_chunks::<COLUMNS>();
    let [(w0, t0), (w1, t1), (w2, t2), (w3, t3)] = rows.map(|row| row.as_chunks::<COLUMNS>());
    let mut acc = [_mm256_setzero_si256(); ROWS];
    let blocks = x_blocks.iter().zip(w0).zip(w1).zip(w2).zip(w3);
    for ((((x, w0), w1), w2), w3) in blocks {
        let x = widen(x);
        let [a0, a1, a2, a3] = &mut acc;
        *a0 = _mm256_add_epi32(*a0, _mm256_madd_epi16(widen(w0), x));
        *a1 = _mm256_add_epi32(*a1, _mm256_madd_epi16(widen(w1), x));
        *a2 = _mm256_add_epi32(*a2, _mm256_madd_epi16(widen(w2), x));
        *a3 = _mm256_add_epi32(*a3, _mm256_madd_epi16(widen(w3), x));
    }
    let [a0, a1, a2, a3] = acc;
    // Lanes of `quad`: per 128-bit half, [sum of a0's four lanes, a1's, a2's, a3's].
    let quad = _mm256_hadd_epi32(_mm256_hadd_epi32(a0, a1), _mm256_hadd_epi32(a2, a3));
    let sums = _mm_add_epi32(
        _mm256_castsi256_si128(quad),
        _mm256_extracti128_si256::<1>(quad),
    );
    let body = [
        _mm_cvtsi128_si32(sums),
        _mm_extract_epi32::<1>(sums),
        _mm_extract_epi32::<2>(sums),
        _mm_extract_epi32::<3>(sums),
    ];
    let mut out = [0_i32; ROWS];
    for ((total, body), tail) in out.iter_mut().zip(body).zip([t0, t1, t2, t3]) {
        let tail_sum = if x_tail.is_empty() {
            0
        } else {
            dot_i8_prefix(tail, x_tail)
        };
        *total = body.wrapping_add(tail_sum);
    }
    out
}

/// Loads 16 int8 values and sign-extends them to 16 int16 lanes.
#[inline]
#[target_feature(enable = "avx2")]
fn widen(block: &[i8; COLUMNS]) -> __m256i {
    // SAFETY: the pointer comes from a `&[i8; 16]`: 16 initialized, readable bytes; `loadu`
    // has no alignment requirement.
    let bytes = unsafe { _mm_loadu_si128(block.as_ptr().cast::<__m128i>()) };
    _mm256_cvtepi8_epi16(bytes)
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::kernels::matvec::tests::{random_cases, wide_row_sums};
    use crate::kernels::x86::avx2_supported;
    use std::vec::Vec;

    #[test]
    fn avx2_kernel_matches_portable_and_wide_sums() {
        if !avx2_supported() {
            std::eprintln!("no AVX2 on this CPU: only the portable kernel is exercised");
            return;
        }
        random_cases(0xA7, |weights, input| {
            let (mut avx2, mut portable) = (Vec::new(), Vec::new());
            for_each_row_dot_avx2(weights, input, &mut |sum| avx2.push(sum));
            for_each_row_dot_portable(weights, input, &mut |sum| portable.push(sum));
            assert_eq!(avx2, portable, "columns {}", input.len());
            let wide: Vec<i64> = avx2.iter().map(|s| i64::from(*s)).collect();
            assert_eq!(wide, wide_row_sums(weights, input));
        });
    }

    #[test]
    fn avx2_kernel_wraps_like_the_portable_one() {
        if !avx2_supported() {
            return;
        }
        // 65 537 * 2 products of 16384 exceed i32::MAX: both kernels wrap identically.
        static COLUMN: [i8; 131_074] = [-128; 131_074];
        let weights: Vec<i8> = COLUMN
            .iter()
            .chain(&COLUMN)
            .chain(&COLUMN)
            .chain(&COLUMN)
            .copied()
            .collect();
        let (mut avx2, mut portable) = (Vec::new(), Vec::new());
        for_each_row_dot_avx2(&weights, &COLUMN, &mut |sum| avx2.push(sum));
        for_each_row_dot_portable(&weights, &COLUMN, &mut |sum| portable.push(sum));
        let wide = (131_074_i64 * 16384) as i32;
        assert_eq!(avx2, [wide; 4]);
        assert_eq!(portable, avx2);
    }

    #[test]
    fn switching_reports_the_state() {
        // Only reads the state: other tests of this process may run the kernels concurrently.
        assert_eq!(avx2_active(), avx2_supported());
    }
}
