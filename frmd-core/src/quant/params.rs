//! Scales and zero points: activation parameters from calibration ranges, symmetric per-channel
//! weights, int32 bias, requantization multipliers, and quantize/dequantize of single values.

use super::{quantize_multiplier, QuantError};

/// Smallest int8 weight value (symmetric quantization never uses -128).
pub const WEIGHT_MIN: i8 = -127;
/// Largest int8 weight value.
pub const WEIGHT_MAX: i8 = 127;

const ACTIVATION_QMIN: i32 = -128;
const ACTIVATION_QMAX: i32 = 127;

/// Affine int8 quantization of a tensor: `real = scale * (q - zero_point)`.
///
/// Invariants when built by [`QuantParams::from_range`] or [`QuantParams::new`]: `scale` is finite
/// and positive, `zero_point` is in `[-128, 127]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QuantParams {
    /// Real units per quantization step.
    pub scale: f32,
    /// The int8 code that represents real 0.
    pub zero_point: i32,
}

impl QuantParams {
    /// Checked constructor.
    pub fn new(scale: f32, zero_point: i32) -> Result<Self, QuantError> {
        let params = Self { scale, zero_point };
        params.validate()?;
        Ok(params)
    }

    /// Checks the invariants (finite positive scale, zero point in `[-128, 127]`).
    pub fn validate(&self) -> Result<(), QuantError> {
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return Err(QuantError::InvalidScale);
        }
        if !(ACTIVATION_QMIN..=ACTIVATION_QMAX).contains(&self.zero_point) {
            return Err(QuantError::InvalidZeroPoint);
        }
        Ok(())
    }

    /// Asymmetric int8 parameters covering the real range `[min, max]` (TFLite
    /// `ChooseQuantizationParams`).
    ///
    /// The range is first widened to contain 0 (`min' = min(min, 0)`, `max' = max(max, 0)`).
    /// `scale = (max' - min') / 255` (computed in f64, stored as f32). The zero point is taken from
    /// whichever end gives the smaller error, `qmin - min'/scale` or `qmax - max'/scale` (f64 scale,
    /// as TFLite), rounded half away from zero and clamped to `[-128, 127]`; so real 0 maps exactly
    /// to `zero_point`. A range that is all zero gives `scale = 1, zero_point = 0`.
    pub fn from_range(min: f32, max: f32) -> Result<Self, QuantError> {
        if !(min.is_finite() && max.is_finite()) {
            return Err(QuantError::NonFiniteRange);
        }
        if min > max {
            return Err(QuantError::InvertedRange);
        }
        let real_min = f64::from(min.min(0.0));
        let real_max = f64::from(max.max(0.0));
        if real_max == real_min {
            return Self::new(1.0, 0);
        }
        let qmin = f64::from(ACTIVATION_QMIN);
        let qmax = f64::from(ACTIVATION_QMAX);
        let scale_wide = (real_max - real_min) / (qmax - qmin);
        let scale = scale_wide as f32;
        if !(scale.is_finite() && scale > 0.0) {
            return Err(QuantError::InvalidScale);
        }
        let zero_point_from_min = qmin - real_min / scale_wide;
        let zero_point_from_max = qmax - real_max / scale_wide;
        let error_from_min = qmin.abs() + (real_min / scale_wide).abs();
        let error_from_max = qmax.abs() + (real_max / scale_wide).abs();
        let zero_point_real = if error_from_min < error_from_max {
            zero_point_from_min
        } else {
            zero_point_from_max
        };
        let zero_point = libm::round(zero_point_real).clamp(qmin, qmax) as i32;
        Self::new(scale, zero_point)
    }

    /// Quantizes one value with these parameters; see [`quantize`].
    #[inline]
    pub fn quantize(&self, value: f32) -> i8 {
        quantize(value, *self)
    }

    /// Dequantizes one value with these parameters; see [`dequantize`].
    #[inline]
    pub fn dequantize(&self, code: i8) -> f32 {
        dequantize(code, *self)
    }
}

/// `clamp(round_half_away_from_zero(value / scale) + zero_point, -128, 127)`, division in f32
/// (TFLite reference `Quantize`). NaN maps to `zero_point`; infinities saturate.
#[inline]
pub fn quantize(value: f32, params: QuantParams) -> i8 {
    let code = round_to_i32(value / params.scale)
        .saturating_add(params.zero_point)
        .clamp(ACTIVATION_QMIN, ACTIVATION_QMAX);
    code as i8
}

/// `libm::roundf(value) as i32` (round half away from zero, saturating, NaN to 0) without
/// branches on the value, so that quantizing an observation costs the same instructions whatever
/// it is: `t = value as i32` truncates toward zero (saturating), and the fraction `value - t`
/// (exact: for `|value| < 2^23` it is the fractional part, above that 0 or beyond the saturated
/// range) moves `t` one step away from zero when it is at least one half.
#[inline]
pub fn round_to_i32(value: f32) -> i32 {
    let truncated = value as i32;
    let fraction = value - truncated as f32;
    truncated
        .saturating_add(i32::from(fraction >= 0.5))
        .saturating_sub(i32::from(fraction <= -0.5))
}

/// The 16-bit input plane (`model::mlp::InputPrecision::Int16`): the code of `value` on a grid
/// `2^FINE_INPUT_BITS` times finer than the int8 grid of `params`:
/// `clamp(round_half_away_from_zero(value / wide_scale) + wide_zero_point, -32768, 32767)` with
/// [`wide_scale`] and [`wide_zero_point`]. The codes span exactly the real range of the two-plane
/// input: from half an int8 step below the int8 range to half an int8 step (less one fine step)
/// above it. `scale / 2^8` is exact in f32 for every valid scale above `2^-118`.
#[inline]
pub fn quantize_i16(value: f32, params: QuantParams) -> i16 {
    let code = round_to_i32(value / wide_scale(params))
        .saturating_add(wide_zero_point(params))
        .clamp(i32::from(i16::MIN), i32::from(i16::MAX));
    code as i16
}

/// `wide_scale * (code - wide_zero_point)` in f32: the real value of a 16-bit input code.
#[inline]
pub fn dequantize_i16(code: i16, params: QuantParams) -> f32 {
    let steps = i32::from(code).saturating_sub(wide_zero_point(params));
    wide_scale(params) * steps as f32
}

/// Scale of the 16-bit input plane: `params.scale / 2^FINE_INPUT_BITS`.
#[inline]
pub fn wide_scale(params: QuantParams) -> f32 {
    params.scale / (1_u32 << FINE_INPUT_BITS) as f32
}

/// Zero point of the 16-bit input plane: `params.zero_point * 2^FINE_INPUT_BITS + 2^7`, which
/// centres the 65536 codes on the int8 range (`[-32640, 32640]` for valid int8 zero points).
#[inline]
pub fn wide_zero_point(params: QuantParams) -> i32 {
    params
        .zero_point
        .saturating_mul(1 << FINE_INPUT_BITS)
        .saturating_add(1 << (FINE_INPUT_BITS - 1))
}

/// Bits of precision the fine input plane of a two-plane input, and the 16-bit input plane, add
/// below the int8 grid: their scale is the input scale `/ 2^FINE_INPUT_BITS`.
pub const FINE_INPUT_BITS: u32 = 8;

/// Two-plane quantization of one f32 input (about 16-bit precision from two int8 codes):
/// `coarse = quantize(value, params)` (the ordinary int8 code), then the residual
/// `value - dequantize(coarse)` (f32) is quantized symmetrically with scale
/// `params.scale / 2^FINE_INPUT_BITS` into `fine` (saturating to `[-128, 127]`).
///
/// Inside the calibrated range the residual is at most half a coarse step, so `fine` lies in
/// `[-128, 128]` before saturation and `value` is represented to half a fine step (one fine step
/// where the residual is +128 fine steps and saturates to 127); outside the range both planes
/// saturate (the represented value then ends about half a coarse step beyond the range).
/// The scale division by a power of two is exact in f32 for every valid scale above `2^-118`.
#[inline]
pub fn quantize_two_plane(value: f32, params: QuantParams) -> (i8, i8) {
    let coarse = quantize(value, params);
    let residual = value - dequantize(coarse, params);
    let fine_params = QuantParams {
        scale: wide_scale(params),
        zero_point: 0,
    };
    (coarse, quantize(residual, fine_params))
}

/// The accumulator of both input planes at scale `input_scale * weight_scale / 2^FINE_INPUT_BITS`:
/// `coarse * 2^FINE_INPUT_BITS + fine` (exact in i64), saturated to i32. `coarse` is the layer's
/// accumulator of the coarse codes (bias included, at scale `input_scale * weight_scale`), `fine`
/// the bias-free dot product of the weights with the fine codes. The exporter checks that its
/// layers cannot reach the saturation.
#[inline]
pub fn combine_plane_accumulators(coarse: i32, fine: i32) -> i32 {
    let wide = i64::from(coarse) * (1_i64 << FINE_INPUT_BITS) + i64::from(fine);
    wide.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
}

/// `scale * (code - zero_point)` in f32 (the integer difference is exact).
#[inline]
pub fn dequantize(code: i8, params: QuantParams) -> f32 {
    let steps = i32::from(code).saturating_sub(params.zero_point);
    params.scale * steps as f32
}

/// Real value of an int32 accumulator whose scale is `input_scale * weight_scale` (the last layer's
/// raw output): `acc as f32 * scale` (the i32 -> f32 conversion rounds to nearest even).
#[inline]
pub fn dequantize_accumulator(acc: i32, scale: f32) -> f32 {
    acc as f32 * scale
}

/// Symmetric weight scale for a channel whose largest absolute weight is `max_abs`:
/// `max_abs / 127` in f32, or 1 for an all-zero channel (any positive scale represents it exactly).
pub fn symmetric_weight_scale(max_abs: f32) -> Result<f32, QuantError> {
    if !max_abs.is_finite() {
        return Err(QuantError::NonFiniteValue);
    }
    let max_abs = max_abs.abs();
    if max_abs == 0.0 {
        return Ok(1.0);
    }
    let scale = max_abs / f32::from(WEIGHT_MAX);
    if scale > 0.0 {
        Ok(scale)
    } else {
        // max_abs is so small that max_abs / 127 underflows to 0.
        Err(QuantError::InvalidScale)
    }
}

/// `clamp(round_half_away_from_zero(weight / scale), -127, 127)`, division in f32.
#[inline]
pub fn quantize_weight(weight: f32, scale: f32) -> i8 {
    let steps = libm::roundf(weight / scale) as i32;
    steps.clamp(i32::from(WEIGHT_MIN), i32::from(WEIGHT_MAX)) as i8
}

/// Symmetric per-output-channel quantization of a row-major `[out, in]` weight matrix, where
/// `out = scales.len()` and `in = in_features`. Writes the int8 weights into `quantized` (same
/// shape) and each row's scale ([`symmetric_weight_scale`]) into `scales`.
pub fn quantize_weights_per_channel(
    weights: &[f32],
    in_features: usize,
    quantized: &mut [i8],
    scales: &mut [f32],
) -> Result<(), QuantError> {
    let expected = scales
        .len()
        .checked_mul(in_features)
        .ok_or(QuantError::LengthMismatch)?;
    if in_features == 0 || weights.len() != expected || quantized.len() != expected {
        return Err(QuantError::LengthMismatch);
    }
    let rows = weights
        .chunks_exact(in_features)
        .zip(quantized.chunks_exact_mut(in_features))
        .zip(scales.iter_mut());
    for ((row, row_q), scale_out) in rows {
        if row.iter().any(|w| !w.is_finite()) {
            return Err(QuantError::NonFiniteValue);
        }
        let max_abs = row.iter().fold(0.0_f32, |acc, w| acc.max(w.abs()));
        let scale = symmetric_weight_scale(max_abs)?;
        for (w, q) in row.iter().zip(row_q.iter_mut()) {
            *q = quantize_weight(*w, scale);
        }
        *scale_out = scale;
    }
    Ok(())
}

/// int32 bias with scale `input_scale * weight_scale`:
/// `round_half_away_from_zero(bias / (input_scale * weight_scale))`, computed in f64.
pub fn quantize_bias(bias: f32, input_scale: f32, weight_scale: f32) -> Result<i32, QuantError> {
    let limits = (f64::from(i32::MIN), f64::from(i32::MAX));
    Ok(bias_steps(bias, input_scale, weight_scale, limits)? as i32)
}

/// `round_half_away_from_zero(bias / (input_scale * weight_scale))` in f64, checked to lie in
/// `limits` (both ends exact in f64): the rounding of every bias width.
pub(crate) fn bias_steps(
    bias: f32,
    input_scale: f32,
    weight_scale: f32,
    limits: (f64, f64),
) -> Result<f64, QuantError> {
    if !bias.is_finite() {
        return Err(QuantError::NonFiniteValue);
    }
    let bias_scale = f64::from(input_scale) * f64::from(weight_scale);
    if !(bias_scale.is_finite() && bias_scale > 0.0) {
        return Err(QuantError::InvalidScale);
    }
    let steps = libm::round(f64::from(bias) / bias_scale);
    if !(limits.0..=limits.1).contains(&steps) {
        return Err(QuantError::BiasOverflow);
    }
    Ok(steps)
}

/// Folds the input zero point into a quantized bias: `bias_q - input_zero_point * sum(weight_row)`,
/// so that `bias' + sum(w * x_q) = bias_q + sum(w * (x_q - input_zero_point))`.
pub fn fold_input_zero_point(
    bias_q: i32,
    weight_row: &[i8],
    input_zero_point: i32,
) -> Result<i32, QuantError> {
    let weight_sum: i64 = weight_row.iter().map(|w| i64::from(*w)).sum();
    let folded = i64::from(input_zero_point)
        .checked_mul(weight_sum)
        .and_then(|offset| i64::from(bias_q).checked_sub(offset))
        .ok_or(QuantError::BiasOverflow)?;
    i32::try_from(folded).map_err(|_| QuantError::BiasOverflow)
}

/// Q31 multiplier and shift for one output channel: real multiplier
/// `input_scale * weight_scale / output_scale` (f64), then [`quantize_multiplier`].
pub fn requantization_multiplier(
    input_scale: f32,
    weight_scale: f32,
    output_scale: f32,
) -> Result<(i32, i32), QuantError> {
    let scales = [input_scale, weight_scale, output_scale];
    if scales.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return Err(QuantError::InvalidScale);
    }
    let real = f64::from(input_scale) * f64::from(weight_scale) / f64::from(output_scale);
    quantize_multiplier(real)
}
