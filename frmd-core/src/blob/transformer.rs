//! Transformer-lite blobs (magic [`TRANSFORMER_MAGIC`], `b"FRMT"`): the
//! [`TransformerDescriptor`], its emit side ([`encode_transformer`] from borrowed
//! [`TransformerBlobParts`]) and its parse side ([`LoadedTransformer`]). An MLP loader rejects a
//! transformer blob (and vice versa) with [`BlobError::BadMagic`].
//!
//! Data area, in order: the policy sections ([`super::policy_tables`]), the noise tokens (f32
//! `[variants][W]`; a step's `noise_variant` selects its token), the positions, `traj_in`,
//! `cond_in`, per block `norm1`, `qkv`, `proj`, `norm2`, `fc1` (with its multipliers, shifts and
//! GELU table), `fc2`, then `final_norm` and `head`. Element types: norms, positions, tokens,
//! scales f32; weights and tables i8; biases, multipliers, shifts i32. The data area ends with its
//! last section.

use heapless::Vec;
use serde::{Deserialize, Serialize};

use super::container::{self, Data, Section, SectionId, SectionWriter};
use super::mlp::LUT_LEN;
use super::policy_tables::{self, PolicyFields, PolicySections, PolicyTables};
use super::BlobError;
use crate::kernels::{FcRequant, FullyConnected};
use crate::model::linear::{Int8Linear, QuantizedLinear, RequantizedLinear};
use crate::model::transformer::{
    Int8Block, Int8FeedForward, Int8Transformer, LayerNormWeights, Part, TokenLinear,
    TransformerError, TransformerShape,
};
use crate::policy::{
    InputLayout, Int8TransformerNetwork, PolicyConfig, PolicyDims, PolicyError, StepConstants,
    TransformerWork, STANDARD_SEGMENTS,
};
use crate::quant::QuantParams;

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

/// A linear layer with f32 input and output ([`QuantizedLinear`]).
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
    /// Observation history length `m`.
    pub history: u32,
    /// Observation dimension `o`.
    pub obs_dim: u32,
    /// Action dimension `k`.
    pub action_dim: u32,
    /// Horizon `n`.
    pub horizon: u32,
    /// ProDMP parameters per DoF `p`.
    pub params_per_dof: u32,
    /// Control period, seconds.
    pub control_dt: f32,
    /// Model input layout (must be the standard order).
    pub layout: InputLayout,
    /// Token width `W`.
    pub width: u32,
    /// Attention heads.
    pub heads: u32,
    /// f32 `[min; o]` then `[max; o]`.
    pub obs_norm: Section,
    /// f32 `[min; k]` then `[max; k]`.
    pub action_norm: Section,
    /// f32 ProDMP tables (as the MLP blob).
    pub prodmp: Section,
    /// u32 `[steps][STEP_WORDS]`.
    pub steps: Section,
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

/// Everything a transformer blob holds, borrowed.
#[derive(Clone, Copy, Debug)]
pub struct TransformerBlobParts<'p> {
    /// Normalization, steps, decoder tables, layout, control period.
    pub config: PolicyConfig<'p>,
    /// The int8 backbone (`traj_in` and `cond_in` int8).
    pub model: Int8Transformer<'p>,
    /// The per-step noise tokens, `W` values each, back to back.
    pub noise_tokens: &'p [f32],
}

fn small(value: usize) -> Result<u32, BlobError> {
    u32::try_from(value).map_err(|_| BlobError::TooLarge)
}

fn write_linear(
    writer: &mut SectionWriter<'_>,
    input: QuantParams,
    fc: &FullyConnected<'_>,
    scales: &[f32],
) -> Result<LinearDesc, BlobError> {
    Ok(LinearDesc {
        input_scale: input.scale,
        input_zero_point: input.zero_point,
        weights: writer.i8s(fc.weights.iter())?,
        bias: writer.i32s(fc.bias)?,
        scales: writer.f32s(scales.iter())?,
    })
}

fn write_quantized(
    writer: &mut SectionWriter<'_>,
    layer: &QuantizedLinear<'_>,
) -> Result<LinearDesc, BlobError> {
    write_linear(writer, layer.input, &layer.linear.fc, layer.linear.output_scales)
}

fn write_input(writer: &mut SectionWriter<'_>, layer: &TokenLinear<'_>) -> Result<LinearDesc, BlobError> {
    match layer {
        TokenLinear::Int8(layer) => write_quantized(writer, layer),
        // The format holds int8 input layers only.
        TokenLinear::Float(_) => Err(BlobError::Encode),
    }
}

fn write_norm(writer: &mut SectionWriter<'_>, norm: &LayerNormWeights<'_>) -> Result<NormDesc, BlobError> {
    Ok(NormDesc {
        gamma: writer.f32s(norm.gamma.iter())?,
        beta: writer.f32s(norm.beta.iter())?,
    })
}

fn write_block(writer: &mut SectionWriter<'_>, block: &Int8Block<'_>) -> Result<BlockDesc, BlobError> {
    let ff = &block.feed_forward;
    let gelu = ff.fc1.activation.ok_or(BlobError::Encode)?;
    Ok(BlockDesc {
        norm1: write_norm(writer, &block.norm1)?,
        qkv: write_quantized(writer, &block.qkv)?,
        proj: write_quantized(writer, &block.proj)?,
        norm2: write_norm(writer, &block.norm2)?,
        fc1: write_linear(writer, ff.input, &ff.fc1.fc, &[])?,
        fc1_multipliers: writer.i32s(ff.fc1.requant.multipliers)?,
        fc1_shifts: writer.i32s(ff.fc1.requant.shifts)?,
        fc1_output_zero_point: ff.fc1.requant.output_zero_point,
        gelu: writer.i8s(gelu.iter())?,
        fc2: write_quantized(writer, &ff.fc2)?,
    })
}

/// Lays out the sections of `parts` and returns the descriptor.
fn emit(
    parts: &TransformerBlobParts<'_>,
    writer: &mut SectionWriter<'_>,
) -> Result<TransformerDescriptor, BlobError> {
    let PolicySections {
        obs_norm,
        action_norm,
        prodmp,
        steps,
    } = policy_tables::write(writer, &parts.config)?;
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
    let dims = parts.config.dims();
    Ok(TransformerDescriptor {
        history: small(dims.history)?,
        obs_dim: small(dims.obs_dim)?,
        action_dim: small(dims.action_dim)?,
        horizon: small(dims.horizon)?,
        params_per_dof: small(dims.params_per_dof)?,
        control_dt: parts.config.sampler.control_dt,
        layout: parts.config.sampler.layout,
        width: small(model.shape.width)?,
        heads: small(model.shape.heads)?,
        obs_norm,
        action_norm,
        prodmp,
        steps,
        noise_tokens,
        positions,
        traj_in,
        cond_in,
        blocks,
        final_norm,
        head,
    })
}

/// Exact length of the blob [`encode_transformer`] writes for `parts`.
pub fn transformer_encoded_len(parts: &TransformerBlobParts<'_>) -> Result<usize, BlobError> {
    container::encoded_len(|writer| emit(parts, writer))
}

/// Writes the transformer blob of `parts` into the front of `out` and returns its length
/// ([`transformer_encoded_len`]). Fails with a named error if a size does not fit the format
/// (more than [`MAX_BLOCKS`] blocks, sizes beyond u32, f32 input layers); the loader checks
/// every shape.
pub fn encode_transformer(parts: &TransformerBlobParts<'_>, out: &mut [u8]) -> Result<usize, BlobError> {
    container::encode(TRANSFORMER_MAGIC, out, |writer| emit(parts, writer))
}

/// A validated transformer blob, borrowed: weights, biases, requantization parameters, tables,
/// scales, norms, positions, noise tokens, normalization and decoder tables stay in the blob; the
/// steps are copied.
///
/// ```text
/// let loaded = LoadedTransformer::load(BLOB)?;
/// let mut network = loaded.network(&mut SCRATCH)?;  // Int8TransformerNetwork
/// let mut policy = Policy::<_, 2, 20, 7, 12, 11, 160>::new(loaded.config(), network)?;
/// ```
#[derive(Clone, Debug)]
pub struct LoadedTransformer<'a> {
    tables: PolicyTables<'a>,
    layout: InputLayout,
    shape: TransformerShape,
    noise_tokens: &'a [f32],
    positions: &'a [f32],
    traj_in: QuantizedLinear<'a>,
    cond_in: QuantizedLinear<'a>,
    blocks: Vec<Int8Block<'a>, MAX_BLOCKS>,
    final_norm: LayerNormWeights<'a>,
    head: QuantizedLinear<'a>,
}

fn field(part: Part, field: TensorField) -> SectionId {
    SectionId::Transformer { part, field }
}

fn read_norm<'a>(data: &Data<'a>, d: &NormDesc, part: Part) -> Result<LayerNormWeights<'a>, BlobError> {
    Ok(LayerNormWeights {
        gamma: data.finite_any(d.gamma, field(part, TensorField::Gamma))?,
        beta: data.finite_any(d.beta, field(part, TensorField::Beta))?,
    })
}

fn quant_params(scale: f32, zero_point: i32, part: Part) -> Result<QuantParams, BlobError> {
    QuantParams::new(scale, zero_point)
        .map_err(|_| BlobError::Transformer(TransformerError::InputParams { part }))
}

/// Reads a linear layer; lengths are checked against the shape by
/// [`Int8Transformer::validate`] after loading (named by part).
fn read_linear<'a>(
    data: &Data<'a>,
    d: &LinearDesc,
    in_features: usize,
    part: Part,
) -> Result<QuantizedLinear<'a>, BlobError> {
    let weights = data.cast::<i8>(d.weights, field(part, TensorField::Weights))?;
    let bias = data.cast::<i32>(d.bias, field(part, TensorField::Bias))?;
    let output_scales = data.finite_any(d.scales, field(part, TensorField::Scales))?;
    Ok(QuantizedLinear {
        input: quant_params(d.input_scale, d.input_zero_point, part)?,
        linear: Int8Linear {
            fc: FullyConnected::new(in_features, bias.len(), weights, bias),
            output_scales,
        },
    })
}

fn read_block<'a>(
    data: &Data<'a>,
    d: &BlockDesc,
    width: usize,
    layer: usize,
) -> Result<Int8Block<'a>, BlobError> {
    let hidden = width.checked_mul(4).ok_or(BlobError::TooLarge)?;
    let fc1_part = Part::Fc1 { layer };
    let fc1 = read_linear(data, &d.fc1, width, fc1_part)?;
    if !fc1.linear.output_scales.is_empty() {
        return Err(BlobError::SectionLength(field(fc1_part, TensorField::Scales)));
    }
    let fc2 = read_linear(data, &d.fc2, hidden, Part::Fc2 { layer })?;
    let table = data.exact::<i8>(d.gelu, Some(LUT_LEN), field(fc1_part, TensorField::Lut))?;
    let gelu = table
        .try_into()
        .map_err(|_| BlobError::SectionLength(field(fc1_part, TensorField::Lut)))?;
    Ok(Int8Block {
        norm1: read_norm(data, &d.norm1, Part::Norm1 { layer })?,
        qkv: read_linear(data, &d.qkv, width, Part::Qkv { layer })?,
        proj: read_linear(data, &d.proj, width, Part::Proj { layer })?,
        norm2: read_norm(data, &d.norm2, Part::Norm2 { layer })?,
        feed_forward: Int8FeedForward {
            input: fc1.input,
            fc1: RequantizedLinear {
                fc: fc1.linear.fc,
                requant: FcRequant {
                    multipliers: data
                        .cast::<i32>(d.fc1_multipliers, field(fc1_part, TensorField::Multipliers))?,
                    shifts: data.cast::<i32>(d.fc1_shifts, field(fc1_part, TensorField::Shifts))?,
                    output_zero_point: d.fc1_output_zero_point,
                    activation_min: i8::MIN,
                    activation_max: i8::MAX,
                },
                activation: Some(gelu),
            },
            fc2,
        },
    })
}

impl<'a> LoadedTransformer<'a> {
    /// Validates `bytes` (header, CRC, descriptor, sections, shapes, values; the backbone by
    /// [`Int8Transformer::validate`], reported as [`BlobError::Transformer`]) and borrows it.
    /// The buffer must start at a 4-byte aligned address.
    pub fn load(bytes: &'a [u8]) -> Result<Self, BlobError> {
        let (descriptor, data) =
            container::parse::<TransformerDescriptor>(bytes, TRANSFORMER_MAGIC, true)?;
        Self::view(&descriptor, &data)
    }

    /// [`Self::load`] without recomputing the CRC, for bytes that passed [`Self::load`] before;
    /// every other check runs.
    pub fn reload(bytes: &'a [u8]) -> Result<Self, BlobError> {
        let (descriptor, data) =
            container::parse::<TransformerDescriptor>(bytes, TRANSFORMER_MAGIC, false)?;
        Self::view(&descriptor, &data)
    }

    fn view(d: &TransformerDescriptor, data: &Data<'a>) -> Result<Self, BlobError> {
        let fields = PolicyFields {
            dims: [d.history, d.obs_dim, d.action_dim, d.horizon, d.params_per_dof],
            control_dt: d.control_dt,
            sections: PolicySections {
                obs_norm: d.obs_norm,
                action_norm: d.action_norm,
                prodmp: d.prodmp,
                steps: d.steps,
            },
        };
        let tables = policy_tables::read(data, fields)?;
        d.layout.validate().map_err(|_| BlobError::InputLayout)?;
        if d.layout.segments() != STANDARD_SEGMENTS {
            return Err(BlobError::InputLayout);
        }
        let dims = &tables.dims;
        let cond_dim = dims
            .history_len()
            .and_then(|obs| obs.checked_add(dims.action_dim.checked_mul(2)?))
            .ok_or(BlobError::TooLarge)?;
        let shape = TransformerShape {
            horizon: dims.horizon,
            action_dim: dims.action_dim,
            cond_dim,
            width: d.width as usize,
            heads: d.heads as usize,
            layers: d.blocks.len(),
            output: dims.params_len().ok_or(BlobError::TooLarge)?,
        };
        shape.validate().map_err(BlobError::Transformer)?;
        if d.layout.width_of(dims) != shape.cond_dim.checked_add(shape.trajectory_len()) {
            return Err(BlobError::InputLayout);
        }
        let width = shape.width;
        let tokens_id = field(Part::NoiseToken, TensorField::Values);
        let noise_tokens = data.finite_any(d.noise_tokens, tokens_id)?;
        let variants = noise_tokens
            .len()
            .checked_div(width)
            .filter(|n| *n > 0 && noise_tokens.len().is_multiple_of(width))
            .ok_or(BlobError::SectionLength(tokens_id))?;
        policy_tables::check_variants(&tables.steps, variants)?;
        let positions = data.finite(
            d.positions,
            shape.tokens().checked_mul(width),
            field(Part::Positions, TensorField::Values),
        )?;
        let mut blocks = Vec::new();
        for (layer, desc) in d.blocks.iter().enumerate() {
            let block = read_block(data, desc, width, layer)?;
            blocks.push(block).map_err(|_| BlobError::TooLarge)?;
        }
        let loaded = Self {
            tables,
            layout: d.layout,
            shape,
            noise_tokens,
            positions,
            traj_in: read_linear(data, &d.traj_in, dims.action_dim, Part::TrajIn)?,
            cond_in: read_linear(data, &d.cond_in, cond_dim, Part::CondIn)?,
            blocks,
            final_norm: read_norm(data, &d.final_norm, Part::FinalNorm)?,
            head: read_linear(data, &d.head, shape.token_values(), Part::Head)?,
        };
        loaded.model().validate().map_err(BlobError::Transformer)?;
        Ok(loaded)
    }

    /// The blob's sizes.
    pub fn dims(&self) -> PolicyDims {
        self.tables.dims
    }

    /// [`BlobError::DimensionMismatch`] unless the blob has the sizes `expected`.
    pub fn check_dims(&self, expected: &PolicyDims) -> Result<(), BlobError> {
        self.tables.check_dims(expected)
    }

    /// The backbone's sizes.
    pub fn shape(&self) -> &TransformerShape {
        &self.shape
    }

    /// The step table.
    pub fn steps(&self) -> &[StepConstants] {
        self.tables.steps.as_slice()
    }

    /// The per-step noise tokens, `W` values each.
    pub fn noise_tokens(&self) -> &'a [f32] {
        self.noise_tokens
    }

    /// The int8 backbone with the first step's noise token (its blocks borrowed from `self`).
    pub fn model(&self) -> Int8Transformer<'_> {
        Int8Transformer {
            shape: self.shape,
            traj_in: TokenLinear::Int8(self.traj_in),
            cond_in: TokenLinear::Int8(self.cond_in),
            noise_token: self.noise_tokens.get(..self.shape.width).unwrap_or(&[]),
            positions: self.positions,
            blocks: &self.blocks,
            final_norm: self.final_norm,
            head: self.head,
        }
    }

    /// The policy network with per-step noise tokens, running in `scratch`.
    pub fn network<S: TransformerWork>(
        &self,
        scratch: S,
    ) -> Result<Int8TransformerNetwork<'_, S>, PolicyError> {
        Int8TransformerNetwork::new(self.model(), &self.layout, self.noise_tokens, scratch)
    }

    /// The policy configuration (normalization, sampler) borrowing the blob.
    pub fn config(&self) -> PolicyConfig<'a> {
        self.tables.config(self.layout)
    }
}
