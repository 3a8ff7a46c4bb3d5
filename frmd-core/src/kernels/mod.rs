//! Compute kernels of the firmware forward passes.
//!
//! - [`dot`]: int8 x int8 -> int32 dot product (on Arm cores with the DSP extension, the
//!   fully connected layer uses the `SMLAD` kernel of the private `dsp` module; see `build.rs`);
//! - [`fc`]: fully connected layer (requantized int8 or int16 output, or raw accumulators),
//!   generic over the activation [`Precision`] (int8, or int16 with int64 accumulation);
//! - [`lut`]: 256-entry int8 lookup-table activations and their builder;
//! - [`lut16`]: interpolated 513-knot int16 activation tables and their builder;
//! - [`precision`]: the [`Precision`] (`i8`, `i16`) and [`Accumulator`] (`i32`, `i64`) traits;
//! - [`activation`]: the f32 SiLU / Mish / GELU (erf, tanh and sigmoid forms) definitions used
//!   everywhere (LUT building, f32 reference paths, host models);
//! - [`packed`]: a layer's weights packed for the hosts' dot-product instructions;
//! - [`norm`]: f32 LayerNorm; [`softmax`]: numerically stable f32 softmax.
//!
//! Every kernel checks slice lengths and returns a [`KernelError`] instead of panicking. Integer
//! kernels are bit-exact: int32 accumulation wraps (two's complement, like the Cortex-M
//! `SMLAD`/`MLA` instructions), so the result does not depend on summation order; int64
//! accumulation adds the sign-extended int32 sums of fixed 512-column chunks.

#[cfg(target_arch = "aarch64")]
pub mod aarch64;
pub mod activation;
pub mod dot;
#[cfg(frmd_arm_dsp)]
mod dsp;
#[cfg(frmd_arm_dsp)]
mod dsp_asm;
pub mod fc;
mod input;
pub mod lut;
pub mod lut16;
pub mod norm;
pub mod packed;
pub mod precision;
pub(crate) mod rows;
pub mod softmax;
#[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
mod switch;
#[cfg(target_arch = "x86_64")]
pub mod x86;

pub use activation::{gelu, gelu_sigmoid, gelu_tanh, mish, silu, softplus, Activation};
pub use dot::dot_i8;
pub use fc::{dequantize_accumulators, FcRequant, FullyConnected, LayerInput};
pub use lut::{Lut8, LutTable};
pub use lut16::{Lut16, Lut16Table, LUT16_LEN};
pub use norm::{layer_norm, layer_norm_in_place};
pub use precision::{Accumulator, Precision};
pub use softmax::softmax_in_place;

/// Rows per block that the row kernels (`rows::for_each_block`) hand to their caller.
pub(crate) const BLOCK_ROWS: usize = 16;

/// Why a kernel refused its arguments. Small and `Copy`; each variant names the offending slice.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum KernelError {
    /// The two operands of a dot product differ in length.
    OperandLength,
    /// `weights.len() != out_features * in_features` (or a zero dimension).
    WeightsLength,
    /// `bias.len() != out_features`.
    BiasLength,
    /// Per-channel multipliers or shifts: `len() != out_features`.
    RequantLength,
    /// A per-channel scale slice has the wrong length.
    ScaleLength,
    /// The input slice has the wrong length.
    InputLength,
    /// The output slice has the wrong length.
    OutputLength,
    /// LayerNorm `gamma` or `beta` has the wrong length.
    AffineLength,
    /// An operation that needs at least one element got an empty slice.
    Empty,
    /// `activation_min > activation_max`.
    ActivationRange,
    /// The output zero point lies outside `[-128, 127]` (int8 outputs) or is not 0 (int16).
    ZeroPoint,
    /// A per-channel shift lies outside `SHIFT_MIN..=SHIFT_MAX`, or a multiplier is negative.
    Multiplier,
    /// A float input is NaN or +infinity where a finite value is required.
    NonFinite,
    /// LayerNorm epsilon is not a finite positive number.
    Epsilon,
    /// A weight of -128 in a layer with int64 accumulation (exact only for `[-127, 127]`).
    WeightRange,
    /// An int64 bias beyond `quant::BIAS16_MAX`, or an input wider than
    /// `quant::IN_FEATURES16_MAX`: accumulators could leave the exact domain.
    BiasRange,
}

impl core::fmt::Display for KernelError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let text = match self {
            Self::OperandLength => "dot product operands differ in length",
            Self::WeightsLength => "weights length is not out_features * in_features",
            Self::BiasLength => "bias length is not out_features",
            Self::RequantLength => "multiplier/shift length is not out_features",
            Self::ScaleLength => "per-channel scale length is not out_features",
            Self::InputLength => "input length does not match the layer",
            Self::OutputLength => "output length does not match the layer",
            Self::AffineLength => "layer norm gamma/beta length does not match the input",
            Self::Empty => "empty input",
            Self::ActivationRange => "activation_min > activation_max",
            Self::ZeroPoint => "output zero point is outside [-128, 127] (int8) or not 0 (int16)",
            Self::Multiplier => "requantization multiplier negative or shift out of range",
            Self::NonFinite => "non-finite float input",
            Self::Epsilon => "layer norm epsilon is not finite and positive",
            Self::WeightRange => "weight -128 in a layer with int64 accumulation",
            Self::BiasRange => "int64 bias or input width beyond the exact accumulation range",
        };
        f.write_str(text)
    }
}

/// No variant wraps another error.
impl core::error::Error for KernelError {}
