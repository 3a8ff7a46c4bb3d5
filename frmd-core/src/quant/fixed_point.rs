//! Fixed-point requantization: the integer arithmetic that turns an int32 accumulator into an
//! int8 activation, bit for bit as the TFLite int8 reference kernels and CMSIS-NN do it.
//!
//! A real multiplier `m > 0` is stored as a Q31 mantissa `M` in `[2^30, 2^31 - 1]` and a power-of-two
//! exponent `shift`, so that `m ~= M * 2^(shift - 31)`. Applying it to an accumulator `acc` is done
//! in two roundings (the TFLite "double rounding" convention, which CMSIS-NN reproduces):
//!
//! 1. `x = sat32(acc * 2^max(shift, 0))` (left shift, saturated to i32);
//! 2. `h = round_half_up(x * M / 2^31)` — [`saturating_rounding_doubling_high_mul`];
//! 3. `r = round_half_away_from_zero(h / 2^max(-shift, 0))` — [`rounding_divide_by_pot`].
//!
//! Every function here is total: any `i32` input gives a defined result without panicking, and the
//! results for in-range inputs (shift in `-31..=30`, positive multiplier) equal TFLite's.

use super::QuantError;

/// Smallest Q31 mantissa produced by [`quantize_multiplier`] for a non-zero multiplier (`2^30`).
pub const Q31_MANTISSA_MIN: i32 = 1 << 30;
/// Smallest shift [`quantize_multiplier`] produces (multipliers down to `2^-32`).
pub const SHIFT_MIN: i32 = -31;
/// Largest shift [`quantize_multiplier`] produces (multipliers below `2^30`).
pub const SHIFT_MAX: i32 = 30;

/// Splits a real multiplier into a Q31 mantissa and a shift (TFLite `QuantizeMultiplier`).
///
/// `real = q * 2^shift` with `q` in `[0.5, 1)` (`frexp`); the mantissa is
/// `round_half_away_from_zero(q * 2^31)`; when that rounds up to `2^31` it is renormalized to
/// `2^30` and `shift` incremented. The result satisfies
/// `|mantissa * 2^(shift - 31) - real| <= 2^-32 * 2^shift <= 2^-31 * real`.
///
/// Returns `(mantissa, shift)` with mantissa in `[2^30, 2^31 - 1]` and shift in
/// `SHIFT_MIN..=SHIFT_MAX`; a positive shift means a left shift (TFLite/CMSIS-NN convention).
/// Representable: `2^-32 <= real < 2^30 - 1/4`. Errors: NaN/infinite, zero or negative, below
/// `2^-32` after rounding (underflow; TFLite would silently return a zero multiplier), and
/// `2^30 - 1/4` or above (overflow: the mantissa rounds to `2^31` and would need shift 31).
pub fn quantize_multiplier(real: f64) -> Result<(i32, i32), QuantError> {
    if !real.is_finite() {
        return Err(QuantError::NonFiniteMultiplier);
    }
    if real <= 0.0 {
        return Err(QuantError::NonPositiveMultiplier);
    }
    let (fraction, mut shift) = libm::frexp(real);
    // fraction in [0.5, 1): the product is exact (power-of-two scaling) and lies in [2^30, 2^31].
    let mut mantissa = libm::round(fraction * 2_147_483_648.0) as i64;
    if mantissa == 1_i64 << 31 {
        mantissa /= 2;
        shift += 1;
    }
    if shift < SHIFT_MIN {
        return Err(QuantError::MultiplierUnderflow);
    }
    if shift > SHIFT_MAX {
        return Err(QuantError::MultiplierOverflow);
    }
    i32::try_from(mantissa)
        .map(|m| (m, shift))
        .map_err(|_| QuantError::MultiplierOverflow)
}

/// `round_half_up(a * b / 2^31)`, saturating the single overflowing case
/// `a = b = i32::MIN` to `i32::MAX` (gemmlowp `SaturatingRoundingDoublingHighMul`).
///
/// Computed as gemmlowp does: `(a*b + nudge) / 2^31` with truncating division and
/// `nudge = 2^30` for a non-negative product, `1 - 2^30` otherwise. That is exactly
/// `floor((a*b + 2^30) / 2^31)`: round to nearest, ties towards +infinity (`-0.5 -> 0`, `0.5 -> 1`).
#[inline]
pub fn saturating_rounding_doubling_high_mul(a: i32, b: i32) -> i32 {
    if a == i32::MIN && b == i32::MIN {
        return i32::MAX;
    }
    let product = i64::from(a) * i64::from(b);
    let nudge: i64 = if product >= 0 { 1 << 30 } else { 1 - (1 << 30) };
    // |product| <= 2^62 - 2^31 here, so the sum does not overflow and the quotient fits i32.
    let high = (product + nudge) / (1_i64 << 31);
    high as i32
}

/// `round_half_away_from_zero(x / 2^exponent)` (gemmlowp `RoundingDivideByPOT`).
///
/// For `exponent` in `0..=31` this is gemmlowp's mask/threshold form:
/// `(x >> e) + (remainder > threshold)`, with `remainder = x & (2^e - 1)` and
/// `threshold = (2^e - 1) >> 1` plus one for negative `x`. Ties go away from zero
/// (`2.5 -> 3`, `-2.5 -> -3`). A negative exponent is treated as 0 (no division); exponents
/// of 32 and more give the mathematically rounded quotient (0, or -1 for `i32::MIN / 2^32`).
#[inline]
pub fn rounding_divide_by_pot(x: i32, exponent: i32) -> i32 {
    if exponent <= 0 {
        return x;
    }
    if exponent >= 32 {
        // |x| / 2^exponent <= 1/2, with equality only for x = i32::MIN and exponent 32.
        return if exponent == 32 && x == i32::MIN {
            -1
        } else {
            0
        };
    }
    let mask = ((1_u32 << exponent) - 1) as i32;
    let remainder = x & mask;
    let threshold = (mask >> 1) + i32::from(x < 0);
    (x >> exponent) + i32::from(remainder > threshold)
}

/// Applies a quantized multiplier (TFLite `MultiplyByQuantizedMultiplier`, CMSIS-NN
/// `arm_nn_requantize` without single rounding).
///
/// `shift > 0` shifts left before the high multiply, `shift < 0` divides by `2^-shift` after it:
/// `rounding_divide_by_pot(srdhm(sat32(acc << max(shift, 0)), multiplier), max(-shift, 0))`.
///
/// The left shift saturates to the i32 range. TFLite and CMSIS-NN leave that overflow undefined or
/// wrapping; for every input where they do not overflow the results are identical, and saturating
/// keeps the final int8 clamp correct where they would wrap.
#[inline]
pub fn multiply_by_quantized_multiplier(acc: i32, multiplier: i32, shift: i32) -> i32 {
    let left = shift.clamp(0, 31) as u32;
    let right = if shift < 0 { shift.saturating_neg() } else { 0 };
    let shifted = saturate_to_i32(i64::from(acc) << left);
    rounding_divide_by_pot(
        saturating_rounding_doubling_high_mul(shifted, multiplier),
        right,
    )
}

/// Requantizes one int32 accumulator to int8: multiply by the quantized multiplier, add the output
/// zero point, clamp to `[activation_min, activation_max]`.
///
/// `clamp(multiply_by_quantized_multiplier(acc, multiplier, shift) + output_zero_point,
/// activation_min, activation_max)`; the addition saturates, which equals the exact sum after the
/// clamp. If `activation_min > activation_max` the result is `activation_max` (callers validate the
/// range; see `kernels::FcRequant::validate`).
#[inline]
pub fn requantize_to_i8(
    acc: i32,
    multiplier: i32,
    shift: i32,
    output_zero_point: i32,
    activation_min: i8,
    activation_max: i8,
) -> i8 {
    let scaled = if (SHIFT_MIN..=0).contains(&shift) && multiplier != i32::MIN {
        scale_down(acc, multiplier, shift.unsigned_abs())
    } else {
        multiply_by_quantized_multiplier(acc, multiplier, shift)
    };
    offset_and_clamp(scaled, output_zero_point, activation_min, activation_max)
}

/// `clamp(scaled + zero_point, lo, hi)`; the addition saturates, which equals the exact sum after
/// the clamp. The bounds are i8 values, so the conversion is exact.
#[inline(always)]
fn offset_and_clamp(scaled: i32, zero_point: i32, lo: i8, hi: i8) -> i8 {
    scaled
        .saturating_add(zero_point)
        .max(i32::from(lo))
        .min(i32::from(hi)) as i8
}

/// [`requantize_to_i8`] for parameters that passed `kernels::FcRequant::validate` (multiplier
/// non-negative, shift in `SHIFT_MIN..=SHIFT_MAX`), with one branch on the shift's sign instead
/// of the full range check; equal to [`requantize_to_i8`] there, defined (never a panic) anywhere.
#[inline(always)]
pub fn requantize_valid(
    acc: i32,
    multiplier: i32,
    shift: i32,
    output_zero_point: i32,
    activation_min: i8,
    activation_max: i8,
) -> i8 {
    let scaled = if shift <= 0 {
        scale_down(acc, multiplier, shift.unsigned_abs())
    } else {
        multiply_by_quantized_multiplier(acc, multiplier, shift)
    };
    offset_and_clamp(scaled, output_zero_point, activation_min, activation_max)
}

#[inline]
fn saturate_to_i32(value: i64) -> i32 {
    value.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
}

/// [`multiply_by_quantized_multiplier`] for `shift = -exponent` with `exponent` in `0..=31` and
/// `multiplier != i32::MIN` (every layer whose real multiplier is below 1), without branches:
/// the high multiply is `floor((acc * multiplier + 2^30) / 2^31)` (one 64-bit product; its only
/// saturating case needs `multiplier == i32::MIN`), and the rounding division of `x` by
/// `2^exponent`, half away from zero, is the half-up division of `y = x - [x < 0]`:
/// `floor(y / 2^e + 1/2) = (y >> e) + bit_{e-1}(y)` for `e >= 1` (`y = x` for `e = 0`).
/// `x >= 1 - 2^31`, so `y` does not overflow.
#[inline(always)]
pub(crate) fn scale_down(acc: i32, multiplier: i32, exponent: u32) -> i32 {
    let exponent = exponent & 31;
    let product = i64::from(acc) * i64::from(multiplier);
    let high = ((product + (1_i64 << 30)) >> 31) as i32;
    let divides = 0_i32.wrapping_sub(i32::from(exponent != 0));
    let y = high.wrapping_add((high >> 31) & divides);
    (y >> exponent).wrapping_add((y.wrapping_shl(1) >> exponent) & 1)
}
