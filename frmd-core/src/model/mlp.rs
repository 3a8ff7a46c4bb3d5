//! MLP backbone: an int8 forward pass (fully connected layers with LUT activations, last layer
//! dequantized to f32) and an f32 reference forward pass through the same structure ([`F32Mlp`]).
//!
//! Int8 data flow for hidden layer `l` (all int8 tensors are asymmetric per tensor):
//! `x_l (int8) --FC + requant--> pre_l (int8, params of the pre-activation) --LUT--> x_{l+1}`;
//! a layer without LUT (ReLU via the clamp, or identity) outputs `x_{l+1}` directly. The f32 input
//! is quantized with [`Int8Mlp::input`]; the last layer's int32 accumulators are dequantized per
//! channel with `output_scales[o] = input_scale * weight_scale[o]`.
//!
//! With [`InputPrecision::TwoPlane`] the input gets about 16 bits instead of 8: each value becomes
//! a coarse int8 code and a fine int8 code of the residual at `1/2^FINE_INPUT_BITS` of the input
//! scale ([`quantize_two_plane`]); the first hidden layer runs its int8 kernel on both planes and
//! requantizes `coarse_acc * 2^8 + fine_dot` ([`combine_plane_accumulators`]), so its multipliers
//! are those of the input scale `input_scale / 2^FINE_INPUT_BITS`. Everything after the first
//! layer is unchanged. Cost: one more int8 matrix-vector product of the first layer.
//!
//! [`InputPrecision::Int16`] gives the same precision in one pass: each value becomes one 16-bit
//! code on the fine grid (`input_scale / 2^8`, zero point `input_zero_point * 2^8`,
//! [`quantize_i16`]) and the first layer multiplies int8 weights by int16 codes (on Arm DSP cores
//! `SMLAD` takes the 16-bit codes as they are). Its bias is at the fine scale and its multipliers
//! are made for the fine scale, as for two planes.
//!
//! Scratch memory is caller-owned and sized by a const generic `WIDTH` that must be at least the
//! widest layer (input, hidden and output widths); nothing is allocated.

use crate::kernels::{
    dequantize_accumulators, FcRequant, FullyConnected, KernelError, LayerInput, Lut8,
};
use crate::quant::{
    combine_plane_accumulators, quantize_i16, quantize_two_plane, requantize_to_i8, QuantParams,
};

mod float;

pub use float::{F32Layer, F32Mlp, F32Scratch, Probe};

/// Why a forward pass refused its arguments.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelError {
    /// A kernel refused a layer's arguments (names the slice).
    Kernel(KernelError),
    /// Layer `index` (0-based, the output layer last) does not take the previous layer's width.
    LayerWidth {
        /// Index of the offending layer.
        index: usize,
    },
    /// A layer is wider than the scratch buffers' `WIDTH`.
    ScratchTooSmall,
    /// The input slice length differs from the first layer's input width.
    InputLength,
    /// The output slice length differs from the last layer's output width.
    OutputLength,
    /// The input quantization parameters are invalid.
    InputParams,
    /// [`InputPrecision::TwoPlane`] and [`InputPrecision::Int16`] need a hidden first layer (the
    /// output layer's accumulators are dequantized at the int8 input scale).
    TwoPlaneWithoutHiddenLayer,
}

impl From<KernelError> for ModelError {
    fn from(error: KernelError) -> Self {
        Self::Kernel(error)
    }
}

impl core::fmt::Display for ModelError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Kernel(e) => write!(f, "kernel error: {e}"),
            Self::LayerWidth { index } => {
                write!(
                    f,
                    "layer {index} input width differs from the previous output width"
                )
            }
            Self::ScratchTooSmall => f.write_str("a layer is wider than the scratch buffers"),
            Self::InputLength => f.write_str("input length differs from the first layer's width"),
            Self::OutputLength => f.write_str("output length differs from the last layer's width"),
            Self::InputParams => f.write_str("input quantization parameters are invalid"),
            Self::TwoPlaneWithoutHiddenLayer => {
                f.write_str("two-plane or 16-bit input quantization needs a hidden first layer")
            }
        }
    }
}

/// One int8 hidden layer: fully connected, requantized, then an optional LUT activation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Int8Layer<'a> {
    /// Weights and bias (input zero point folded).
    pub fc: FullyConnected<'a>,
    /// Per-channel requantization to the pre-activation (or, without LUT, the output) params.
    pub requant: FcRequant<'a>,
    /// Activation table from pre-activation to output params; `None` for identity/clamp-only.
    pub activation: Option<&'a Lut8>,
}

impl Int8Layer<'_> {
    /// The layer on `input`: fully connected, requantized, activation table applied, in one pass
    /// (`output` is `out_features` long).
    pub fn forward(&self, input: LayerInput<'_>, output: &mut [i8]) -> Result<(), KernelError> {
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
        output: &mut [i8],
    ) -> Result<(), KernelError> {
        self.fc
            .forward_validated(&self.requant, self.activation, input, output)
    }

    /// First-layer accumulators of a two-plane input ([`InputPrecision::TwoPlane`]):
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
    /// into `output` and applies its LUT.
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
        if let Some(lut) = self.activation {
            lut.apply_in_place(output);
        }
        Ok(())
    }
}

/// How the f32 input vector is quantized for the first layer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum InputPrecision {
    /// One int8 code per value ([`QuantParams::quantize`]), as TFLite.
    #[default]
    Int8,
    /// A coarse and a fine int8 plane per value (see the module docs); the first hidden layer's
    /// multipliers must be for the input scale `input_scale / 2^FINE_INPUT_BITS`.
    TwoPlane,
    /// One 16-bit code per value on the fine grid (see the module docs); the first hidden
    /// layer's bias and multipliers must be for the input scale `input_scale / 2^FINE_INPUT_BITS`.
    Int16,
}

/// Writes the 16-bit codes ([`quantize_i16`]) of `input` into `codes` (values beyond the shorter
/// slice are left alone).
pub fn quantize_input_i16(input: &[f32], params: QuantParams, codes: &mut [i16]) {
    for (code, x) in codes.iter_mut().zip(input) {
        *code = quantize_i16(*x, params);
    }
}

/// Writes the two-plane codes ([`quantize_two_plane`]) of `input` into `coarse` and `fine`
/// (pairs beyond the shortest slice are left alone).
pub fn quantize_input_two_plane(
    input: &[f32],
    params: QuantParams,
    coarse: &mut [i8],
    fine: &mut [i8],
) {
    for ((c, f), x) in coarse.iter_mut().zip(fine.iter_mut()).zip(input) {
        (*c, *f) = quantize_two_plane(*x, params);
    }
}

/// int8 MLP: hidden [`Int8Layer`]s, then a raw-accumulator output layer dequantized to f32.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Int8Mlp<'a> {
    /// Quantization of the f32 input vector (first layer's input).
    pub input: QuantParams,
    /// Hidden layers in order (may be empty).
    pub hidden: &'a [Int8Layer<'a>],
    /// Output layer; its int32 accumulators are dequantized, not requantized.
    pub output: FullyConnected<'a>,
    /// `[output.out_features]` dequantization scales `input_scale * weight_scale[o]`.
    pub output_scales: &'a [f32],
}

/// Scratch buffers for [`Int8Mlp::forward`]: two int8 ping-pong activations and the int32
/// accumulators of the output layer, each `WIDTH` long.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Int8Scratch<const WIDTH: usize> {
    ping: [i8; WIDTH],
    pong: [i8; WIDTH],
    accumulators: [i32; WIDTH],
}

impl<const WIDTH: usize> Int8Scratch<WIDTH> {
    /// Zeroed scratch.
    pub const fn new() -> Self {
        Self {
            ping: [0; WIDTH],
            pong: [0; WIDTH],
            accumulators: [0; WIDTH],
        }
    }

    /// The output layer's int32 accumulators of the last forward pass (`out_features` long prefix).
    pub fn accumulators(&self) -> &[i32; WIDTH] {
        &self.accumulators
    }
}

impl<const WIDTH: usize> Default for Int8Scratch<WIDTH> {
    fn default() -> Self {
        Self::new()
    }
}

impl Int8Mlp<'_> {
    /// Input width (first layer's `in_features`).
    pub fn input_width(&self) -> usize {
        self.hidden
            .first()
            .map_or(self.output.in_features, |layer| layer.fc.in_features)
    }

    /// Output width (`output.out_features`).
    pub fn output_width(&self) -> usize {
        self.output.out_features
    }

    /// Checks that consecutive widths agree and that every width fits in `WIDTH`.
    pub fn validate<const WIDTH: usize>(&self) -> Result<(), ModelError> {
        self.input.validate().map_err(|_| ModelError::InputParams)?;
        let mut width = self.input_width();
        let layers = self
            .hidden
            .iter()
            .map(|layer| &layer.fc)
            .chain([&self.output]);
        for (index, fc) in layers.enumerate() {
            fc.validate()?;
            if fc.in_features != width {
                return Err(ModelError::LayerWidth { index });
            }
            if fc.in_features > WIDTH || fc.out_features > WIDTH {
                return Err(ModelError::ScratchTooSmall);
            }
            width = fc.out_features;
        }
        if self.output_scales.len() != self.output.out_features {
            return Err(ModelError::Kernel(KernelError::ScaleLength));
        }
        Ok(())
    }

    /// Runs the network on `input` (f32, `input_width()` long) and writes the dequantized last
    /// layer into `output` (`output_width()` long); the input is quantized to int8
    /// ([`InputPrecision::Int8`]).
    pub fn forward<const WIDTH: usize>(
        &self,
        input: &[f32],
        output: &mut [f32],
        scratch: &mut Int8Scratch<WIDTH>,
    ) -> Result<(), ModelError> {
        self.forward_with_input(InputPrecision::Int8, input, output, scratch)
    }

    /// Checks every hidden layer's requantization parameters ([`FcRequant::validate`]).
    pub fn validate_requantization(&self) -> Result<(), ModelError> {
        for layer in self.hidden {
            layer.requant.validate(layer.fc.out_features)?;
        }
        Ok(())
    }

    /// [`Self::forward`] with the input quantized as `precision` says.
    pub fn forward_with_input<const WIDTH: usize>(
        &self,
        precision: InputPrecision,
        input: &[f32],
        output: &mut [f32],
        scratch: &mut Int8Scratch<WIDTH>,
    ) -> Result<(), ModelError> {
        self.validate_requantization()?;
        self.forward_prevalidated(precision, input, output, scratch)
    }

    /// [`Self::forward_with_input`] for a network whose requantization passed
    /// [`Self::validate_requantization`] before (the per-channel checks are not repeated; see
    /// [`Int8Layer::forward_prevalidated`]).
    pub fn forward_prevalidated<const WIDTH: usize>(
        &self,
        precision: InputPrecision,
        input: &[f32],
        output: &mut [f32],
        scratch: &mut Int8Scratch<WIDTH>,
    ) -> Result<(), ModelError> {
        self.validate::<WIDTH>()?;
        let in_width = self.input_width();
        if input.len() != in_width {
            return Err(ModelError::InputLength);
        }
        if output.len() != self.output_width() {
            return Err(ModelError::OutputLength);
        }
        let Int8Scratch {
            ping,
            pong,
            accumulators,
        } = scratch;
        let (mut current, mut next) = (ping, pong);
        let first = current
            .get_mut(..in_width)
            .ok_or(ModelError::ScratchTooSmall)?;
        let mut width = in_width;
        let mut hidden = self.hidden;
        match precision {
            InputPrecision::Int8 => {
                for (q, x) in first.iter_mut().zip(input) {
                    *q = self.input.quantize(*x);
                }
            }
            InputPrecision::TwoPlane => {
                let (layer, rest) = self
                    .hidden
                    .split_first()
                    .ok_or(ModelError::TwoPlaneWithoutHiddenLayer)?;
                let fine = next
                    .get_mut(..in_width)
                    .ok_or(ModelError::ScratchTooSmall)?;
                quantize_input_two_plane(input, self.input, first, fine);
                let out_width = layer.fc.out_features;
                let acc = accumulators
                    .get_mut(..out_width)
                    .ok_or(ModelError::ScratchTooSmall)?;
                layer.two_plane_accumulators(first, fine, acc)?;
                let layer_output = next
                    .get_mut(..out_width)
                    .ok_or(ModelError::ScratchTooSmall)?;
                layer.requantize_and_activate(acc, layer_output)?;
                core::mem::swap(&mut current, &mut next);
                width = out_width;
                hidden = rest;
            }
            InputPrecision::Int16 => {
                let (layer, rest) = self
                    .hidden
                    .split_first()
                    .ok_or(ModelError::TwoPlaneWithoutHiddenLayer)?;
                // The accumulators are free until the output layer: they hold the 16-bit codes.
                let codes = bytemuck::cast_slice_mut::<i32, i16>(accumulators.as_mut_slice())
                    .get_mut(..in_width)
                    .ok_or(ModelError::ScratchTooSmall)?;
                quantize_input_i16(input, self.input, codes);
                let out_width = layer.fc.out_features;
                let layer_output = next
                    .get_mut(..out_width)
                    .ok_or(ModelError::ScratchTooSmall)?;
                layer.forward_prevalidated(LayerInput::Int16(codes), layer_output)?;
                core::mem::swap(&mut current, &mut next);
                width = out_width;
                hidden = rest;
            }
        }
        for layer in hidden {
            let out_width = layer.fc.out_features;
            let layer_input = current.get(..width).ok_or(ModelError::ScratchTooSmall)?;
            let layer_output = next
                .get_mut(..out_width)
                .ok_or(ModelError::ScratchTooSmall)?;
            layer.forward_prevalidated(LayerInput::Int8(layer_input), layer_output)?;
            core::mem::swap(&mut current, &mut next);
            width = out_width;
        }
        let last_input = current.get(..width).ok_or(ModelError::ScratchTooSmall)?;
        let acc = accumulators
            .get_mut(..self.output.out_features)
            .ok_or(ModelError::ScratchTooSmall)?;
        self.output.forward_accumulators(last_input, acc)?;
        dequantize_accumulators(acc, self.output_scales, output)?;
        Ok(())
    }
}
