//! MLP blobs (magic [`MLP_MAGIC`], `b"FRMD"`): the [`MlpDescriptor`] with its
//! [`MlpActivations`] trailer, the emit side ([`encode_mlp`] from borrowed [`MlpBlobParts`]) and
//! the parse side ([`LoadedMlp`]), for int8 or int16 activations (int8 weights either way).
//!
//! Data area, in order: the policy sections (`blob::policy_tables`), the first-layer bias
//! variants, the activation tables (one per hidden layer that has one, in layer order: [`LUT_LEN`]
//! int8 entries, or `LUT16_LEN` int16 knots), then per hidden layer weights (i8 `[out, in]`),
//! bias, multipliers and shifts (i32 `[out]`), then the output layer's weights, bias and
//! dequantization scales (f32). Biases and bias variants are i32 with int8 activations and i64
//! with int16 activations (the loader then needs the blob 8-byte aligned). The data area ends at
//! a multiple of 16 bytes.

use heapless::Vec;
use serde::{Deserialize, Serialize};

use super::container::{self, Section, SectionWriter};
use super::policy_tables::{self, PolicyHeader, PolicySections};
use super::{BlobError, SectionId};
use crate::model::mlp::{InputPrecision, MlpPrecision, QuantMlp};
use crate::policy::{PolicyConfig, MAX_HIDDEN_LAYERS};

/// First four bytes of an MLP blob.
pub const MLP_MAGIC: [u8; 4] = *b"FRMD";
/// [`MlpDescriptor::input_precision`] of int8 input ([`InputPrecision::Int8`]).
pub const INPUT_INT8: u8 = 0;
/// [`MlpDescriptor::input_precision`] of a two-plane input ([`InputPrecision::TwoPlane`]).
pub const INPUT_TWO_PLANE: u8 = 1;
/// [`MlpDescriptor::input_precision`] of the 16-bit input plane ([`InputPrecision::Int16`]).
pub const INPUT_INT16: u8 = 2;
/// Bytes per table in the activation-table section (outputs for input codes -128..=127).
pub const LUT_LEN: usize = 256;
/// Format version from which MLP descriptors end with an [`MlpActivations`] trailer.
pub const ACTIVATIONS_SINCE: u16 = 4;

/// The sections of an MLP blob besides the policy sections (for
/// [`SectionId::Mlp`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MlpSection {
    /// First-layer bias variants.
    FirstLayerBiases,
    /// Activation tables.
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
}

/// One hidden layer: int8 FC, per-channel requantization, optional activation table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct HiddenLayerDesc {
    /// Input width.
    pub in_features: u32,
    /// Output width.
    pub out_features: u32,
    /// i8 `[out, in]` row-major.
    pub weights: Section,
    /// i32 `[out]` (input zero point folded). For the first layer these are variant 0's; the
    /// sampler uses the first-layer-bias section instead when it is non-empty.
    pub bias: Section,
    /// i32 `[out]` Q31 multipliers.
    pub multipliers: Section,
    /// i32 `[out]` shifts.
    pub shifts: Section,
    /// Zero point of the requantized output.
    pub output_zero_point: i32,
    /// Lower clamp of the requantized output (formats 2 and 3; from format 4 the trailer's
    /// [`MlpActivations::clamps`] hold the clamps and these are their int8 saturations).
    pub activation_min: i8,
    /// Upper clamp of the requantized output (see `activation_min`).
    pub activation_max: i8,
    /// Index of the table applied after requantization, if any.
    pub lut: Option<u32>,
}

/// The output layer: int8 FC whose int32 accumulators are dequantized to f32.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct OutputLayerDesc {
    /// Input width.
    pub in_features: u32,
    /// Output width (`k p`).
    pub out_features: u32,
    /// i8 `[out, in]` row-major.
    pub weights: Section,
    /// i32 `[out]` (i64 with int16 activations).
    pub bias: Section,
    /// f32 `[out]` dequantization scales.
    pub scales: Section,
}

/// The trailer of an MLP descriptor (format 4 on; older blobs have int8 activations and their
/// clamps in the layer descriptors).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct MlpActivations {
    /// Bits per activation code: 8 (int8 activations, i32 biases) or 16 (int16 activations, i64
    /// biases, interpolated tables).
    pub bits: u8,
    /// `[activation_min, activation_max]` of each hidden layer, in its activation codes.
    pub clamps: Vec<[i16; 2], MAX_HIDDEN_LAYERS>,
}

/// Everything about an MLP blob that is not bulk data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MlpDescriptor {
    /// Sizes, control period and input layout.
    pub header: PolicyHeader,
    /// Input quantization scale.
    pub input_scale: f32,
    /// Input quantization zero point.
    pub input_zero_point: i32,
    /// How the first layer takes the input ([`INPUT_INT8`], [`INPUT_TWO_PLANE`] or
    /// [`INPUT_INT16`]); a `bool` "two-plane" flag in format version 2.
    pub input_precision: u8,
    /// Normalization, ProDMP tables and steps.
    pub tables: PolicySections,
    /// First-layer bias variants, `out_features` of the first layer each (may be empty); i32, or
    /// i64 with int16 activations.
    pub first_layer_biases: Section,
    /// Activation tables: i8 `[tables][LUT_LEN]`, or i16 `[tables][LUT16_LEN]`.
    pub luts: Section,
    /// Hidden layers in order.
    pub hidden: Vec<HiddenLayerDesc, MAX_HIDDEN_LAYERS>,
    /// Output layer.
    pub output: OutputLayerDesc,
}

/// Everything an MLP blob holds, borrowed; `P` is the activation precision.
#[derive(Clone, Copy, Debug)]
pub struct MlpBlobParts<'p, P: MlpPrecision = i8> {
    /// Normalization, steps, decoder tables, layout, control period.
    pub config: PolicyConfig<'p>,
    /// The quantized network (its first hidden layer's bias is variant 0).
    pub mlp: QuantMlp<'p, P>,
    /// How the first layer takes the input (its multipliers must match).
    pub input_precision: InputPrecision,
    /// First-layer bias variants back to back (may be empty).
    pub noise_variants: &'p [P::Acc],
}

fn precision_code(precision: InputPrecision) -> u8 {
    match precision {
        InputPrecision::Int8 => INPUT_INT8,
        InputPrecision::TwoPlane => INPUT_TWO_PLANE,
        InputPrecision::Int16 => INPUT_INT16,
    }
}

fn small(value: usize) -> Result<u32, BlobError> {
    u32::try_from(value).map_err(|_| BlobError::TooLarge)
}

fn expect_len(actual: usize, expected: Option<usize>, id: SectionId) -> Result<(), BlobError> {
    if Some(actual) == expected {
        Ok(())
    } else {
        Err(BlobError::SectionLength(id))
    }
}

/// `value` saturated to the int8 range (the pre-format-4 clamp fields).
fn saturate_i8(value: i16) -> i8 {
    value.clamp(i16::from(i8::MIN), i16::from(i8::MAX)) as i8
}

/// Lays out the sections of `parts` (every length checked against the stated shapes) and
/// returns the descriptor and its trailer.
fn emit<P: MlpPrecision + Into<i16>>(
    parts: &MlpBlobParts<'_, P>,
    writer: &mut SectionWriter<'_>,
) -> Result<(MlpDescriptor, MlpActivations), BlobError> {
    let tables = policy_tables::write(writer, &parts.config)?;
    let first_layer_biases = writer.ints([parts.noise_variants].into_iter())?;
    let activations = parts.mlp.hidden.iter().filter_map(|layer| layer.activation);
    let luts = writer.ints(activations.map(P::table_entries))?;
    let mut hidden = Vec::new();
    let mut clamps = Vec::new();
    let mut next_lut = 0_u32;
    for (index, layer) in parts.mlp.hidden.iter().enumerate() {
        let id = u8::try_from(index).map_err(|_| BlobError::TooLarge)?;
        let (fc, requant) = (&layer.fc, &layer.requant);
        let out = fc.out_features;
        let weight_count = out.checked_mul(fc.in_features);
        expect_len(
            fc.weights.len(),
            weight_count,
            MlpSection::HiddenWeights(id).into(),
        )?;
        expect_len(fc.bias.len(), Some(out), MlpSection::HiddenBias(id).into())?;
        expect_len(
            requant.multipliers.len(),
            Some(out),
            MlpSection::HiddenMultipliers(id).into(),
        )?;
        expect_len(
            requant.shifts.len(),
            Some(out),
            MlpSection::HiddenShifts(id).into(),
        )?;
        let lut = layer.activation.map(|_| {
            next_lut += 1;
            next_lut - 1
        });
        let clamp: [i16; 2] = [requant.activation_min.into(), requant.activation_max.into()];
        let desc = HiddenLayerDesc {
            in_features: small(fc.in_features)?,
            out_features: small(out)?,
            weights: writer.i8s(fc.weights.iter())?,
            bias: writer.ints([fc.bias].into_iter())?,
            multipliers: writer.i32s(requant.multipliers)?,
            shifts: writer.i32s(requant.shifts)?,
            output_zero_point: requant.output_zero_point,
            activation_min: saturate_i8(clamp[0]),
            activation_max: saturate_i8(clamp[1]),
            lut,
        };
        hidden.push(desc).map_err(|_| BlobError::TooLarge)?;
        clamps.push(clamp).map_err(|_| BlobError::TooLarge)?;
    }
    let (fc, scales) = (&parts.mlp.output.fc, parts.mlp.output.output_scales);
    let out = fc.out_features;
    expect_len(
        fc.weights.len(),
        out.checked_mul(fc.in_features),
        MlpSection::OutputWeights.into(),
    )?;
    expect_len(fc.bias.len(), Some(out), MlpSection::OutputBias.into())?;
    expect_len(scales.len(), Some(out), MlpSection::OutputScales.into())?;
    let output = OutputLayerDesc {
        in_features: small(fc.in_features)?,
        out_features: small(out)?,
        weights: writer.i8s(fc.weights.iter())?,
        bias: writer.ints([fc.bias].into_iter())?,
        scales: writer.f32s(scales.iter())?,
    };
    writer.pad_end();
    let trailer = MlpActivations {
        bits: P::BITS,
        clamps,
    };
    let descriptor = MlpDescriptor {
        header: PolicyHeader::of(&parts.config)?,
        input_scale: parts.mlp.input.scale,
        input_zero_point: parts.mlp.input.zero_point,
        input_precision: precision_code(parts.input_precision),
        tables,
        first_layer_biases,
        luts,
        hidden,
        output,
    };
    Ok((descriptor, trailer))
}

/// Exact length of the blob [`encode_mlp`] writes for `parts`.
pub fn mlp_encoded_len<P: MlpPrecision + Into<i16>>(
    parts: &MlpBlobParts<'_, P>,
) -> Result<usize, BlobError> {
    container::encoded_len(|writer| emit(parts, writer))
}

/// Writes the MLP blob of `parts` into the front of `out` and returns its length
/// ([`mlp_encoded_len`]); the rest of `out` is untouched. Every part's length is checked against
/// the stated shapes; value checks (finite floats, shift ranges, ...) are the loader's.
pub fn encode_mlp<P: MlpPrecision + Into<i16>>(
    parts: &MlpBlobParts<'_, P>,
    out: &mut [u8],
) -> Result<usize, BlobError> {
    container::encode(MLP_MAGIC, out, |writer| emit(parts, writer))
}

mod load;

pub use load::{activation_bits, LoadedMlp, LoadedMlp16, LoadedQuantMlp};
