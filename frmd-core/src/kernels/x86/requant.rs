//! AVX2 requantization of eight int32 accumulators to int8: the same integer steps as
//! [`crate::quant::requantize_to_i8`] (see `quant::fixed_point` for the definitions), one lane
//! per output channel: about 40 instructions per eight outputs instead of about 70 per output.
//! `x86::matvec` applies it to the accumulators of eight rows while they are still in registers.
//!
//! Per lane, with `left = max(shift, 0)` and `right = max(-shift, 0)`:
//! 1. `x = sat32(acc << left)`: `vpsllvd`, with the lanes where `acc` exceeds `i32::MAX >> left`
//!    (or is below `i32::MIN >> left`) replaced by `i32::MAX` (`i32::MIN`);
//! 2. `h = floor((x * multiplier + 2^30) / 2^31)`: `vpmuldq` on the even and (shifted) odd
//!    lanes gives the exact 64-bit products; bits 31..62 of `product + 2^30` are the result
//!    (`vpsrlq 31` for even lanes, `vpsllq 1` for odd ones, then one blend); the one overflowing
//!    case `x = multiplier = i32::MIN` is set to `i32::MAX` as the scalar code does;
//! 3. `r = round_half_away_from_zero(h / 2^right)`: the mask/threshold form
//!    `(h >> right) + (h & mask > (mask >> 1) + (h < 0))` with `mask = 2^right - 1`
//!    (`vpsllvd`, `vpsravd`); `right = 0` gives `mask = 0` and `r = h`;
//! 4. `clamp(r + zero_point, min, max)` with the saturating add done as `clamp(r, -256, 256) +
//!    zero_point`: the zero point lies in `[-128, 127]` and the bounds are int8, so both give the
//!    same clamped value.
//!
//! Preconditions (checked by `FcRequant::validate` before any call): shifts in
//! `SHIFT_MIN..=SHIFT_MAX` (so `left <= 30`, `right <= 31`), zero point in `[-128, 127]`.
#![allow(unsafe_code)]

#[cfg(test)]
use super::Avx2;
use super::BLOCK_ROWS;
use core::arch::x86_64::{
    __m256i, _mm256_add_epi32, _mm256_add_epi64, _mm256_and_si256, _mm256_blend_epi32,
    _mm256_blendv_epi8, _mm256_castsi256_si128, _mm256_cmpeq_epi32, _mm256_cmpgt_epi32,
    _mm256_extracti128_si256, _mm256_loadu_si256, _mm256_max_epi32, _mm256_min_epi32,
    _mm256_mul_epi32, _mm256_packs_epi16, _mm256_packs_epi32, _mm256_set1_epi32,
    _mm256_set1_epi64x, _mm256_setzero_si256, _mm256_slli_epi64, _mm256_sllv_epi32,
    _mm256_srai_epi32, _mm256_srav_epi32, _mm256_srli_epi64, _mm256_sub_epi32, _mm_cvtsi128_si32,
};

/// Loads eight int32 lanes.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn load_i32(values: &[i32; BLOCK_ROWS]) -> __m256i {
    // SAFETY: the pointer comes from a `&[i32; 8]`: 32 initialized, readable bytes; `loadu` has no
    // alignment requirement.
    unsafe { _mm256_loadu_si256(values.as_ptr().cast::<__m256i>()) }
}

/// Requantization parameters of eight output channels (as in `kernels::FcRequant`, which
/// validates them: shifts in `SHIFT_MIN..=SHIFT_MAX`, zero point in `[-128, 127]`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct RequantBlock<'a> {
    /// Q31 multiplier mantissas.
    pub multipliers: &'a [i32; BLOCK_ROWS],
    /// Shifts, positive to the left.
    pub shifts: &'a [i32; BLOCK_ROWS],
    /// Output zero point.
    pub zero_point: i32,
    /// Activation clamp `(min, max)`.
    pub bounds: (i8, i8),
}

#[cfg(test)]
impl Avx2 {
    /// (Tests) `requantize_to_i8(acc[i], multipliers[i], shifts[i], zero_point, min, max)` for eight
    /// lanes at once.
    #[inline]
    pub(crate) fn requantize_accumulators(
        self,
        acc: &[i32; BLOCK_ROWS],
        requant: RequantBlock<'_>,
    ) -> [i8; BLOCK_ROWS] {
        // SAFETY: an `Avx2` token exists only after `avx2_active()` returned true.
        unsafe { requantize_loaded(acc, requant) }
    }
}

#[cfg(test)]
#[target_feature(enable = "avx2")]
fn requantize_loaded(acc: &[i32; BLOCK_ROWS], requant: RequantBlock<'_>) -> [i8; BLOCK_ROWS] {
    pack_i8(requantize_lanes(load_i32(acc), requant))
}

/// The eight requantized lanes (each in `[min, max]`) of the accumulators `acc`.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn requantize_lanes(acc: __m256i, requant: RequantBlock<'_>) -> __m256i {
    let multiplier = load_i32(requant.multipliers);
    let shift = load_i32(requant.shifts);
    let (min, max) = requant.bounds;
    let zero_point = requant.zero_point;
    let zero = _mm256_setzero_si256();
    let left = _mm256_max_epi32(shift, zero);
    let right = _mm256_max_epi32(_mm256_sub_epi32(zero, shift), zero);

    // 1. Saturating left shift.
    let int_max = _mm256_set1_epi32(i32::MAX);
    let int_min = _mm256_set1_epi32(i32::MIN);
    let too_high = _mm256_cmpgt_epi32(acc, _mm256_srav_epi32(int_max, left));
    let too_low = _mm256_cmpgt_epi32(_mm256_srav_epi32(int_min, left), acc);
    let shifted = _mm256_sllv_epi32(acc, left);
    let shifted = _mm256_blendv_epi8(shifted, int_max, too_high);
    let shifted = _mm256_blendv_epi8(shifted, int_min, too_low);

    // 2. Rounding doubling high multiply.
    let nudge = _mm256_set1_epi64x(1 << 30);
    let even = _mm256_add_epi64(_mm256_mul_epi32(shifted, multiplier), nudge);
    let odd = _mm256_add_epi64(
        _mm256_mul_epi32(
            _mm256_srli_epi64::<32>(shifted),
            _mm256_srli_epi64::<32>(multiplier),
        ),
        nudge,
    );
    let high = _mm256_blend_epi32::<0b1010_1010>(
        _mm256_srli_epi64::<31>(even),
        _mm256_slli_epi64::<1>(odd),
    );
    let both_min = _mm256_and_si256(
        _mm256_cmpeq_epi32(shifted, int_min),
        _mm256_cmpeq_epi32(multiplier, int_min),
    );
    let high = _mm256_blendv_epi8(high, int_max, both_min);

    // 3. Rounding divide by 2^right, ties away from zero.
    let one = _mm256_set1_epi32(1);
    let mask = _mm256_sub_epi32(_mm256_sllv_epi32(one, right), one);
    let remainder = _mm256_and_si256(high, mask);
    // `_mm256_cmpgt_epi32(zero, high)` is -1 for negative lanes: subtracting it adds one.
    let threshold = _mm256_sub_epi32(_mm256_srai_epi32::<1>(mask), _mm256_cmpgt_epi32(zero, high));
    let rounded = _mm256_sub_epi32(
        _mm256_srav_epi32(high, right),
        _mm256_cmpgt_epi32(remainder, threshold),
    );

    // 4. Zero point and activation clamp.
    let bounded = _mm256_min_epi32(
        _mm256_max_epi32(rounded, _mm256_set1_epi32(-256)),
        _mm256_set1_epi32(256),
    );
    let with_offset = _mm256_add_epi32(bounded, _mm256_set1_epi32(zero_point));
    _mm256_min_epi32(
        _mm256_max_epi32(with_offset, _mm256_set1_epi32(i32::from(min))),
        _mm256_set1_epi32(i32::from(max)),
    )
}

/// Packs eight lanes holding int8 values into bytes (lane order kept).
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn pack_i8(lanes: __m256i) -> [i8; BLOCK_ROWS] {
    // The lanes are int8 values already, so the saturating packs are exact; after both packs each
    // 128-bit half starts with its four lanes as bytes.
    let words = _mm256_packs_epi32(lanes, lanes);
    let bytes = _mm256_packs_epi16(words, words);
    let low = _mm_cvtsi128_si32(_mm256_castsi256_si128(bytes)).to_le_bytes();
    let high = _mm_cvtsi128_si32(_mm256_extracti128_si256::<1>(bytes)).to_le_bytes();
    let [b0, b1, b2, b3] = low.map(|b| b as i8);
    let [b4, b5, b6, b7] = high.map(|b| b as i8);
    [b0, b1, b2, b3, b4, b5, b6, b7]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quant::requantize_to_i8;
    use crate::quant::{SHIFT_MAX, SHIFT_MIN};
    use crate::rng::SplitMix64;

    const EDGES: [i32; 12] = [
        i32::MIN,
        i32::MIN + 1,
        -(1 << 30),
        -65_536,
        -1,
        0,
        1,
        2,
        65_535,
        1 << 30,
        i32::MAX - 1,
        i32::MAX,
    ];

    fn scalar(acc: &[i32; 8], m: &[i32; 8], s: &[i32; 8], zp: i32, (lo, hi): (i8, i8)) -> [i8; 8] {
        core::array::from_fn(|i| requantize_to_i8(acc[i], m[i], s[i], zp, lo, hi))
    }

    #[test]
    fn avx2_requantization_matches_scalar() {
        let Some(avx2) = Avx2::get() else {
            return;
        };
        let mut rng = SplitMix64::new(0x5EED);
        let span = (SHIFT_MAX - SHIFT_MIN + 1) as u64;
        let mut unclamped = 0_usize;
        for case in 0..200_000 {
            let mut pick = |edge_one_in: u64| {
                let bits = rng.next_u64();
                if bits.is_multiple_of(edge_one_in) {
                    EDGES[((bits >> 8) % EDGES.len() as u64) as usize]
                } else {
                    // Random magnitudes: shift a random word right by 0..31 bits.
                    (bits >> 32) as i32 >> ((bits >> 16) % 32)
                }
            };
            let acc: [i32; 8] = core::array::from_fn(|_| pick(8));
            // Negative multipliers (rejected by `FcRequant::validate`) in half the cases: the lanes
            // still equal the scalar function, which is total.
            let signed = case % 2 == 0;
            let multipliers: [i32; 8] =
                core::array::from_fn(|_| if signed { pick(16) } else { pick(16).max(0) });
            let shifts: [i32; 8] =
                core::array::from_fn(|_| SHIFT_MIN + (rng.next_u64() % span) as i32);
            let zero_point = (rng.next_u64() % 256) as i32 - 128;
            let bounds = if case % 3 == 0 {
                (zero_point as i8, 127)
            } else {
                let (a, b) = (rng.next_u64() as i8, rng.next_u64() as i8);
                (a.min(b), a.max(b))
            };
            let requant = RequantBlock {
                multipliers: &multipliers,
                shifts: &shifts,
                zero_point,
                bounds,
            };
            let got = avx2.requantize_accumulators(&acc, requant);
            let want = scalar(&acc, &multipliers, &shifts, zero_point, bounds);
            assert_eq!(
                got, want,
                "acc {acc:?} m {multipliers:?} s {shifts:?} zp {zero_point} {bounds:?}"
            );
            unclamped += want
                .iter()
                .filter(|v| **v != bounds.0 && **v != bounds.1)
                .count();
        }
        // The cases must exercise the rounding, not only the clamps.
        assert!(unclamped > 100_000, "{unclamped} unclamped outputs");
    }

    #[test]
    fn avx2_requantization_of_typical_layers_matches_scalar() {
        let Some(avx2) = Avx2::get() else {
            return;
        };
        // Multipliers from real-valued scales as the exporter makes them; accumulators of
        // 256-wide int8 layers; ties forced by small accumulators and large right shifts.
        let mut rng = SplitMix64::new(0xF00D);
        for _ in 0..50_000 {
            let scale: [(i32, i32); 8] = core::array::from_fn(|_| {
                let u = (rng.next_u64() >> 11) as f64 / (1_u64 << 53) as f64;
                crate::quant::quantize_multiplier(1e-5 * 1e5_f64.powf(u)).unwrap_or((1 << 30, 0))
            });
            let acc: [i32; 8] =
                core::array::from_fn(|_| ((rng.next_u64() >> 40) as i32) - (1 << 23));
            let multipliers = scale.map(|(m, _)| m);
            let shifts = scale.map(|(_, s)| s);
            let zero_point = (rng.next_u64() % 256) as i32 - 128;
            let requant = RequantBlock {
                multipliers: &multipliers,
                shifts: &shifts,
                zero_point,
                bounds: (-128, 127),
            };
            let got = avx2.requantize_accumulators(&acc, requant);
            assert_eq!(
                got,
                scalar(&acc, &multipliers, &shifts, zero_point, (-128, 127))
            );
        }
    }
}
