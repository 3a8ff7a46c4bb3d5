//! AVX2 kernels of the int16-activation layers (the 16x8 scheme) for x86-64: eight output
//! channels per call, accumulated in int64, requantized to int16 and (optionally) mapped through
//! the interpolated table, all in registers. The portable kernels (`kernels::rows`,
//! `quant::requantize_s64`, `kernels::lut16::lookup`) are the definition; the tests compare.
//!
//! 1. Accumulation (`x86::layer`): for each 512-column chunk, the eight-row sums of the token's
//!    level (`x86::matvec`: 25 AVX2 instructions per 128 MACs for int16 inputs as for int8, or
//!    the AVX-512 `vpdpwssd` front) give eight int32 chunk sums; they are sign-extended
//!    (`vpmovsxdq`) and added to two vectors of four int64 lanes that start at the bias.
//! 2. Requantization, per 64-bit lane, the steps of `quant::requantize_s64`:
//!    `m15 = clamp((M >> 16) + bit15(M), 0, 0x7FFF)` (int32 lanes);
//!    `p = acc * m15` as `lo32(acc) * m15 + (hi32(acc) * m15) << 32` (`vpmuludq`, `vpmuldq`;
//!    modulo 2^64 like `wrapping_mul`); the arithmetic shift by `(14 - shift) mod 64`, which AVX2
//!    lacks, as `((p ^ s) >>> n) ^ s` with `s` the sign mask (`vpsrlvq`); saturation to int32
//!    (`vpcmpgtq`, `vpblendvb`); then in eight int32 lanes `(s >> 1) + (s & 1)` and the clamp.
//! 3. Table: `i = ((y >> 7) + 256) & 511`, one `vpgatherdd` (scale 2) reads the 32-bit pair
//!    `(t[i], t[i+1])` for every lane, `vpmaddwd` with `(f << 16) | (128 - f)` gives
//!    `t[i] (128 - f) + t[i+1] f`, then `+ 64` and `>> 7`: `lut16::lookup` exactly.
#![allow(unsafe_code)]

use super::requant::load_i32;
use super::BLOCK_ROWS;
use super::{for_each_tail_row, Avx2};
use crate::kernels::lut16::{self, Lut16Table};
use crate::kernels::rows::for_each_accumulator;
use crate::kernels::{FcRequant, FullyConnected, LayerInput};
use crate::quant::requantize_s64;
use core::arch::x86_64::{
    __m128i, __m256i, _mm256_add_epi32, _mm256_add_epi64, _mm256_and_si256, _mm256_blendv_epi8,
    _mm256_castsi256_si128, _mm256_cmpgt_epi64, _mm256_cvtepu32_epi64, _mm256_extracti128_si256,
    _mm256_i32gather_epi32, _mm256_loadu_si256, _mm256_madd_epi16, _mm256_max_epi32,
    _mm256_min_epi32, _mm256_mul_epi32, _mm256_mul_epu32, _mm256_or_si256,
    _mm256_permute2x128_si256, _mm256_permutevar8x32_epi32, _mm256_set1_epi32, _mm256_set1_epi64x,
    _mm256_setr_epi32, _mm256_setzero_si256, _mm256_slli_epi32, _mm256_slli_epi64,
    _mm256_srai_epi32, _mm256_srli_epi32, _mm256_srli_epi64, _mm256_srlv_epi64, _mm256_sub_epi32,
    _mm256_xor_si256, _mm_packs_epi32, _mm_storeu_si128,
};

/// Requantization parameters of eight int16 output channels (as in `kernels::FcRequant<i16>`,
/// which validates them).
#[derive(Clone, Copy, Debug)]
pub(crate) struct RequantBlock16<'a> {
    /// Q31 multiplier mantissas (reduced to Q15 here).
    pub multipliers: &'a [i32; BLOCK_ROWS],
    /// Shifts, positive to the left.
    pub shifts: &'a [i32; BLOCK_ROWS],
    /// Activation clamp `(min, max)`.
    pub bounds: (i16, i16),
}

impl FullyConnected<'_, i64> {
    /// `FullyConnected::forward_validated` for int16 outputs with the x86 kernels (callers
    /// checked every length): the whole blocks of eight channels by `x86::layer`, the last
    /// `out_features % 8` by the portable accumulation and `requantize_s64`. Same outputs as the
    /// portable loop.
    pub(crate) fn forward_avx2_wide(
        &self,
        avx2: Avx2,
        requant: &FcRequant<'_, i16>,
        table: Option<&Lut16Table>,
        input: LayerInput<'_>,
        output: &mut [i16],
    ) {
        avx2.requantize_blocks_wide(self, requant, table, input, output);
        let bounds = (requant.activation_min, requant.activation_max);
        for_each_tail_row(
            self,
            requant,
            output,
            |(out, row, bias, multiplier, shift)| {
                let mut acc = 0_i64;
                let bias = core::slice::from_ref(bias);
                match input {
                    LayerInput::Int8(values) => {
                        for_each_accumulator(values, row, bias, |sum| acc = sum)
                    }
                    LayerInput::Int16(values) => {
                        for_each_accumulator(values, row, bias, |sum| acc = sum)
                    }
                }
                let y = requantize_s64(acc, multiplier, shift, bounds.0, bounds.1);
                *out = match table {
                    Some(table) => lut16::lookup(table, y),
                    None => y,
                };
            },
        );
    }
}

#[cfg(test)]
impl Avx2 {
    /// (Tests) the eight accumulators' int64 sums as the kernel forms them (`rows` holds eight
    /// rows of `input.len()` weights).
    pub(crate) fn accumulate_rows_wide(
        self,
        rows: &[i8],
        input: LayerInput<'_>,
        bias: &[i64; BLOCK_ROWS],
    ) -> [i64; BLOCK_ROWS] {
        let layer = FullyConnected::new(input.len(), BLOCK_ROWS, rows, bias);
        let mut out = [0_i64; BLOCK_ROWS];
        self.accumulate_blocks_wide(&layer, input, &mut out);
        out
    }

    /// (Tests) requantization and table of eight given accumulators, in registers.
    pub(crate) fn requantize_wide(
        self,
        acc: &[i64; BLOCK_ROWS],
        requant: RequantBlock16<'_>,
        table: Option<&Lut16Table>,
    ) -> [i16; BLOCK_ROWS] {
        // SAFETY: an `Avx2` token exists only after `avx2_active()` returned true.
        unsafe { requantize_loaded(acc, requant, table) }
    }
}

#[cfg(test)]
#[target_feature(enable = "avx2")]
fn requantize_loaded(
    acc: &[i64; BLOCK_ROWS],
    requant: RequantBlock16<'_>,
    table: Option<&Lut16Table>,
) -> [i16; BLOCK_ROWS] {
    let (halves, _) = acc.as_chunks::<4>();
    let (low, high) = match halves {
        [first, second] => (load_i64x4(first), load_i64x4(second)),
        _ => (_mm256_setzero_si256(), _mm256_setzero_si256()),
    };
    pack_i16(finish_wide(low, high, requant, table))
}

/// Requantization, clamp and table of the eight lanes `low` (rows 0..4), `high` (rows 4..8):
/// eight int32 lanes holding int16 values.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn finish_wide(
    low: __m256i,
    high: __m256i,
    requant: RequantBlock16<'_>,
    table: Option<&Lut16Table>,
) -> __m256i {
    let y = requantize_lanes_s64(low, high, requant);
    match table {
        Some(table) => interpolate(y, table),
        None => y,
    }
}

/// `requantize_s64` of eight int64 lanes (see the module documentation), as eight int32 lanes.
#[inline]
#[target_feature(enable = "avx2")]
fn requantize_lanes_s64(low: __m256i, high: __m256i, requant: RequantBlock16<'_>) -> __m256i {
    let multiplier = load_i32(requant.multipliers);
    let shift = load_i32(requant.shifts);
    let zero = _mm256_setzero_si256();
    let one = _mm256_set1_epi32(1);
    let rounding_bit = _mm256_and_si256(_mm256_srli_epi32::<15>(multiplier), one);
    let m15 = _mm256_min_epi32(
        _mm256_max_epi32(
            _mm256_add_epi32(_mm256_srai_epi32::<16>(multiplier), rounding_bit),
            zero,
        ),
        _mm256_set1_epi32(0x7FFF),
    );
    let amount = _mm256_and_si256(
        _mm256_sub_epi32(_mm256_set1_epi32(14), shift),
        _mm256_set1_epi32(63),
    );
    let q_low = scaled_lanes(
        low,
        _mm256_cvtepu32_epi64(_mm256_castsi256_si128(m15)),
        _mm256_cvtepu32_epi64(_mm256_castsi256_si128(amount)),
    );
    let q_high = scaled_lanes(
        high,
        _mm256_cvtepu32_epi64(_mm256_extracti128_si256::<1>(m15)),
        _mm256_cvtepu32_epi64(_mm256_extracti128_si256::<1>(amount)),
    );
    // The low dwords of the eight lanes, in order.
    let even = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
    let s = _mm256_permute2x128_si256::<0x20>(
        _mm256_permutevar8x32_epi32(q_low, even),
        _mm256_permutevar8x32_epi32(q_high, even),
    );
    let rounded = _mm256_add_epi32(_mm256_srai_epi32::<1>(s), _mm256_and_si256(s, one));
    let (lo, hi) = requant.bounds;
    _mm256_min_epi32(
        _mm256_max_epi32(rounded, _mm256_set1_epi32(i32::from(lo))),
        _mm256_set1_epi32(i32::from(hi)),
    )
}

/// `sat32((acc * m15) >> amount)` of four int64 lanes (`m15`, `amount` in the low dwords).
#[inline]
#[target_feature(enable = "avx2")]
fn scaled_lanes(acc: __m256i, m15: __m256i, amount: __m256i) -> __m256i {
    let low = _mm256_mul_epu32(acc, m15);
    let high = _mm256_slli_epi64::<32>(_mm256_mul_epi32(_mm256_srli_epi64::<32>(acc), m15));
    let product = _mm256_add_epi64(low, high);
    let sign = _mm256_cmpgt_epi64(_mm256_setzero_si256(), product);
    let shifted = _mm256_xor_si256(
        _mm256_srlv_epi64(_mm256_xor_si256(product, sign), amount),
        sign,
    );
    let max = _mm256_set1_epi64x(i64::from(i32::MAX));
    let min = _mm256_set1_epi64x(i64::from(i32::MIN));
    let shifted = _mm256_blendv_epi8(shifted, max, _mm256_cmpgt_epi64(shifted, max));
    _mm256_blendv_epi8(shifted, min, _mm256_cmpgt_epi64(min, shifted))
}

/// `lut16::lookup(table, y)` of eight int32 lanes holding int16 codes.
#[inline]
#[target_feature(enable = "avx2")]
fn interpolate(y: __m256i, table: &Lut16Table) -> __m256i {
    let index = _mm256_and_si256(
        _mm256_add_epi32(_mm256_srai_epi32::<7>(y), _mm256_set1_epi32(256)),
        _mm256_set1_epi32(511),
    );
    let fraction = _mm256_and_si256(y, _mm256_set1_epi32(127));
    // SAFETY: every index is in 0..=511 (masked above), so each lane reads the 4 bytes at byte
    // offset `2 index <= 1022` of the table, `t[index]` and `t[index + 1]`, which end at byte
    // 1026 at most: inside the 513-entry (1026-byte) `&[i16; 513]`. The gather needs no alignment.
    let pairs = unsafe { _mm256_i32gather_epi32::<2>(table.as_ptr().cast::<i32>(), index) };
    let weights = _mm256_or_si256(
        _mm256_slli_epi32::<16>(fraction),
        _mm256_sub_epi32(_mm256_set1_epi32(128), fraction),
    );
    _mm256_srai_epi32::<7>(_mm256_add_epi32(
        _mm256_madd_epi16(pairs, weights),
        _mm256_set1_epi32(64),
    ))
}

/// Eight int32 lanes holding int16 values as int16 (the saturating pack is exact).
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn pack_i16(lanes: __m256i) -> [i16; BLOCK_ROWS] {
    let packed = _mm_packs_epi32(
        _mm256_castsi256_si128(lanes),
        _mm256_extracti128_si256::<1>(lanes),
    );
    let mut out = [0_i16; BLOCK_ROWS];
    // SAFETY: the pointer comes from a `&mut [i16; 8]`: 16 writable bytes; no alignment needed.
    unsafe { _mm_storeu_si128(out.as_mut_ptr().cast::<__m128i>(), packed) };
    out
}

/// Loads four int64 lanes.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn load_i64x4(values: &[i64; 4]) -> __m256i {
    // SAFETY: the pointer comes from a `&[i64; 4]`: 32 initialized, readable bytes; `loadu` has
    // no alignment requirement.
    unsafe { _mm256_loadu_si256(values.as_ptr().cast::<__m256i>()) }
}

#[cfg(test)]
mod tests;
