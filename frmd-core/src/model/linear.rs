//! The linear layer, the building block of both backbones, in its f32 and quantized forms.
//!
//! - [`F32Linear`]: `y = activation(W x + b)` in f32, the reference form.
//! - [`Int8Linear`]: int8 codes in, f32 out: int8 weights (symmetric per output channel), an int32
//!   bias with the input zero point folded in, int32 accumulators dequantized per channel with
//!   `output_scales[o] = input_scale * weight_scale[o]`.
//! - [`QuantizedLinear`]: f32 in, f32 out through the int8 form: the input is quantized per
//!   tensor with its own calibrated [`QuantParams`] (to int8, or symmetric int16), then
//!   [`Int8Linear`].
//! - [`RequantizedLinear`]: int8 codes in, int8 codes out, for a chain of int8 layers (the MLP's
//!   hidden layers, the transformer's feed-forward expansion): the accumulators are requantized
//!   per channel straight to the next layer's input parameters (dequantize and quantize fused) and
//!   an optional 256-entry table applies the activation.
//!
//! [`Int8Linear`], [`QuantizedLinear`] and [`RequantizedLinear`] are generic over the activation
//! [`Precision`] (int8
//! weights either way): with int16 activations (the 16x8 scheme) the bias and accumulators are
//! int64, the requantization is [`crate::quant::requantize_s64`] and the table an interpolated
//! [`crate::kernels::Lut16Table`]. The type parameters default to int8.
//!
//! Weights are row-major `[out_features, in_features]` (candle `Linear` layout) in every form.

use crate::kernels::{
    dequantize_accumulators, lut, Accumulator, Activation, FcRequant, FullyConnected, KernelError,
    LayerInput, Precision,
};
use crate::quant::{combine_plane_accumulators, requantize_to_i8, QuantParams};

/// The f32 form: `y = activation(W x + b)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct F32Linear<'a> {
    /// Input width.
    pub in_features: usize,
    /// Output width.
    pub out_features: usize,
    /// `[out_features, in_features]` row-major weights.
    pub weights: &'a [f32],
    /// `[out_features]` bias.
    pub bias: &'a [f32],
    /// Pointwise activation applied after the affine map.
    pub activation: Activation,
}

/// Output channels `start .. start + count` of row-major `[out, in]` weights and their bias.
fn row_range<'a, W, B>(
    weights: &'a [W],
    bias: &'a [B],
    in_features: usize,
    start: usize,
    count: usize,
) -> Result<(&'a [W], &'a [B]), KernelError> {
    let end = start.checked_add(count).ok_or(KernelError::WeightsLength)?;
    let rows = start
        .checked_mul(in_features)
        .zip(end.checked_mul(in_features))
        .and_then(|(from, to)| weights.get(from..to))
        .ok_or(KernelError::WeightsLength)?;
    let bias = bias.get(start..end).ok_or(KernelError::BiasLength)?;
    Ok((rows, bias))
}

impl<'a> F32Linear<'a> {
    /// Checks the weight and bias lengths against the shape.
    pub fn validate(&self) -> Result<(), KernelError> {
        let expected = self.out_features.checked_mul(self.in_features);
        if self.in_features == 0 || self.out_features == 0 || expected != Some(self.weights.len()) {
            return Err(KernelError::WeightsLength);
        }
        if self.bias.len() != self.out_features {
            return Err(KernelError::BiasLength);
        }
        Ok(())
    }

    /// `output = activation(W input + b)`. Dot products are summed sequentially in f32.
    pub fn forward(&self, input: &[f32], output: &mut [f32]) -> Result<(), KernelError> {
        self.affine(input, output)?;
        self.activation.apply_in_place(output);
        Ok(())
    }

    /// `output = W input + b` (the pre-activation; [`Self::forward`] applies the activation to
    /// it in place).
    pub fn affine(&self, input: &[f32], output: &mut [f32]) -> Result<(), KernelError> {
        self.validate()?;
        if input.len() != self.in_features {
            return Err(KernelError::InputLength);
        }
        if output.len() != self.out_features {
            return Err(KernelError::OutputLength);
        }
        let rows = self.weights.chunks_exact(self.in_features).zip(self.bias);
        for ((row, bias), out) in rows.zip(output.iter_mut()) {
            *out = row.iter().zip(input).fold(*bias, |acc, (w, x)| acc + w * x);
        }
        Ok(())
    }

    /// Output channels `start .. start + count` as a layer of their own (a head's slice of a
    /// fused query/key/value layer).
    pub fn rows(&self, start: usize, count: usize) -> Result<Self, KernelError> {
        let (weights, bias) = row_range(self.weights, self.bias, self.in_features, start, count)?;
        Ok(Self {
            in_features: self.in_features,
            out_features: count,
            weights,
            bias,
            activation: self.activation,
        })
    }
}

/// The int8-weight form with dequantized output: codes in, f32 out,
/// `output[o] = (bias[o] + w[o] . codes) * output_scales[o]`. `A` is the accumulator: `i32` for
/// int8 codes in (the default), `i64` for int16 activations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Int8Linear<'a, A: Accumulator = i32> {
    /// int8 weights `[out, in]` and bias at scale `input_scale * weight_scale[o]`, input zero
    /// point folded in.
    pub fc: FullyConnected<'a, A>,
    /// `[out]` dequantization scales `input_scale * weight_scale[o]`.
    pub output_scales: &'a [f32],
}

impl<'a, A: Accumulator> Int8Linear<'a, A> {
    /// Checks the weights, bias and scale lengths against the shape.
    pub fn validate(&self) -> Result<(), KernelError> {
        self.fc.validate()?;
        if self.output_scales.len() != self.fc.out_features {
            return Err(KernelError::ScaleLength);
        }
        Ok(())
    }

    /// Codes of either width to dequantized f32; `accumulators` and `output` are `out_features`
    /// long.
    pub fn forward_input(
        &self,
        input: LayerInput<'_>,
        accumulators: &mut [A],
        output: &mut [f32],
    ) -> Result<(), KernelError> {
        self.fc.accumulate(input, accumulators)?;
        dequantize_accumulators(accumulators, self.output_scales, output)
    }

    /// Output channels `start .. start + count` as a layer of their own.
    pub fn rows(&self, start: usize, count: usize) -> Result<Self, KernelError> {
        let fc = &self.fc;
        let (weights, bias) = row_range(fc.weights, fc.bias, fc.in_features, start, count)?;
        let end = start.checked_add(count).ok_or(KernelError::ScaleLength)?;
        let output_scales = self
            .output_scales
            .get(start..end)
            .ok_or(KernelError::ScaleLength)?;
        Ok(Self {
            fc: FullyConnected::new(fc.in_features, count, weights, bias),
            output_scales,
        })
    }
}

/// `codes[i] = P::quantize(values[i], params)` over the common length (asymmetric int8 or
/// symmetric int16, [`Precision::quantize`]).
pub fn quantize_into<P: Precision>(values: &[f32], params: QuantParams, codes: &mut [P]) {
    for (code, value) in codes.iter_mut().zip(values) {
        *code = P::quantize(*value, params);
    }
}

/// f32 in, f32 out through the quantized form: the input is quantized per tensor with `input`
/// to `P` codes (int8 asymmetric, the default, or int16 symmetric), then [`Int8Linear`] (whose
/// bias has `input.zero_point` folded in and whose scales are `input.scale * weight_scale[o]`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QuantizedLinear<'a, P: Precision = i8> {
    /// Quantization of the f32 input (calibrated at the layer's input; zero point 0 for int16).
    pub input: QuantParams,
    /// The int8-weight layer.
    pub linear: Int8Linear<'a, P::Acc>,
}

impl<P: Precision> QuantizedLinear<'_, P> {
    /// Quantizes `input` into `codes` (same length), then [`Int8Linear::forward_input`].
    pub fn forward(
        &self,
        input: &[f32],
        codes: &mut [P],
        accumulators: &mut [P::Acc],
        output: &mut [f32],
    ) -> Result<(), KernelError> {
        if codes.len() != input.len() {
            return Err(KernelError::InputLength);
        }
        quantize_into(input, self.input, codes);
        self.linear
            .forward_input(P::layer_input(codes), accumulators, output)
    }

    /// Output channels `start .. start + count` as a layer of their own (same input params).
    pub fn rows(&self, start: usize, count: usize) -> Result<Self, KernelError> {
        Ok(Self {
            input: self.input,
            linear: self.linear.rows(start, count)?,
        })
    }
}

/// The form with requantized output: codes in, `P` codes out,
/// `output[o] = activation(requantize(bias[o] + w[o] . codes))`; `P` is `i8` (the default) or
/// `i16` (int16 activations, int64 bias).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RequantizedLinear<'a, P: Precision = i8> {
    /// Weights and bias (input zero point folded).
    pub fc: FullyConnected<'a, P::Acc>,
    /// Per-channel requantization to the pre-activation (or, without a table, the output) params.
    pub requant: FcRequant<'a, P>,
    /// Activation table from pre-activation to output params; `None` for identity/clamp-only.
    pub activation: Option<&'a P::Table>,
}

impl<P: Precision> RequantizedLinear<'_, P> {
    /// The layer on `input`: fully connected, requantized, activation table applied, in one pass
    /// (`output` is `out_features` long).
    pub fn forward(&self, input: LayerInput<'_>, output: &mut [P]) -> Result<(), KernelError> {
        self.fc
            .forward_activated(&self.requant, self.activation, input, output)
    }

    /// [`Self::forward`] without repeating the per-channel checks of `requant`
    /// ([`FcRequant::validate`], O(out_features)), for a layer whose requantization was validated
    /// once, e.g. when a network was built; shapes are still checked. With parameters that would
    /// not validate the outputs are unspecified (never a panic).
    pub fn forward_prevalidated(
        &self,
        input: LayerInput<'_>,
        output: &mut [P],
    ) -> Result<(), KernelError> {
        self.fc
            .forward_validated(&self.requant, self.activation, input, output)
    }
}

impl RequantizedLinear<'_> {
    /// First-layer accumulators of a two-plane input (`model::mlp::InputPrecision::TwoPlane`):
    /// `acc[o] = combine_plane_accumulators(bias[o] + w[o] . coarse, w[o] . fine)`.
    /// `coarse` and `fine` are `in_features` long, `acc` is `out_features` long.
    pub fn two_plane_accumulators(
        &self,
        coarse: &[i8],
        fine: &[i8],
        acc: &mut [i32],
    ) -> Result<(), KernelError> {
        self.fc.forward_accumulators(coarse, acc)?;
        let mut slots = acc.iter_mut();
        self.fc.for_each_dot(fine, |dot| {
            if let Some(slot) = slots.next() {
                *slot = combine_plane_accumulators(*slot, dot);
            }
        })?;
        Ok(())
    }

    /// Requantizes accumulators (`out_features` long) with this layer's per-channel parameters
    /// into `output` and applies its table.
    pub fn requantize_and_activate(
        &self,
        acc: &[i32],
        output: &mut [i8],
    ) -> Result<(), KernelError> {
        let out = self.fc.out_features;
        self.requant.validate(out)?;
        if acc.len() != out || output.len() != out {
            return Err(KernelError::OutputLength);
        }
        let channels = self.requant.multipliers.iter().zip(self.requant.shifts);
        for ((slot, a), (multiplier, shift)) in output.iter_mut().zip(acc).zip(channels) {
            *slot = requantize_to_i8(
                *a,
                *multiplier,
                *shift,
                self.requant.output_zero_point,
                self.requant.activation_min,
                self.requant.activation_max,
            );
        }
        if let Some(table) = self.activation {
            lut::apply_in_place(table, output);
        }
        Ok(())
    }
}
