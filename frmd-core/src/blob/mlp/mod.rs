//! MLP blobs (magic [`MLP_MAGIC`], `b"FRMD"`): the [`MlpDescriptor`], its emit side
//! ([`encode_mlp`] from borrowed [`MlpBlobParts`]) and its parse side ([`LoadedMlp`]).
//!
//! Data area, in order: the policy sections (`blob::policy_tables`), the first-layer bias
//! variants (i32), the activation tables (i8, [`LUT_LEN`] each, one per hidden layer that has one,
//! in layer order), then per hidden layer weights (i8 `[out, in]`), bias, multipliers and shifts
//! (i32 `[out]`), then the output layer's weights, bias and dequantization scales (f32). The data
//! area ends at a multiple of 16 bytes.

use heapless::Vec;
use serde::{Deserialize, Serialize};

use super::container::{self, Section, SectionWriter};
use super::policy_tables::{self, PolicyHeader, PolicySections};
use super::{BlobError, SectionId};
use crate::model::mlp::{InputPrecision, Int8Mlp};
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
    /// Lower clamp of the requantized output.
    pub activation_min: i8,
    /// Upper clamp of the requantized output.
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
    /// i32 `[out]`.
    pub bias: Section,
    /// f32 `[out]` dequantization scales.
    pub scales: Section,
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
    /// i32 first-layer bias variants, `out_features` of the first layer each (may be empty).
    pub first_layer_biases: Section,
    /// i8 `[tables][LUT_LEN]`.
    pub luts: Section,
    /// Hidden layers in order.
    pub hidden: Vec<HiddenLayerDesc, MAX_HIDDEN_LAYERS>,
    /// Output layer.
    pub output: OutputLayerDesc,
}

/// Everything an MLP blob holds, borrowed.
#[derive(Clone, Copy, Debug)]
pub struct MlpBlobParts<'p> {
    /// Normalization, steps, decoder tables, layout, control period.
    pub config: PolicyConfig<'p>,
    /// The int8 network (its first hidden layer's bias is variant 0).
    pub mlp: Int8Mlp<'p>,
    /// How the first layer takes the input (its multipliers must match).
    pub input_precision: InputPrecision,
    /// First-layer bias variants back to back (may be empty).
    pub noise_variants: &'p [i32],
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

/// Lays out the sections of `parts` (every length checked against the stated shapes) and
/// returns the descriptor.
fn emit(
    parts: &MlpBlobParts<'_>,
    writer: &mut SectionWriter<'_>,
) -> Result<MlpDescriptor, BlobError> {
    let tables = policy_tables::write(writer, &parts.config)?;
    let first_layer_biases = writer.i32s(parts.noise_variants)?;
    let activations = parts.mlp.hidden.iter().filter_map(|layer| layer.activation);
    let luts = writer.i8s(activations.flatten())?;
    let mut hidden = Vec::new();
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
        let desc = HiddenLayerDesc {
            in_features: small(fc.in_features)?,
            out_features: small(out)?,
            weights: writer.i8s(fc.weights.iter())?,
            bias: writer.i32s(fc.bias)?,
            multipliers: writer.i32s(requant.multipliers)?,
            shifts: writer.i32s(requant.shifts)?,
            output_zero_point: requant.output_zero_point,
            activation_min: requant.activation_min,
            activation_max: requant.activation_max,
            lut,
        };
        hidden.push(desc).map_err(|_| BlobError::TooLarge)?;
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
        bias: writer.i32s(fc.bias)?,
        scales: writer.f32s(scales.iter())?,
    };
    writer.pad_end();
    Ok(MlpDescriptor {
        header: PolicyHeader::of(&parts.config)?,
        input_scale: parts.mlp.input.scale,
        input_zero_point: parts.mlp.input.zero_point,
        input_precision: precision_code(parts.input_precision),
        tables,
        first_layer_biases,
        luts,
        hidden,
        output,
    })
}

/// Exact length of the blob [`encode_mlp`] writes for `parts`.
pub fn mlp_encoded_len(parts: &MlpBlobParts<'_>) -> Result<usize, BlobError> {
    container::encoded_len(|writer| emit(parts, writer))
}

/// Writes the MLP blob of `parts` into the front of `out` and returns its length
/// ([`mlp_encoded_len`]); the rest of `out` is untouched. Every part's length is checked against
/// the stated shapes; value checks (finite floats, shift ranges, ...) are the loader's.
pub fn encode_mlp(parts: &MlpBlobParts<'_>, out: &mut [u8]) -> Result<usize, BlobError> {
    container::encode(MLP_MAGIC, out, |writer| emit(parts, writer))
}

mod load;

pub use load::LoadedMlp;
