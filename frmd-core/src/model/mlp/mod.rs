//! MLP backbone built from [`crate::model::linear`]: an int8 forward pass ([`Int8Mlp`]: hidden
//! [`RequantizedLinear`] layers with table activations, the last layer an [`Int8Linear`]
//! dequantized to f32) and an f32 reference forward pass ([`F32Mlp`]) through the same structure.
//!
//! Int8 data flow for hidden layer `l` (all int8 tensors are asymmetric per tensor):
//! `x_l (int8) --FC + requant--> pre_l (int8, params of the pre-activation) --LUT--> x_{l+1}`;
//! a layer without a table (ReLU via the clamp, or identity) outputs `x_{l+1}` directly. The f32
//! input is quantized with [`Int8Mlp::input`]; the last layer's int32 accumulators are dequantized
//! per channel with `output_scales[o] = input_scale * weight_scale[o]`.
//!
//! With [`InputPrecision::TwoPlane`] the input gets about 16 bits instead of 8: each value becomes
//! a coarse int8 code and a fine int8 code of the residual at `1/2^FINE_INPUT_BITS` of the input
//! scale ([`quantize_two_plane`]); the first hidden layer runs its int8 kernel on both planes and
//! requantizes `coarse_acc * 2^8 + fine_dot` ([`crate::quant::combine_plane_accumulators`]), so
//! its multipliers are those of the input scale `input_scale / 2^FINE_INPUT_BITS`. Everything
//! after the first layer is unchanged. Cost: one more int8 matrix-vector product of the first
//! layer.
//!
//! [`InputPrecision::Int16`] gives the same precision in one pass: each value becomes one 16-bit
//! code on the fine grid (`input_scale / 2^8`, zero point `input_zero_point * 2^8`,
//! [`quantize_i16`]) and the first layer multiplies int8 weights by int16 codes (on Arm DSP cores
//! `SMLAD` takes the 16-bit codes as they are). Its bias is at the fine scale and its multipliers
//! are made for the fine scale, as for two planes.
//!
//! With int16 activations ([`Int16Mlp`], TFLite's 16x8 scheme) every hidden activation is a
//! symmetric int16 code, the biases and accumulators are int64 and the activation tables are
//! interpolated int16 tables; the input is the 16-bit plane as above. [`QuantMlp`] is written once
//! for both precisions ([`MlpPrecision`]).
//!
//! Working memory is caller-owned: slices ([`QuantBuffers`], [`F32Buffers`]), or fixed arrays of a
//! const `WIDTH` at least the widest layer ([`QuantScratch`], [`F32Scratch`]); nothing is
//! allocated. The transformer's feed-forward is a one-hidden-layer MLP run on the transformer's
//! own scratch.

mod float;
mod quantized;
#[cfg(test)]
mod tests;

pub use float::{F32Buffers, F32Mlp, F32Scratch};
pub use quantized::{
    Int16Mlp, Int8Buffers, Int8Mlp, Int8Scratch, MlpPrecision, QuantBuffers, QuantMlp, QuantScratch,
};

use crate::kernels::KernelError;
#[cfg(doc)]
use crate::model::linear::{Int8Linear, RequantizedLinear};
use crate::quant::{quantize_i16, quantize_two_plane, QuantParams};

/// Why a forward pass refused its arguments.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ModelError {
    /// A kernel refused a layer's arguments (names the slice).
    Kernel(KernelError),
    /// Layer `index` (0-based, the output layer last) does not take the previous layer's width.
    LayerWidth {
        /// Index of the offending layer.
        index: usize,
    },
    /// A layer is wider than the scratch buffers.
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
    /// int16 activations take the 16-bit input plane only ([`InputPrecision::Int16`]).
    InputPrecision,
}

impl From<KernelError> for ModelError {
    fn from(error: KernelError) -> Self {
        Self::Kernel(error)
    }
}

impl core::fmt::Display for ModelError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Kernel(_) => f.write_str("a kernel refused a layer"),
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
            Self::InputPrecision => {
                f.write_str("int16 activations take the 16-bit input plane only")
            }
        }
    }
}

impl core::error::Error for ModelError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        match self {
            Self::Kernel(error) => Some(error),
            _ => None,
        }
    }
}

/// How the f32 input vector is quantized for the first layer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
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

/// Which tensor an [`F32Mlp::forward_observed`] callback sees (for calibration).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Probe {
    /// The network input.
    Input,
    /// Hidden layer `l`'s affine output before its activation.
    PreActivation(usize),
    /// Hidden layer `l`'s output after its activation (the next layer's input).
    Output(usize),
    /// The output layer's values (before any activation it has).
    Final,
}

/// Checks a forward pass's input and output lengths against the network's widths.
#[inline]
fn check_lengths(
    (input_len, output_len): (usize, usize),
    (input_width, output_width): (usize, usize),
) -> Result<(), ModelError> {
    if input_len != input_width {
        return Err(ModelError::InputLength);
    }
    if output_len != output_width {
        return Err(ModelError::OutputLength);
    }
    Ok(())
}

/// Checks that consecutive widths agree (`widths` yields `(in, out)` per layer, output last),
/// starting from `input_width`, and that every width is at most `max_width`.
fn check_widths(
    input_width: usize,
    widths: impl Iterator<Item = (usize, usize)>,
    max_width: usize,
) -> Result<(), ModelError> {
    let mut width = input_width;
    for (index, (in_features, out_features)) in widths.enumerate() {
        if in_features != width {
            return Err(ModelError::LayerWidth { index });
        }
        if in_features > max_width || out_features > max_width {
            return Err(ModelError::ScratchTooSmall);
        }
        width = out_features;
    }
    Ok(())
}
