//! Quantization: the single definition of every rounding step between real numbers and the int8
//! firmware, shared by the runtime (frmd-core) and the exporter (frmd-export).
//!
//! Conventions follow the TFLite int8 specification, which CMSIS-NN matches bit for bit:
//! - activations: int8 asymmetric per tensor, `real = scale * (q - zero_point)`, with `q` in
//!   `[-128, 127]` and the real range widened to contain 0 so that 0 is exactly representable;
//! - weights: int8 symmetric per output channel, `real = scale[c] * q`, `q` in `[-127, 127]`;
//! - bias: int32 with scale `input_scale * weight_scale[c]`, the input zero point folded in
//!   (`bias_q - input_zero_point * sum(w_q)`), so the kernels never see the input zero point;
//! - requantization: `fixed_point` (Q31 multiplier and shift, TFLite double rounding).
//!
//! The 16x8 scheme (int16 symmetric activations, int8 weights, int64 bias; TFLite / CMSIS-NN
//! `s16`) adds [`requantize_s64`] (Q15 multiplier, one rounding), [`dequantize_wide`],
//! [`quantize_sym16`] and the int64 bias helpers ([`quantize_bias_i64`]).
//!
//! Rounding modes, stated once:
//! - float -> integer ([`quantize`], weights, bias, multiplier mantissas): round half away from
//!   zero (`libm::roundf` / `libm::round`, C `round`, as TFLite's `TfLiteRound`);
//! - high multiply: round half up; divide by a power of two: round half away from zero.

mod fixed_point;
mod int16;
mod params;

pub use fixed_point::{
    multiply_by_quantized_multiplier, quantize_multiplier, requantize_to_i8, requantize_valid,
    rounding_divide_by_pot, saturating_rounding_doubling_high_mul, Q31_MANTISSA_MIN, SHIFT_MAX,
    SHIFT_MIN,
};
pub use int16::{
    dequantize_sym16, dequantize_wide, fold_input_zero_point_i64, quantize_bias_i64,
    quantize_sym16, reduce_multiplier, requantize_s64, symmetric_i16_scale, BIAS16_MAX, CHUNK16,
    IN_FEATURES16_MAX, SHIFT16_MAX, SHIFT16_MIN,
};
pub use params::{
    combine_plane_accumulators, dequantize, dequantize_accumulator, dequantize_i16,
    fold_input_zero_point, quantize, quantize_bias, quantize_i16, quantize_two_plane,
    quantize_weight, quantize_weights_per_channel, requantization_multiplier, round_to_i32,
    symmetric_weight_scale, wide_scale, wide_zero_point, QuantParams, FINE_INPUT_BITS, WEIGHT_MAX,
    WEIGHT_MIN,
};

#[cfg(test)]
mod int16_tests;
#[cfg(any(test, feature = "reference"))]
pub mod reference;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod two_plane_tests;
#[cfg(test)]
mod wide_input_tests;

/// Why a quantization parameter cannot be computed. Small and `Copy`; each variant names the
/// offending quantity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum QuantError {
    /// A real multiplier is NaN or infinite.
    NonFiniteMultiplier,
    /// A real multiplier is zero or negative (multipliers are ratios of positive scales).
    NonPositiveMultiplier,
    /// A real multiplier is below `2^-32` (would need a shift below [`SHIFT_MIN`]).
    MultiplierUnderflow,
    /// A real multiplier is `2^30` or more, or so close below that its mantissa rounds up to it
    /// (would need a shift above [`SHIFT_MAX`]).
    MultiplierOverflow,
    /// A calibration range bound is NaN or infinite.
    NonFiniteRange,
    /// A calibration range has `min > max`.
    InvertedRange,
    /// A scale is NaN, infinite, zero or negative.
    InvalidScale,
    /// A zero point lies outside `[-128, 127]`.
    InvalidZeroPoint,
    /// A weight, bias or function value to quantize is NaN or infinite.
    NonFiniteValue,
    /// Slice lengths disagree with the stated shape.
    LengthMismatch,
    /// A quantized bias (or bias with the folded zero point) does not fit in i32 (int8 layers),
    /// or exceeds `BIAS16_MAX` in magnitude (int16-activation layers).
    BiasOverflow,
}

impl core::fmt::Display for QuantError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let text = match self {
            Self::NonFiniteMultiplier => "requantization multiplier is not finite",
            Self::NonPositiveMultiplier => "requantization multiplier is not positive",
            Self::MultiplierUnderflow => "requantization multiplier is below 2^-32",
            Self::MultiplierOverflow => "requantization multiplier is 2^30 or larger",
            Self::NonFiniteRange => "calibration range bound is not finite",
            Self::InvertedRange => "calibration range has min > max",
            Self::InvalidScale => "quantization scale is not a finite positive number",
            Self::InvalidZeroPoint => "zero point is outside [-128, 127]",
            Self::NonFiniteValue => "value to quantize is not finite",
            Self::LengthMismatch => "slice length does not match the shape",
            Self::BiasOverflow => "quantized bias does not fit its accumulator",
        };
        f.write_str(text)
    }
}

/// No variant wraps another error.
impl core::error::Error for QuantError {}
