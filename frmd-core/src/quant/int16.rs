//! The arithmetic of the 16x8 scheme (TFLite int16 activations with int8 weights, what CMSIS-NN's
//! `s16` kernels implement): symmetric int16 activations, int8 per-channel weights (unchanged),
//! int64 bias and accumulators, and requantization of an int64 accumulator with a Q15 multiplier
//! and one rounding. The design and its deviations are in `/work/notes/int16-design.md`
//! sections 3.1-3.6 (and its "Implementation notes").
//!
//! - activations: `real = scale * q`, `q` in `[-32768, 32767]`, zero point 0
//!   ([`quantize_sym16`], [`dequantize_sym16`], [`symmetric_i16_scale`]);
//! - bias: int64 at scale `input_scale * weight_scale[c]` with the input zero point folded in
//!   (only the first layer's 16-bit observation plane has one), `|bias| <= 2^46`
//!   ([`quantize_bias_i64`], [`fold_input_zero_point_i64`], [`BIAS16_MAX`]);
//! - accumulation: `bias + sum over 512-column chunks of the chunk's int32 sum` (see
//!   `kernels::Accumulator`), exact for weights in `[-127, 127]` and inputs up to
//!   [`IN_FEATURES16_MAX`] wide;
//! - requantization: [`requantize_s64`] (TFLite's int64 `MultiplyByQuantizedMultiplier`, CMSIS-NN
//!   `arm_nn_requantize_s64` with `REDUCE_MULTIPLIER`);
//! - dequantization of an int64 accumulator to f32: [`dequantize_wide`].
//!
//! Every function is total (no panic on any input) and branch-free on the data.

use super::{round_to_i32, QuantError};

/// Smallest shift of an int16-output channel (the Q31 multipliers of `quantize_multiplier`).
pub const SHIFT16_MIN: i32 = -31;
/// Largest shift of an int16-output channel: real multipliers below `2^7`, so that the rounding
/// shift `15 - shift` of [`requantize_s64`] is at least 8 (TFLite's range for 16x8 layers).
pub const SHIFT16_MAX: i32 = 7;
/// Largest magnitude of an int64 bias (and of a first-layer bias variant): with inputs at most
/// [`IN_FEATURES16_MAX`] wide every accumulator then stays within `2^47`, TFLite's domain.
pub const BIAS16_MAX: i64 = 1 << 46;
/// Widest input of a layer with int64 accumulation (`2^24` columns: 32,768 chunks of at most
/// `2^31` each add at most `2^46` to the bias).
pub const IN_FEATURES16_MAX: usize = 1 << 24;
/// Columns per int32 partial sum of the int64 accumulation (`kernels::Accumulator::CHUNK` of
/// `i64`): `512 * 127 * 32768 = 2,130,706,432 < 2^31`, so a chunk's int32 sum is exact for
/// weights in `[-127, 127]` (the bound CMSIS-NN relies on, `MAX_COL_COUNT = 512`).
pub const CHUNK16: usize = 512;

/// The Q15 multiplier of a Q31 mantissa: `clamp((multiplier + 2^15) >> 16, 0, 2^15 - 1)`.
///
/// Equal to CMSIS-NN's `REDUCE_MULTIPLIER` (`x < 0x7FFF0000 ? (x + 2^15) >> 16 : 0x7FFF`) for
/// every non-negative `multiplier` (the cap replaces the one value, `2^15`, that would not fit);
/// negative multipliers (refused by `kernels::FcRequant::validate`) give 0. Computed as
/// `(multiplier >> 16) + bit 15 of multiplier`, which cannot overflow.
#[inline(always)]
pub fn reduce_multiplier(multiplier: i32) -> i32 {
    ((multiplier >> 16) + ((multiplier >> 15) & 1)).clamp(0, 0x7FFF)
}

/// Requantizes an int64 accumulator to int16 (zero point 0):
/// `clamp(round_half_up(acc * m15 / 2^(15 - shift)), lo, hi)` with
/// `m15 = reduce_multiplier(multiplier)` (TFLite's 64-bit `MultiplyByQuantizedMultiplier`).
///
/// For `|acc| <= 2^47` and `shift` in [`SHIFT16_MIN`]`..=`[`SHIFT16_MAX`] (what validated layers
/// guarantee) this is exactly the rounded product, one rounding, ties towards +infinity. It is
/// computed as CMSIS-NN does, `((acc * m15) >> (14 - shift)) + 1) >> 1`, except that the
/// intermediate is saturated to int32 (exact: any value it changes is clamped to the same int16
/// bound afterwards) instead of truncated:
///
/// 1. `p = acc * m15` (wrapping int64; exact in the domain, `|p| < 2^62`);
/// 2. `q = p >> ((14 - shift) mod 64)` (arithmetic);
/// 3. `s = sat32(q)`, `r = (s >> 1) + (s & 1)` (`= floor((s + 1) / 2)`, no overflow);
/// 4. `clamp(r, lo, hi)` as `min(max(r, lo), hi)` (so `lo > hi` gives `hi`).
///
/// Outside the domain every step is still defined (wrapping, shift amounts mod 64), identical
/// in the portable, AVX2 and Cortex-M kernels; it just stops being the rounded product.
#[inline(always)]
pub fn requantize_s64(acc: i64, multiplier: i32, shift: i32, lo: i16, hi: i16) -> i16 {
    let m15 = i64::from(reduce_multiplier(multiplier));
    let amount = (14_i32.wrapping_sub(shift) as u32) & 63;
    let q = acc.wrapping_mul(m15).wrapping_shr(amount);
    let s = saturate_i64_to_i32(q);
    let r = (s >> 1) + (s & 1);
    r.max(i32::from(lo)).min(i32::from(hi)) as i16
}

/// `q` saturated to the i32 range, as a comparison of the high word with the low word's sign
/// (a select, not a branch, on the cores that have one).
#[inline(always)]
fn saturate_i64_to_i32(q: i64) -> i32 {
    let low = q as i32;
    let fits = (q >> 32) as i32 == low >> 31;
    let saturated = ((q >> 63) as i32) ^ i32::MAX;
    if fits {
        low
    } else {
        saturated
    }
}

/// Real value of an int64 accumulator at scale `scale` (the int16 network's dequantized layers),
/// without an i64 -> f32 conversion (a library call on 32-bit cores whose cost may depend on the
/// value): `hi = (acc + 2^23) >> 24`, `lo = acc - hi 2^24` (in `[-2^23, 2^23)`), then
/// `(hi as f32) * (scale * 2^24) + (lo as f32) * scale` in f32, each operation rounded once (no
/// fused multiply-add), so every target gives the same bits.
///
/// `lo` is exact in f32, `hi` for `|acc| < 2^48` (beyond, it rounds; beyond `2^55` it wraps),
/// `scale * 2^24` is exact. Because `|lo| <= 2^23 <= |hi| 2^24 / 2`, the two products never
/// cancel (a floor split with `lo >= 0` would: `-3 = -2^24 + (2^24 - 3)` loses everything but the
/// rounding error of `lo * scale`), so the result is within about 2 ulp of `acc * scale`; for
/// `|acc| < 2^23` it is exactly `acc as f32 * scale`, the int32 path's value.
#[inline(always)]
pub fn dequantize_wide(acc: i64, scale: f32) -> f32 {
    let hi = acc.wrapping_add(1 << 23) >> 24;
    let lo = acc.wrapping_sub(hi << 24) as i32;
    (hi as i32 as f32) * (scale * 16_777_216.0) + (lo as f32) * scale
}

/// Symmetric int16 scale for a tensor whose largest magnitude is `max_abs`: `max_abs / 32767`
/// (f64, stored f32), or 1 for an all-zero tensor.
pub fn symmetric_i16_scale(max_abs: f32) -> Result<f32, QuantError> {
    if !max_abs.is_finite() {
        return Err(QuantError::NonFiniteRange);
    }
    let max_abs = max_abs.abs();
    if max_abs == 0.0 {
        return Ok(1.0);
    }
    let scale = (f64::from(max_abs) / f64::from(i16::MAX)) as f32;
    if scale.is_finite() && scale > 0.0 {
        Ok(scale)
    } else {
        Err(QuantError::InvalidScale)
    }
}

/// `clamp(round_half_away_from_zero(value / scale), -32768, 32767)`, division in f32 (as
/// [`super::quantize`] with zero point 0); NaN maps to 0, infinities saturate; branch-free.
#[inline]
pub fn quantize_sym16(value: f32, scale: f32) -> i16 {
    round_to_i32(value / scale).clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16
}

/// `scale * code` in f32.
#[inline]
pub fn dequantize_sym16(code: i16, scale: f32) -> f32 {
    scale * f32::from(code)
}

/// int64 bias at scale `input_scale * weight_scale`:
/// `round_half_away_from_zero(bias / (input_scale * weight_scale))` in f64, at most
/// [`BIAS16_MAX`] in magnitude.
pub fn quantize_bias_i64(
    bias: f32,
    input_scale: f32,
    weight_scale: f32,
) -> Result<i64, QuantError> {
    // 2^46 is exact in f64.
    let limit = BIAS16_MAX as f64;
    Ok(super::params::bias_steps(bias, input_scale, weight_scale, (-limit, limit))? as i64)
}

/// [`super::fold_input_zero_point`] for an int64 bias:
/// `bias_q - input_zero_point * sum(weight_row)`, at most [`BIAS16_MAX`] in magnitude.
pub fn fold_input_zero_point_i64(
    bias_q: i64,
    weight_row: &[i8],
    input_zero_point: i32,
) -> Result<i64, QuantError> {
    let weight_sum: i64 = weight_row.iter().map(|w| i64::from(*w)).sum();
    let folded = i64::from(input_zero_point)
        .checked_mul(weight_sum)
        .and_then(|offset| bias_q.checked_sub(offset))
        .ok_or(QuantError::BiasOverflow)?;
    if folded.unsigned_abs() > BIAS16_MAX.unsigned_abs() {
        return Err(QuantError::BiasOverflow);
    }
    Ok(folded)
}
