//! Transformer-lite blobs: the same header, CRC, postcard descriptor and aligned sections as the
//! MLP blob ([`super::format`]), with magic [`TRANSFORMER_MAGIC`] (`b"FRMT"`) and a
//! [`TransformerDescriptor`]. An MLP loader rejects a transformer blob (and vice versa) with
//! [`BlobError::BadMagic`].
//!
//! Section element types: norms, positions, noise tokens, output scales, ProDMP tables: f32;
//! weights and GELU tables: i8; biases, multipliers, shifts: i32; steps: u32 words as in the MLP
//! blob. The `first_layer_bias_index` of a step selects its noise token (`W` values).
//!
//! [`encode_transformer`] assembles a blob from a descriptor and an already laid out data area
//! (the exporter lays it out); [`LoadedTransformer::load`] validates a blob and borrows it.

use heapless::Vec;
use serde::{Deserialize, Serialize};

use super::format::{Section, HEADER_LEN};
use super::writer::{data_start, seal};
use super::BlobError;
use crate::policy::InputLayout;

mod load;

pub use load::{LoadedTransformer, TransformerBlocks};

/// First four bytes of a transformer blob.
pub const TRANSFORMER_MAGIC: [u8; 4] = *b"FRMT";
/// Most blocks a transformer blob can hold.
pub const MAX_BLOCKS: usize = 8;

/// Which array of a transformer part a section holds (for [`SectionId::Transformer`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TensorField {
    /// i8 weights.
    Weights,
    /// i32 bias.
    Bias,
    /// f32 dequantization scales.
    Scales,
    /// i32 Q31 multipliers.
    Multipliers,
    /// i32 shifts.
    Shifts,
    /// i8 256-entry GELU table.
    Lut,
    /// f32 LayerNorm gamma.
    Gamma,
    /// f32 LayerNorm beta.
    Beta,
    /// f32 values of positions or noise tokens.
    Values,
}

/// An int8 linear layer with f32 input and output ([`Int8Linear`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinearDesc {
    /// Input quantization scale.
    pub input_scale: f32,
    /// Input quantization zero point.
    pub input_zero_point: i32,
    /// i8 `[out, in]`.
    pub weights: Section,
    /// i32 `[out]`.
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

/// One block ([`Int8Block`]).
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
    /// Zero point of the requantized `fc1` output (GELU table input).
    pub fc1_output_zero_point: i32,
    /// i8 `[256]` GELU table.
    pub gelu: Section,
    /// `4W -> W`; its input parameters are the GELU output's.
    pub fc2: LinearDesc,
}

/// Everything about a transformer blob that is not bulk data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TransformerDescriptor {
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
    /// Model input layout (must be the standard order).
    pub layout: InputLayout,
    /// Token width `W`.
    pub width: u32,
    /// Attention heads.
    pub heads: u32,
    /// f32 `[min; O]` then `[max; O]`.
    pub obs_norm: Section,
    /// f32 `[min; K]` then `[max; K]`.
    pub action_norm: Section,
    /// f32 ProDMP tables (as the MLP blob).
    pub prodmp: Section,
    /// u32 `[steps][STEP_WORDS]`.
    pub steps: Section,
    /// f32 `[variants][W]` noise tokens.
    pub noise_tokens: Section,
    /// f32 `[N + 2][W]` positions.
    pub positions: Section,
    /// `k -> W`.
    pub traj_in: LinearDesc,
    /// `cond_dim -> W`.
    pub cond_in: LinearDesc,
    /// The blocks in order.
    pub blocks: Vec<BlockDesc, MAX_BLOCKS>,
    /// Final LayerNorm.
    pub final_norm: NormDesc,
    /// `(N + 2) W -> K P`.
    pub head: LinearDesc,
}

/// Length of the transformer blob for `descriptor` and a data area of `data_len` bytes.
pub fn transformer_encoded_len(
    descriptor: &TransformerDescriptor,
    data_len: usize,
) -> Result<usize, BlobError> {
    let desc_len =
        postcard::serialize_with_flavor(descriptor, postcard::ser_flavors::Size::default())
            .map_err(|_| BlobError::Encode)?;
    data_start(desc_len)
        .and_then(|start| start.checked_add(data_len))
        .ok_or(BlobError::TooLarge)
}

/// Writes a transformer blob into the front of `out`: header, `descriptor`, then `data` (the data
/// area, whose sections the descriptor names); returns its length
/// ([`transformer_encoded_len`]).
pub fn encode_transformer(
    descriptor: &TransformerDescriptor,
    data: &[u8],
    out: &mut [u8],
) -> Result<usize, BlobError> {
    let total = transformer_encoded_len(descriptor, data.len())?;
    let start = total.checked_sub(data.len()).ok_or(BlobError::TooLarge)?;
    let blob = out.get_mut(..total).ok_or(BlobError::BufferTooSmall)?;
    blob.fill(0);
    let desc_area = blob
        .get_mut(HEADER_LEN..start)
        .ok_or(BlobError::BufferTooSmall)?;
    let desc_len = postcard::to_slice(descriptor, desc_area)
        .map_err(|_| BlobError::Encode)?
        .len();
    blob.get_mut(start..)
        .ok_or(BlobError::BufferTooSmall)?
        .copy_from_slice(data);
    seal(blob, TRANSFORMER_MAGIC, desc_len)?;
    Ok(total)
}
