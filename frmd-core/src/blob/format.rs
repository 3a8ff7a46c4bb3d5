//! Blob layout: fixed header, postcard descriptor, aligned sections.
//!
//! ```text
//! offset  size  field (little endian)
//!  0      4     magic b"FRMD"
//!  4      2     format version (u16, FORMAT_VERSION)
//!  6      2     reserved, 0
//!  8      4     total length in bytes, header included (u32)
//! 12      4     CRC-32 (IEEE) of bytes [HEADER_LEN, total length)
//! 16      4     descriptor length in bytes (u32)
//! 20      ..    descriptor (postcard-encoded [`Descriptor`])
//! D       ..    data area, D = align_up(20 + descriptor length, SECTION_ALIGN)
//! ```
//! Every section is a `(offset, len)` byte range relative to the data area start `D`, with the
//! offset a multiple of [`SECTION_ALIGN`]; gaps are zero. Element types per section: normalization
//! and ProDMP tables, output scales: f32; step table: u32 words; biases, multipliers and shifts:
//! i32; weights and LUTs: i8. Multi-byte values are little endian, so the blob is read in place
//! on little-endian targets (Cortex-M, x86-64, aarch64); the loader needs the blob to start at a
//! 4-byte aligned address (it checks, see [`super::BlobError::SectionMisaligned`]).

use heapless::Vec;
use serde::{Deserialize, Serialize};

use crate::policy::{InputLayout, MAX_HIDDEN_LAYERS};

/// First four bytes of every blob.
pub const MAGIC: [u8; 4] = *b"FRMD";
/// The format version this crate writes. Version 3 turned the descriptor's two-plane flag into
/// an input precision code (adding the 16-bit input plane); postcard encodes the old `bool` as
/// the byte 0 or 1, which is the same code, so version 2 blobs read unchanged.
pub const FORMAT_VERSION: u16 = 3;
/// The oldest format version this crate reads.
pub const MIN_FORMAT_VERSION: u16 = 2;
/// [`Descriptor::input_precision`] of int8 input (`model::mlp::InputPrecision::Int8`).
pub const INPUT_INT8: u8 = 0;
/// [`Descriptor::input_precision`] of a two-plane input (`InputPrecision::TwoPlane`).
pub const INPUT_TWO_PLANE: u8 = 1;
/// [`Descriptor::input_precision`] of the 16-bit input plane (`InputPrecision::Int16`).
pub const INPUT_INT16: u8 = 2;
/// Header length in bytes (the descriptor starts here).
pub const HEADER_LEN: usize = 20;
/// Alignment of the data area and of every section offset, in bytes.
pub const SECTION_ALIGN: usize = 16;
/// Words per step in the step-constants section: `sigma, renoise_std, c_in, c_skip, c_out` as
/// f32 bit patterns, then `first_layer_bias_index`.
pub const STEP_WORDS: usize = 6;
/// Bytes per LUT in the LUT section (outputs for input codes -128..=127).
pub const LUT_LEN: usize = 256;

/// A byte range of the data area.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Section {
    /// Start, relative to the data area, a multiple of [`SECTION_ALIGN`].
    pub offset: u32,
    /// Length in bytes.
    pub len: u32,
}

/// One hidden layer: int8 FC, per-channel requantization, optional LUT activation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct HiddenLayerDesc {
    /// Input width.
    pub in_features: u32,
    /// Output width.
    pub out_features: u32,
    /// i8 `[out, in]` row-major.
    pub weights: Section,
    /// i32 `[out]` (input zero point folded). For the first layer these are step variant 0's;
    /// the sampler uses the first-layer-bias section instead when it is non-empty.
    pub bias: Section,
    /// i32 `[out]` Q31 multipliers.
    pub multipliers: Section,
    /// i32 `[out]` shifts.
    pub shifts: Section,
    /// Zero point of the requantized output.
    pub output_zero_point: i32,
    /// Lower clamp of the requantized output.
    pub activation_min: i8,
    /// Upper clamp of the requantized output.
    pub activation_max: i8,
    /// Index of the LUT applied after requantization, if any.
    pub lut: Option<u32>,
}

/// The output layer: int8 FC whose int32 accumulators are dequantized to f32.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct OutputLayerDesc {
    /// Input width.
    pub in_features: u32,
    /// Output width (`K * P`).
    pub out_features: u32,
    /// i8 `[out, in]` row-major.
    pub weights: Section,
    /// i32 `[out]`.
    pub bias: Section,
    /// f32 `[out]` dequantization scales.
    pub scales: Section,
}

/// Everything about the blob that is not bulk data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Descriptor {
    /// Observation history length `M`.
    pub history: u32,
    /// Observation dimension `O`.
    pub obs_dim: u32,
    /// Action dimension `K`.
    pub action_dim: u32,
    /// Horizon `N`.
    pub horizon: u32,
    /// ProDMP parameters per DoF `P`.
    pub params_per_dof: u32,
    /// Control period, seconds.
    pub control_dt: f32,
    /// Model input layout.
    pub layout: InputLayout,
    /// Input quantization scale.
    pub input_scale: f32,
    /// Input quantization zero point.
    pub input_zero_point: i32,
    /// How the first layer takes the input ([`INPUT_INT8`], [`INPUT_TWO_PLANE`] or
    /// [`INPUT_INT16`]); a `bool` "two-plane" flag in format version 2.
    pub input_precision: u8,
    /// f32 `[min; O]` then `[max; O]`.
    pub obs_norm: Section,
    /// f32 `[min; K]` then `[max; K]`.
    pub action_norm: Section,
    /// f32 `pos_params [N][P]`, `vel_params [N][P]`, `pos_y0 [N]`, `pos_v0 [N]`, `vel_y0 [N]`,
    /// `vel_v0 [N]`.
    pub prodmp: Section,
    /// u32 `[steps][STEP_WORDS]`.
    pub steps: Section,
    /// i32 first-layer bias variants, `out_features` of the first layer each (may be empty).
    pub first_layer_biases: Section,
    /// i8 `[luts][LUT_LEN]`.
    pub luts: Section,
    /// Hidden layers in order.
    pub hidden: Vec<HiddenLayerDesc, MAX_HIDDEN_LAYERS>,
    /// Output layer.
    pub output: OutputLayerDesc,
}

/// Names a section in errors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SectionId {
    /// Observation min/max.
    ObsNorm,
    /// Action min/max.
    ActionNorm,
    /// ProDMP tables.
    ProDmp,
    /// Step constants.
    Steps,
    /// First-layer bias variants.
    FirstLayerBiases,
    /// Activation LUTs.
    Luts,
    /// Hidden layer `n` weights.
    HiddenWeights(u8),
    /// Hidden layer `n` bias.
    HiddenBias(u8),
    /// Hidden layer `n` multipliers.
    HiddenMultipliers(u8),
    /// Hidden layer `n` shifts.
    HiddenShifts(u8),
    /// Output layer weights.
    OutputWeights,
    /// Output layer bias.
    OutputBias,
    /// Output layer dequantization scales.
    OutputScales,
    /// A section of a transformer blob: which part, which array.
    Transformer {
        /// The model part.
        part: crate::model::transformer::Part,
        /// The array of that part.
        field: super::transformer::TensorField,
    },
}

/// `value` rounded up to a multiple of `align` (a power of two); `None` on overflow.
pub(crate) fn align_up(value: usize, align: usize) -> Option<usize> {
    let mask = align.checked_sub(1)?;
    value.checked_add(mask).map(|v| v & !mask)
}
