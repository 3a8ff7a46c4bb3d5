//! Whole-layer loops of the x86 kernels: one call per layer walks every block of eight rows with
//! one kernel level's row sums (`x86::matvec`), adds the bias and stores, requantizes
//! (`x86::requant`, `x86::wide`) or maps through the table in registers, so that nothing crosses
//! a function boundary per block. The loops are written once ([`level_loops!`]) and stamped for
//! each level with its target features: AVX2, AVX2 with the AVX-VNNI front, AVX-512 VNNI. The
//! last `out_features % 8` rows are the callers' (portable kernels).
#![allow(unsafe_code)]

use super::matvec::{
    finish_row_sums, split_rows, sums_i16_512, sums_i16_avx2, sums_i8_512, sums_i8_avx2,
    sums_i8_vnni,
};
use super::requant::{load_i32, pack_i8, requantize_lanes, RequantBlock};
use super::wide::{finish_wide, load_i64x4, pack_i16, RequantBlock16};
use super::{Avx2, BLOCK_ROWS};
use crate::kernels::lut16::Lut16Table;
use crate::kernels::{FcRequant, FullyConnected, LayerInput};
use crate::quant::CHUNK16;
use core::arch::x86_64::{
    __m256i, _mm256_add_epi32, _mm256_add_epi64, _mm256_castsi256_si128, _mm256_cvtepi32_epi64,
    _mm256_extracti128_si256, _mm256_setzero_si256, _mm256_storeu_si256,
};

/// Stores eight int32 lanes.
#[inline]
#[target_feature(enable = "avx2")]
fn store_i32(out: &mut [i32; BLOCK_ROWS], lanes: __m256i) {
    // SAFETY: the pointer comes from a `&mut [i32; 8]`: 32 writable bytes; no alignment needed.
    unsafe { _mm256_storeu_si256(out.as_mut_ptr().cast::<__m256i>(), lanes) };
}

/// Stores four int64 lanes.
#[inline]
#[target_feature(enable = "avx2")]
fn store_i64(out: &mut [i64; 4], lanes: __m256i) {
    // SAFETY: the pointer comes from a `&mut [i64; 4]`: 32 writable bytes; no alignment needed.
    unsafe { _mm256_storeu_si256(out.as_mut_ptr().cast::<__m256i>(), lanes) };
}

/// The blocks of eight rows of `fc` (weights, bias) zipped with the blocks of `out`.
#[inline(always)]
fn blocks<'f, 'o, A, O>(
    fc: &FullyConnected<'f, A>,
    out: &'o mut [O],
) -> impl Iterator<Item = ((&'o mut [O; BLOCK_ROWS], &'f [i8]), &'f [A; BLOCK_ROWS])> {
    let block_len = fc.in_features.saturating_mul(BLOCK_ROWS).max(1);
    out.as_chunks_mut::<BLOCK_ROWS>()
        .0
        .iter_mut()
        .zip(fc.weights.chunks_exact(block_len))
        .zip(fc.bias.as_chunks::<BLOCK_ROWS>().0)
}

/// The loops of one level: `$sums8!(rows, input, start)` and `$sums16!(rows, input, start)` (macros
/// of `x86::matvec`) are its eight-row sums of an int8 and an int16 input from column `start` on.
macro_rules! level_loops {
    ($level:ident, $features:literal, $sums8:ident, $sums16:ident) => {
        mod $level {
            use super::*;

            /// Calls `$body` with `$sums` bound to a closure giving the eight rows' int32 sums
            /// of `input` (whole rows), once per input type, so that each expansion of the
            /// layer loop inlines one row kernel (matching per block kept it out of line).
            macro_rules! with_row_sums {
                ($input:expr, |$sums:ident| $body:expr) => {
                    match $input {
                        LayerInput::Int8(x) => {
                            let $sums = |rows: [&[i8]; BLOCK_ROWS]| $sums8!(rows, x, 0);
                            $body
                        }
                        LayerInput::Int16(x) => {
                            let $sums = |rows: [&[i8]; BLOCK_ROWS]| $sums16!(rows, x, 0);
                            $body
                        }
                    }
                };
            }

            /// The eight rows' int64 accumulators: `bias` plus the sign-extended int32 sums of
            /// every 512-column chunk, as rows 0..4 and 4..8.
            #[inline]
            #[target_feature(enable = $features)]
            fn wide(
                rows: [&[i8]; BLOCK_ROWS],
                input: LayerInput<'_>,
                bias: &[i64; BLOCK_ROWS],
            ) -> (__m256i, __m256i) {
                let (halves, _) = bias.as_chunks::<4>();
                let (mut low, mut high) = match halves {
                    [first, second] => (load_i64x4(first), load_i64x4(second)),
                    _ => (_mm256_setzero_si256(), _mm256_setzero_si256()),
                };
                let (width, mut start) = (input.len(), 0);
                while start < width {
                    let end = start.saturating_add(CHUNK16).min(width);
                    let sums = match input {
                        LayerInput::Int8(x) => {
                            sums_i8_avx2!(rows, x.get(..end).unwrap_or(&[]), start)
                        }
                        LayerInput::Int16(x) => {
                            $sums16!(rows, x.get(..end).unwrap_or(&[]), start)
                        }
                    };
                    let (lo, hi) = (
                        _mm256_castsi256_si128(sums),
                        _mm256_extracti128_si256::<1>(sums),
                    );
                    low = _mm256_add_epi64(low, _mm256_cvtepi32_epi64(lo));
                    high = _mm256_add_epi64(high, _mm256_cvtepi32_epi64(hi));
                    start = end;
                }
                (low, high)
            }

            /// `out[o] = bias[o] + dot(row o, input)` (or the bare dot without `with_bias`).
            #[target_feature(enable = $features)]
            pub(super) fn accumulate(
                fc: &FullyConnected<'_, i32>,
                input: LayerInput<'_>,
                with_bias: bool,
                out: &mut [i32],
            ) {
                let width = fc.in_features;
                with_row_sums!(input, |sums| {
                    for ((out, rows), bias) in blocks(fc, out) {
                        let sums = sums(split_rows(rows, width));
                        let sums = if with_bias {
                            _mm256_add_epi32(sums, load_i32(bias))
                        } else {
                            sums
                        };
                        store_i32(out, sums);
                    }
                })
            }

            /// `out[o] = requantize_to_i8(bias[o] + dot(row o, input), ...)`.
            #[target_feature(enable = $features)]
            pub(super) fn requantize(
                fc: &FullyConnected<'_, i32>,
                requant: &FcRequant<'_, i8>,
                input: LayerInput<'_>,
                out: &mut [i8],
            ) {
                let width = fc.in_features;
                let (multipliers, _) = requant.multipliers.as_chunks::<BLOCK_ROWS>();
                let (shifts, _) = requant.shifts.as_chunks::<BLOCK_ROWS>();
                let channels = blocks(fc, out).zip(multipliers.iter().zip(shifts));
                with_row_sums!(input, |sums| {
                    for (((out, rows), bias), (multipliers, shifts)) in channels {
                        let sums = sums(split_rows(rows, width));
                        let block = RequantBlock {
                            multipliers,
                            shifts,
                            zero_point: requant.output_zero_point,
                            bounds: (requant.activation_min, requant.activation_max),
                        };
                        let acc = _mm256_add_epi32(sums, load_i32(bias));
                        *out = pack_i8(requantize_lanes(acc, block));
                    }
                })
            }

            /// The int64 accumulators of every row.
            #[target_feature(enable = $features)]
            pub(super) fn accumulate_wide(
                fc: &FullyConnected<'_, i64>,
                input: LayerInput<'_>,
                out: &mut [i64],
            ) {
                let width = fc.in_features;
                for ((out, rows), bias) in blocks(fc, out) {
                    let (low, high) = wide(split_rows(rows, width), input, bias);
                    if let [first, second] = out.as_chunks_mut::<4>().0 {
                        store_i64(first, low);
                        store_i64(second, high);
                    }
                }
            }

            /// `out[o] = table(requantize_s64(acc_o, ...))` of the int64 accumulators.
            #[target_feature(enable = $features)]
            pub(super) fn requantize_wide(
                fc: &FullyConnected<'_, i64>,
                requant: &FcRequant<'_, i16>,
                table: Option<&Lut16Table>,
                input: LayerInput<'_>,
                out: &mut [i16],
            ) {
                let width = fc.in_features;
                let (multipliers, _) = requant.multipliers.as_chunks::<BLOCK_ROWS>();
                let (shifts, _) = requant.shifts.as_chunks::<BLOCK_ROWS>();
                let channels = blocks(fc, out).zip(multipliers.iter().zip(shifts));
                for (((out, rows), bias), (multipliers, shifts)) in channels {
                    let (low, high) = wide(split_rows(rows, width), input, bias);
                    let block = RequantBlock16 {
                        multipliers,
                        shifts,
                        bounds: (requant.activation_min, requant.activation_max),
                    };
                    *out = pack_i16(finish_wide(low, high, block, table));
                }
            }
        }
    };
}

level_loops!(plain, "avx2", sums_i8_avx2, sums_i16_avx2);
level_loops!(dot_avx, "avx2,avxvnni", sums_i8_vnni, sums_i16_avx2);
level_loops!(
    dot_512,
    "avx2,avx512f,avx512bw,avx512vnni",
    sums_i8_512,
    sums_i16_512
);

/// Calls `$call` in the module of the token's level (the unsafe call of a target-feature
/// function: the token's flags were set only after detecting the features, see `x86`).
macro_rules! by_level {
    ($token:expr, $name:ident($($arg:expr),*)) => {
        // SAFETY: an `Avx2` token exists only after `avx2_active()` detected AVX2; its `avx512`
        // and `vnni` flags only after `avx512_active()` / `avx_vnni_active()` detected those.
        // AVX-VNNI first: faster than the 512-bit level where a CPU has both (see `Avx2`).
        unsafe {
            if $token.vnni() {
                dot_avx::$name($($arg),*)
            } else if $token.avx512() {
                dot_512::$name($($arg),*)
            } else {
                plain::$name($($arg),*)
            }
        }
    };
}

impl Avx2 {
    /// `out[o] = bias[o] + dot(row o, input)` (wrapping; the bare dot unless `with_bias`) for the
    /// rows of every whole block of eight; the last `out.len() % 8` entries are left alone.
    /// Callers checked the shapes.
    pub(crate) fn accumulate_blocks(
        self,
        fc: &FullyConnected<'_, i32>,
        input: LayerInput<'_>,
        with_bias: bool,
        out: &mut [i32],
    ) {
        by_level!(self, accumulate(fc, input, with_bias, out))
    }

    /// The requantized int8 outputs of the whole blocks of eight rows (`requant` passed
    /// `FcRequant::validate`); the last `out.len() % 8` are left alone.
    pub(crate) fn requantize_blocks(
        self,
        fc: &FullyConnected<'_, i32>,
        requant: &FcRequant<'_, i8>,
        input: LayerInput<'_>,
        out: &mut [i8],
    ) {
        by_level!(self, requantize(fc, requant, input, out))
    }

    /// The int64 accumulators of the whole blocks of eight rows.
    pub(crate) fn accumulate_blocks_wide(
        self,
        fc: &FullyConnected<'_, i64>,
        input: LayerInput<'_>,
        out: &mut [i64],
    ) {
        by_level!(self, accumulate_wide(fc, input, out))
    }

    /// The int16 outputs (requantized, then `table`) of the whole blocks of eight rows.
    pub(crate) fn requantize_blocks_wide(
        self,
        fc: &FullyConnected<'_, i64>,
        requant: &FcRequant<'_, i16>,
        table: Option<&Lut16Table>,
        input: LayerInput<'_>,
        out: &mut [i16],
    ) {
        by_level!(self, requantize_wide(fc, requant, table, input, out))
    }
}
