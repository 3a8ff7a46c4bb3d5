//! Transformer-lite blobs (magic [`TRANSFORMER_MAGIC`], `b"FRMT"`): the
//! [`TransformerDescriptor`], its emit side ([`encode_transformer`] from borrowed
//! [`TransformerBlobParts`]) and its parse side ([`LoadedTransformer`]). An MLP loader rejects a
//! transformer blob (and vice versa) with [`BlobError::BadMagic`].
//!
//! Data area, in order: the policy sections (`blob::policy_tables`), the noise tokens (f32
//! `[variants][W]`; a step's `noise_variant` selects its token), the positions, `traj_in`,
//! `cond_in`, per block `norm1`, `qkv`, `proj`, `norm2`, `fc1` (with its multipliers, shifts and
//! GELU table), `fc2`, then `final_norm` and `head`. Element types: norms, positions, tokens,
//! scales f32; weights i8; multipliers, shifts i32; biases i32 and tables i8 `[256]` with int8
//! activations, biases i64 and tables i16 `[LUT16_LEN]` with int16 activations (format 5 on: the
//! descriptor's [`TransformerActivations`] trailer says which; older blobs are int8). The data
//! area ends with its last section.

use heapless::Vec;
use serde::{Deserialize, Serialize};

use super::container::{self, Section, SectionWriter};
use super::policy_tables::{self, PolicyHeader, PolicySections};
use super::BlobError;
use crate::kernels::{FullyConnected, Precision};
use crate::model::linear::QuantizedLinear;
use crate::model::transformer::{LayerNormWeights, QuantBlock, QuantTransformer, TokenLinear};
use crate::policy::PolicyConfig;
use crate::quant::QuantParams;

/// First four bytes of a transformer blob.
pub const TRANSFORMER_MAGIC: [u8; 4] = *b"FRMT";
/// Most blocks a transformer blob can hold.
pub const MAX_BLOCKS: usize = 8;
/// Format version from which transformer descriptors end with a [`TransformerActivations`]
/// trailer.
pub const TRANSFORMER_ACTIVATIONS_SINCE: u16 = 5;

/// A section of a transformer blob: which part, which array (for
/// [`SectionId::Transformer`](super::SectionId::Transformer)).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TransformerSection {
    /// The model part.
    pub part: crate::model::transformer::Part,
    /// The array of that part.
    pub field: TensorField,
}

/// Which array of a transformer part a section holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TensorField {
    /// i8 weights.
    Weights,
    /// i32 bias (i64 with int16 activations).
    Bias,
    /// f32 dequantization scales.
    Scales,
    /// i32 Q31 multipliers.
    Multipliers,
    /// i32 shifts.
    Shifts,
    /// GELU table (i8 `[256]`, or i16 `[LUT16_LEN]` with int16 activations).
    Lut,
    /// f32 LayerNorm gamma.
    Gamma,
    /// f32 LayerNorm beta.
    Beta,
    /// f32 values of positions or noise tokens.
    Values,
}

/// A linear layer with f32 input and output ([`QuantizedLinear`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinearDesc {
    /// Input quantization scale.
    pub input_scale: f32,
    /// Input quantization zero point.
    pub input_zero_point: i32,
    /// i8 `[out, in]`.
    pub weights: Section,
    /// i32 `[out]` (i64 with int16 activations).
    pub bias: Section,
    /// f32 `[out]`.
    pub scales: Section,
}

/// LayerNorm affine parameters, f32 `[W]` each.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct NormDesc {
    /// Scale.
    pub gamma: Section,
    /// Shift.
    pub beta: Section,
}

/// One block ([`QuantBlock`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BlockDesc {
    /// LayerNorm before attention.
    pub norm1: NormDesc,
    /// `W -> 3W`.
    pub qkv: LinearDesc,
    /// `W -> W`.
    pub proj: LinearDesc,
    /// LayerNorm before the feed-forward.
    pub norm2: NormDesc,
    /// `fc1` input scale and zero point, weights and bias (its `scales` section is empty).
    pub fc1: LinearDesc,
    /// i32 `[4W]` Q31 multipliers of `fc1`.
    pub fc1_multipliers: Section,
    /// i32 `[4W]` shifts of `fc1`.
    pub fc1_shifts: Section,
    /// Zero point of the requantized `fc1` output (GELU table input; 0 for int16).
    pub fc1_output_zero_point: i32,
    /// GELU table: i8 `[256]`, or i16 `[LUT16_LEN]` knots.
    pub gelu: Section,
    /// `4W -> W`; its input parameters are the GELU output's.
    pub fc2: LinearDesc,
}

/// Everything about a transformer blob that is not bulk data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TransformerDescriptor {
    /// Sizes, control period and input layout (which must be the standard order).
    pub header: PolicyHeader,
    /// Token width `W`.
    pub width: u32,
    /// Attention heads.
    pub heads: u32,
    /// Normalization, ProDMP tables and steps (as the MLP blob).
    pub tables: PolicySections,
    /// f32 `[variants][W]` noise tokens.
    pub noise_tokens: Section,
    /// f32 `[n + 2][W]` positions.
    pub positions: Section,
    /// `k -> W`.
    pub traj_in: LinearDesc,
    /// `cond_dim -> W`.
    pub cond_in: LinearDesc,
    /// The blocks in order.
    pub blocks: Vec<BlockDesc, MAX_BLOCKS>,
    /// Final LayerNorm.
    pub final_norm: NormDesc,
    /// `(n + 2) W -> k p`.
    pub head: LinearDesc,
}

/// The trailer of a transformer descriptor (format 5 on; older blobs have int8 activations).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TransformerActivations {
    /// Bits per activation code: 8 (i32 biases, 256-entry table) or 16 (i64 biases,
    /// interpolated table).
    pub bits: u8,
}

/// Everything a transformer blob holds, borrowed; `P` is the activation precision.
#[derive(Clone, Copy, Debug)]
pub struct TransformerBlobParts<'p, P: Precision = i8> {
    /// Normalization, steps, decoder tables, layout, control period.
    pub config: PolicyConfig<'p>,
    /// The quantized backbone (`traj_in` and `cond_in` quantized).
    pub model: QuantTransformer<'p, P>,
    /// The per-step noise tokens, `W` values each, back to back.
    pub noise_tokens: &'p [f32],
}

fn small(value: usize) -> Result<u32, BlobError> {
    u32::try_from(value).map_err(|_| BlobError::TooLarge)
}

fn write_linear<P: Precision>(
    writer: &mut SectionWriter<'_>,
    input: QuantParams,
    fc: &FullyConnected<'_, P::Acc>,
    scales: &[f32],
) -> Result<LinearDesc, BlobError> {
    Ok(LinearDesc {
        input_scale: input.scale,
        input_zero_point: input.zero_point,
        weights: writer.i8s(fc.weights.iter())?,
        bias: writer.ints([fc.bias].into_iter())?,
        scales: writer.f32s(scales.iter())?,
    })
}

fn write_quantized<P: Precision>(
    writer: &mut SectionWriter<'_>,
    layer: &QuantizedLinear<'_, P>,
) -> Result<LinearDesc, BlobError> {
    write_linear::<P>(
        writer,
        layer.input,
        &layer.linear.fc,
        layer.linear.output_scales,
    )
}

fn write_input<P: Precision>(
    writer: &mut SectionWriter<'_>,
    layer: &TokenLinear<'_, P>,
) -> Result<LinearDesc, BlobError> {
    match layer {
        TokenLinear::Quantized(layer) => write_quantized(writer, layer),
        // The format holds quantized input layers only.
        TokenLinear::Float(_) => Err(BlobError::Encode),
    }
}

fn write_norm(
    writer: &mut SectionWriter<'_>,
    norm: &LayerNormWeights<'_>,
) -> Result<NormDesc, BlobError> {
    Ok(NormDesc {
        gamma: writer.f32s(norm.gamma.iter())?,
        beta: writer.f32s(norm.beta.iter())?,
    })
}

fn write_block<P: Precision>(
    writer: &mut SectionWriter<'_>,
    block: &QuantBlock<'_, P>,
) -> Result<BlockDesc, BlobError> {
    let ff = &block.feed_forward;
    let gelu = ff.fc1.activation.ok_or(BlobError::Encode)?;
    Ok(BlockDesc {
        norm1: write_norm(writer, &block.norm1)?,
        qkv: write_quantized(writer, &block.qkv)?,
        proj: write_quantized(writer, &block.proj)?,
        norm2: write_norm(writer, &block.norm2)?,
        fc1: write_linear::<P>(writer, ff.input, &ff.fc1.fc, &[])?,
        fc1_multipliers: writer.i32s(ff.fc1.requant.multipliers)?,
        fc1_shifts: writer.i32s(ff.fc1.requant.shifts)?,
        fc1_output_zero_point: ff.fc1.requant.output_zero_point,
        gelu: writer.ints([P::table_entries(gelu)].into_iter())?,
        fc2: write_quantized(writer, &ff.fc2)?,
    })
}

/// Lays out the sections of `parts` and returns the descriptor and its trailer.
fn emit<P: Precision>(
    parts: &TransformerBlobParts<'_, P>,
    writer: &mut SectionWriter<'_>,
) -> Result<(TransformerDescriptor, TransformerActivations), BlobError> {
    let tables = policy_tables::write(writer, &parts.config)?;
    let model = &parts.model;
    let noise_tokens = writer.f32s(parts.noise_tokens.iter())?;
    let positions = writer.f32s(model.positions.iter())?;
    let traj_in = write_input(writer, &model.traj_in)?;
    let cond_in = write_input(writer, &model.cond_in)?;
    let mut blocks = Vec::new();
    for block in model.blocks {
        let desc = write_block(writer, block)?;
        blocks.push(desc).map_err(|_| BlobError::TooLarge)?;
    }
    let final_norm = write_norm(writer, &model.final_norm)?;
    let head = write_quantized(writer, &model.head)?;
    let descriptor = TransformerDescriptor {
        header: PolicyHeader::of(&parts.config)?,
        width: small(model.shape.width)?,
        heads: small(model.shape.heads)?,
        tables,
        noise_tokens,
        positions,
        traj_in,
        cond_in,
        blocks,
        final_norm,
        head,
    };
    Ok((descriptor, TransformerActivations { bits: P::BITS }))
}

/// Exact length of the blob [`encode_transformer`] writes for `parts`.
pub fn transformer_encoded_len<P: Precision>(
    parts: &TransformerBlobParts<'_, P>,
) -> Result<usize, BlobError> {
    container::encoded_len(|writer| emit(parts, writer))
}

/// Writes the transformer blob of `parts` into the front of `out` and returns its length
/// ([`transformer_encoded_len`]). Fails with a named error if a size does not fit the format
/// (more than [`MAX_BLOCKS`] blocks, sizes beyond u32, f32 input layers); the loader checks
/// every shape.
pub fn encode_transformer<P: Precision>(
    parts: &TransformerBlobParts<'_, P>,
    out: &mut [u8],
) -> Result<usize, BlobError> {
    container::encode(TRANSFORMER_MAGIC, out, |writer| emit(parts, writer))
}

mod load;

pub use load::{
    transformer_activation_bits, LoadedQuantTransformer, LoadedTransformer, LoadedTransformer16,
};
