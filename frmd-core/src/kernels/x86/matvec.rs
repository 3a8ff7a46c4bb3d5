//! AVX2 int8 fully connected rows, eight output channels per call (see `kernels::x86`).
//!
//! Per 16 input columns the input is loaded and sign-extended to 16 halfwords once
//! (`vpmovsxbw`), and for each of the eight rows: one `vpmovsxbw` of 16 weights, one `vpmaddwd`
//! (16 products summed in pairs into 8 int32 lanes) and one `vpaddd`: 25 instructions per 128
//! multiply-accumulates (then one 8-column step with 128-bit registers if at least 8 columns are
//! left). Three `vphaddd` levels and one 128-bit lane swap reduce the eight
//! accumulators to one vector of eight row sums, to which the bias is added; the requantizing
//! variant then runs `x86::requant` on that vector and packs eight int8 outputs, so accumulators
//! never leave the registers. The last `columns % 8` columns use [`dot_i8_prefix`].
//!
//! Bit-exactness: an int8 x int8 product lies in `[-16256, 16384]`, so a `vpmaddwd` pair sum (at
//! most 32768 in magnitude) is exact in int32; `vpaddd` and `vphaddd` add modulo 2^32. Every row
//! sum is the wrapping int32 sum of the same products as the portable kernel (wrapping addition
//! does not depend on order), plus the bias with wrapping addition as in `FullyConnected`.
//!
//! int16 inputs (the 16-bit first-layer plane, int16-activation layers) run the same loop with
//! the 16 codes loaded as they are instead of sign-extended (an int8 x int16 product is at most
//! `2^22`, a pair sum `2^23`: exact), so they cost the same 25 instructions per 128 MACs; their
//! sums start at any column (one 512-column chunk of an int64 accumulator, see `x86::wide`).
//!
//! Each kernel level has its `sums_*` macros here, for int8 and int16 inputs (AVX2; AVX-VNNI and
//! AVX-512 VNNI put a `x86::vnni` front before the AVX2 steps); `x86::layer` expands them inside
//! its loops over a whole layer.
#![allow(unsafe_code)]

use super::BLOCK_ROWS;
use core::arch::x86_64::{
    __m128i, __m256i, _mm256_add_epi32, _mm256_cvtepi8_epi16, _mm256_hadd_epi32,
    _mm256_loadu_si256, _mm256_permute2x128_si256, _mm_cvtepi8_epi16, _mm_loadl_epi64,
    _mm_loadu_si128,
};

/// Columns per `vpmaddwd` step.
pub(super) const COLUMNS: usize = 16;

/// Columns of the 128-bit step after the 16-column blocks.
pub(super) const HALF: usize = 8;

/// The end of every row-sum kernel, expanded in each so that everything stays in registers (as a
/// function, LLVM did not inline it and passed the eight accumulators through memory; its helpers
/// are named by path because the int8 kernels expand in `x86::layer`): adds
/// columns `$start..` of the eight `$rows` times `$input` to the partial sums `$acc` (16-column
/// `vpmaddwd` blocks, one 8-column step, then scalar) and reduces them to one vector of row sums.
/// The input is loaded by `$load` (16 columns), `$load_half` (8) and its tail summed by `$dot`:
/// int8 codes sign-extended by default, int16 codes as they are.
macro_rules! finish_row_sums {
    ($rows:expr, $input:expr, $acc:expr, $start:expr) => {
        finish_row_sums!(
            $rows,
            $input,
            $acc,
            $start,
            $crate::kernels::x86::matvec::widen,
            $crate::kernels::x86::matvec::widen_half,
            $crate::kernels::dot::dot_i8_prefix
        )
    };
    ($rows:expr, $input:expr, $acc:expr, $start:expr, $load:path, $load_half:path, $dot:path) => {
        // A closure called in place, so that its early `return`s end the expansion only; the
        // `use`s name the helpers wherever it expands.
        (|| -> core::arch::x86_64::__m256i {
            use core::arch::x86_64::{
                __m256i, _mm256_add_epi32, _mm256_madd_epi16, _mm256_zextsi128_si256,
                _mm_madd_epi16,
            };
            use $crate::kernels::x86::matvec::{reduce, widen, widen_half, COLUMNS, HALF};
            use $crate::kernels::x86::requant::load_i32;
            use $crate::kernels::x86::{rows_from, BLOCK_ROWS};
            let rows: [&[i8]; BLOCK_ROWS] = $rows;
            let start: usize = $start;
            let mut acc: [__m256i; BLOCK_ROWS] = $acc;
            let input = $input.get(start..).unwrap_or(&[]);
            if input.is_empty() {
                // A front took every column: only the reduction is left.
                return reduce(acc);
            }
            let rows = rows_from(rows, start);
            let [r0, r1, r2, r3, r4, r5, r6, r7] = rows;

            let (x_blocks, x_tail) = input.as_chunks::<COLUMNS>();
            let blocks = x_blocks
                .iter()
                .zip(r0.as_chunks::<COLUMNS>().0)
                .zip(r1.as_chunks::<COLUMNS>().0)
                .zip(r2.as_chunks::<COLUMNS>().0)
                .zip(r3.as_chunks::<COLUMNS>().0)
                .zip(r4.as_chunks::<COLUMNS>().0)
                .zip(r5.as_chunks::<COLUMNS>().0)
                .zip(r6.as_chunks::<COLUMNS>().0)
                .zip(r7.as_chunks::<COLUMNS>().0);
            for ((((((((x, w0), w1), w2), w3), w4), w5), w6), w7) in blocks {
                let x = $load(x);
                let [a0, a1, a2, a3, a4, a5, a6, a7] = &mut acc;
                *a0 = _mm256_add_epi32(*a0, _mm256_madd_epi16(widen(w0), x));
                *a1 = _mm256_add_epi32(*a1, _mm256_madd_epi16(widen(w1), x));
                *a2 = _mm256_add_epi32(*a2, _mm256_madd_epi16(widen(w2), x));
                *a3 = _mm256_add_epi32(*a3, _mm256_madd_epi16(widen(w3), x));
                *a4 = _mm256_add_epi32(*a4, _mm256_madd_epi16(widen(w4), x));
                *a5 = _mm256_add_epi32(*a5, _mm256_madd_epi16(widen(w5), x));
                *a6 = _mm256_add_epi32(*a6, _mm256_madd_epi16(widen(w6), x));
                *a7 = _mm256_add_epi32(*a7, _mm256_madd_epi16(widen(w7), x));
            }
            // Eight more columns with 128-bit registers when at least eight are left.
            let mut column = input.len() - x_tail.len();
            if let Some((x_half, _)) = x_tail.split_first_chunk::<HALF>() {
                let x = $load_half(x_half);
                for (a, row) in acc.iter_mut().zip(rows) {
                    let weights = row
                        .get(column..)
                        .and_then(|w| w.split_first_chunk::<HALF>());
                    if let Some((w, _)) = weights {
                        let products = _mm_madd_epi16(widen_half(w), x);
                        *a = _mm256_add_epi32(*a, _mm256_zextsi128_si256(products));
                    }
                }
                column += HALF;
            }
            let sums = reduce(acc);
            let Some(x_rest) = input.get(column..).filter(|rest| !rest.is_empty()) else {
                return sums;
            };
            let mut tails = [0_i32; BLOCK_ROWS];
            for (tail, row) in tails.iter_mut().zip(rows) {
                *tail = $dot(row.get(column..).unwrap_or(&[]), x_rest);
            }
            _mm256_add_epi32(sums, load_i32(&tails))
        })()
    };
}

/// One vector of the eight rows' sums: lane `r` is the sum of the eight lanes of `acc[r]`.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn reduce(acc: [__m256i; BLOCK_ROWS]) -> __m256i {
    let [a0, a1, a2, a3, a4, a5, a6, a7] = acc;
    // Per 128-bit half: [row 0 .. row 3 partial sums] and [row 4 .. row 7 partial sums].
    let first = _mm256_hadd_epi32(_mm256_hadd_epi32(a0, a1), _mm256_hadd_epi32(a2, a3));
    let second = _mm256_hadd_epi32(_mm256_hadd_epi32(a4, a5), _mm256_hadd_epi32(a6, a7));
    let low_halves = _mm256_permute2x128_si256::<0x20>(first, second);
    let high_halves = _mm256_permute2x128_si256::<0x31>(first, second);
    _mm256_add_epi32(low_halves, high_halves)
}

/// `[dot(rows[r][start..], input[start..]) for r in 0..8]` as one vector (wrapping int32 sums),
/// one macro per kernel level and input type: AVX2 alone, with the AVX-VNNI front (int8) or the
/// AVX-512 VNNI front. `input` ends where the columns end, `rows` are the whole rows. They expand
/// in place in the layer loops of `x86::layer`, inside functions with the level's target
/// features: as functions, LLVM kept them out of line, one call per block of eight rows with
/// the row slices passed through memory.
macro_rules! sums_i8_avx2 {
    ($rows:expr, $input:expr, $start:expr) => {
        finish_row_sums!(
            $rows,
            $input,
            [core::arch::x86_64::_mm256_setzero_si256(); $crate::kernels::x86::BLOCK_ROWS],
            $start
        )
    };
}

/// [`sums_i8_avx2`] with the AVX-VNNI front.
macro_rules! sums_i8_vnni {
    ($rows:expr, $input:expr, $start:expr) => {{
        let (acc, done) = $crate::kernels::x86::vnni::front_i8_avx($rows, $input, $start);
        finish_row_sums!($rows, $input, acc, done)
    }};
}

/// [`sums_i8_avx2`] with the AVX-512 VNNI front.
macro_rules! sums_i8_512 {
    ($rows:expr, $input:expr, $start:expr) => {{
        let (acc, done) = $crate::kernels::x86::vnni::front_i8_512($rows, $input, $start);
        finish_row_sums!($rows, $input, acc, done)
    }};
}

/// [`sums_i8_avx2`] for an int16 input (its codes loaded as they are).
macro_rules! sums_i16_avx2 {
    ($rows:expr, $input:expr, $start:expr) => {
        finish_row_sums!(
            $rows,
            $input,
            [core::arch::x86_64::_mm256_setzero_si256(); $crate::kernels::x86::BLOCK_ROWS],
            $start,
            $crate::kernels::x86::matvec::load_halves,
            $crate::kernels::x86::matvec::load_halves_half,
            $crate::kernels::dot::dot_i8_i16_prefix
        )
    };
}

/// [`sums_i16_avx2`] with the AVX-512 front.
macro_rules! sums_i16_512 {
    ($rows:expr, $input:expr, $start:expr) => {{
        let (acc, done) = $crate::kernels::x86::vnni::front_i16_512($rows, $input, $start);
        finish_row_sums!(
            $rows,
            $input,
            acc,
            done,
            $crate::kernels::x86::matvec::load_halves,
            $crate::kernels::x86::matvec::load_halves_half,
            $crate::kernels::dot::dot_i8_i16_prefix
        )
    }};
}

pub(super) use {
    finish_row_sums, sums_i16_512, sums_i16_avx2, sums_i8_512, sums_i8_avx2, sums_i8_vnni,
};

/// The eight rows of `rows` (`columns` weights each; missing rows are empty), cut one after
/// the other (no division).
#[inline]
pub(super) fn split_rows(rows: &[i8], columns: usize) -> [&[i8]; BLOCK_ROWS] {
    let mut rest = rows;
    let mut next = || {
        let (row, tail) = rest.split_at_checked(columns).unwrap_or((&[], &[]));
        rest = tail;
        row
    };
    [
        next(),
        next(),
        next(),
        next(),
        next(),
        next(),
        next(),
        next(),
    ]
}

/// Loads 8 int8 values and sign-extends them to 8 int16 lanes.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn widen_half(block: &[i8; HALF]) -> __m128i {
    // SAFETY: the pointer comes from a `&[i8; 8]`: `loadl` reads exactly 8 initialized bytes and
    // has no alignment requirement.
    let bytes = unsafe { _mm_loadl_epi64(block.as_ptr().cast::<__m128i>()) };
    _mm_cvtepi8_epi16(bytes)
}

/// Loads 16 int8 values and sign-extends them to 16 int16 lanes.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn widen(block: &[i8; COLUMNS]) -> __m256i {
    // SAFETY: the pointer comes from a `&[i8; 16]`: 16 initialized, readable bytes; `loadu`
    // has no alignment requirement.
    let bytes = unsafe { _mm_loadu_si128(block.as_ptr().cast::<__m128i>()) };
    _mm256_cvtepi8_epi16(bytes)
}

/// Loads 16 int16 values.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn load_halves(block: &[i16; COLUMNS]) -> __m256i {
    // SAFETY: the pointer comes from a `&[i16; 16]`: 32 initialized, readable bytes; `loadu` has
    // no alignment requirement.
    unsafe { _mm256_loadu_si256(block.as_ptr().cast::<__m256i>()) }
}

/// Loads 8 int16 values.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn load_halves_half(block: &[i16; HALF]) -> __m128i {
    // SAFETY: the pointer comes from a `&[i16; 8]`: 16 initialized, readable bytes; `loadu` has
    // no alignment requirement.
    unsafe { _mm_loadu_si128(block.as_ptr().cast::<__m128i>()) }
}

#[cfg(test)]
mod tests;
