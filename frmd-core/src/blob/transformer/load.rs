//! Loader of transformer blobs: full validation, then a [`LoadedTransformer`] that borrows the
//! blob.

use super::super::format::{Section, SectionId, LUT_LEN};
use super::super::load::{parse_descriptor, shared_fields, Data, SharedFields, SharedTables};
use super::super::{BlobError, LoadedPolicy};
use super::{
    BlockDesc, LinearDesc, NormDesc, TensorField, TransformerDescriptor, MAX_BLOCKS,
    TRANSFORMER_MAGIC,
};
use crate::kernels::{FcRequant, FullyConnected, Lut8};
use crate::model::transformer::{
    Int8Block, Int8FeedForward, Int8Linear, Int8Transformer, LayerNormWeights, Part, TokenLinear,
    TransformerScratch, TransformerShape,
};
use crate::policy::{
    InputLayout, Int8TransformerNetwork, PolicyConfig, PolicyError, StepConstants,
};
use crate::quant::QuantParams;

/// Per-block data borrowed from the blob; the GELU table is copied into [`LoadedTransformer`].
#[derive(Clone, Copy, Debug)]
struct BlockData<'a> {
    norm1: LayerNormWeights<'a>,
    qkv: Int8Linear<'a>,
    proj: Int8Linear<'a>,
    norm2: LayerNormWeights<'a>,
    fc1_input: QuantParams,
    fc1: FullyConnected<'a>,
    fc1_requant: FcRequant<'a>,
    fc2: FullyConnected<'a>,
    fc2_scales: &'a [f32],
}

const EMPTY_NORM: LayerNormWeights<'static> = LayerNormWeights {
    gamma: &[],
    beta: &[],
};
const EMPTY_LINEAR: Int8Linear<'static> = Int8Linear {
    input: QuantParams {
        scale: 1.0,
        zero_point: 0,
    },
    fc: FullyConnected::new(0, 0, &[], &[]),
    output_scales: &[],
};
const EMPTY_BLOCK: BlockData<'static> = BlockData {
    norm1: EMPTY_NORM,
    qkv: EMPTY_LINEAR,
    proj: EMPTY_LINEAR,
    norm2: EMPTY_NORM,
    fc1_input: EMPTY_LINEAR.input,
    fc1: FullyConnected::new(0, 0, &[], &[]),
    fc1_requant: FcRequant {
        multipliers: &[],
        shifts: &[],
        output_zero_point: 0,
        activation_min: i8::MIN,
        activation_max: i8::MAX,
    },
    fc2: FullyConnected::new(0, 0, &[], &[]),
    fc2_scales: &[],
};
static ZERO_LUT: Lut8 = Lut8::from_table([0; LUT_LEN]);

/// The blocks of a [`LoadedTransformer`] as frmd-core [`Int8Block`]s (see
/// [`LoadedTransformer::blocks`]).
#[derive(Clone, Copy, Debug)]
pub struct TransformerBlocks<'b> {
    blocks: [Int8Block<'b>; MAX_BLOCKS],
    count: usize,
}

impl<'b> TransformerBlocks<'b> {
    /// The blocks in order.
    pub fn as_slice(&self) -> &[Int8Block<'b>] {
        self.blocks.get(..self.count).unwrap_or(&[])
    }
}

/// A validated transformer blob with dimensions `M, O, K, N, P` (checked against the
/// descriptor). Weights, biases, requantization parameters, scales, norms, positions and noise
/// tokens stay in the blob; normalization, ProDMP tables, steps and GELU tables are copied.
///
/// ```text
/// let loaded = LoadedTransformer::<2, 20, 7, 12, 11>::load(BLOB)?;
/// let blocks = loaded.blocks();
/// let mut network = loaded.network(&blocks, &mut SCRATCH)?;  // Int8TransformerNetwork
/// let mut policy = Policy::<_, 2, 20, 7, 12, 11, 160>::new(loaded.config(), network)?;
/// ```
#[derive(Clone, Debug)]
pub struct LoadedTransformer<
    'a,
    const M: usize,
    const O: usize,
    const K: usize,
    const N: usize,
    const P: usize,
> {
    shared: SharedTables<O, K, N, P>,
    layout: InputLayout,
    control_dt: f32,
    shape: TransformerShape,
    noise_tokens: &'a [f32],
    positions: &'a [f32],
    traj_in: Int8Linear<'a>,
    cond_in: Int8Linear<'a>,
    blocks: [BlockData<'a>; MAX_BLOCKS],
    luts: [Lut8; MAX_BLOCKS],
    final_norm: LayerNormWeights<'a>,
    head: Int8Linear<'a>,
}

fn field(part: Part, field: TensorField) -> SectionId {
    SectionId::Transformer { part, field }
}

/// f32 section of any length, all finite.
fn finite_any<'a>(
    data: &Data<'a>,
    section: Section,
    id: SectionId,
) -> Result<&'a [f32], BlobError> {
    let values = data.cast::<f32>(section, id)?;
    if values.iter().all(|v| v.is_finite()) {
        Ok(values)
    } else {
        Err(BlobError::NonFinite(id))
    }
}

fn read_norm<'a>(
    data: &Data<'a>,
    d: &NormDesc,
    part: Part,
) -> Result<LayerNormWeights<'a>, BlobError> {
    Ok(LayerNormWeights {
        gamma: finite_any(data, d.gamma, field(part, TensorField::Gamma))?,
        beta: finite_any(data, d.beta, field(part, TensorField::Beta))?,
    })
}

fn quant_params(scale: f32, zero_point: i32, part: Part) -> Result<QuantParams, BlobError> {
    QuantParams::new(scale, zero_point).map_err(|_| {
        BlobError::Transformer(crate::model::transformer::TransformerError::InputParams { part })
    })
}

/// Reads a linear layer; lengths are checked against the shape by
/// [`Int8Transformer::validate`] after loading (named by part).
fn read_linear<'a>(
    data: &Data<'a>,
    d: &LinearDesc,
    in_features: usize,
    part: Part,
) -> Result<Int8Linear<'a>, BlobError> {
    let weights = data.cast::<i8>(d.weights, field(part, TensorField::Weights))?;
    let bias = data.cast::<i32>(d.bias, field(part, TensorField::Bias))?;
    let output_scales = finite_any(data, d.scales, field(part, TensorField::Scales))?;
    Ok(Int8Linear {
        input: quant_params(d.input_scale, d.input_zero_point, part)?,
        fc: FullyConnected::new(in_features, bias.len(), weights, bias),
        output_scales,
    })
}

fn read_block<'a>(
    data: &Data<'a>,
    d: &BlockDesc,
    width: usize,
    layer: usize,
) -> Result<(BlockData<'a>, Lut8), BlobError> {
    let hidden = width.checked_mul(4).ok_or(BlobError::TooLarge)?;
    let fc1_part = Part::Fc1 { layer };
    let fc1 = read_linear(data, &d.fc1, width, fc1_part)?;
    if !fc1.output_scales.is_empty() {
        return Err(BlobError::SectionLength(field(
            fc1_part,
            TensorField::Scales,
        )));
    }
    let fc2 = read_linear(data, &d.fc2, hidden, Part::Fc2 { layer })?;
    let table = data.exact::<i8>(d.gelu, Some(LUT_LEN), field(fc1_part, TensorField::Lut))?;
    let mut lut = Lut8::from_table([0; LUT_LEN]);
    for (slot, value) in lut.table.iter_mut().zip(table) {
        *slot = *value;
    }
    let block = BlockData {
        norm1: read_norm(data, &d.norm1, Part::Norm1 { layer })?,
        qkv: read_linear(data, &d.qkv, width, Part::Qkv { layer })?,
        proj: read_linear(data, &d.proj, width, Part::Proj { layer })?,
        norm2: read_norm(data, &d.norm2, Part::Norm2 { layer })?,
        fc1_input: fc1.input,
        fc1: fc1.fc,
        fc1_requant: FcRequant {
            multipliers: data
                .cast::<i32>(d.fc1_multipliers, field(fc1_part, TensorField::Multipliers))?,
            shifts: data.cast::<i32>(d.fc1_shifts, field(fc1_part, TensorField::Shifts))?,
            output_zero_point: d.fc1_output_zero_point,
            activation_min: i8::MIN,
            activation_max: i8::MAX,
        },
        fc2: fc2.fc,
        fc2_scales: fc2.output_scales,
    };
    Ok((block, lut))
}

impl<'a, const M: usize, const O: usize, const K: usize, const N: usize, const P: usize>
    LoadedTransformer<'a, M, O, K, N, P>
{
    /// Validates `bytes` (header, CRC, descriptor, sections, shapes, values; the backbone by
    /// [`Int8Transformer::validate`], reported as [`BlobError::Transformer`]) and borrows it.
    /// The buffer must start at a 4-byte aligned address.
    pub fn load(bytes: &'a [u8]) -> Result<Self, BlobError> {
        let (d, data) = parse_descriptor::<TransformerDescriptor>(bytes, TRANSFORMER_MAGIC)?;
        let shared = LoadedPolicy::<M, O, K, N, P>::read_shared(&data, shared_fields!(d))?;
        d.layout.validate().map_err(|_| BlobError::InputLayout)?;
        if d.layout.segments() != crate::policy::STANDARD_SEGMENTS {
            return Err(BlobError::InputLayout);
        }

        let cond_dim = M
            .checked_mul(O)
            .and_then(|obs| obs.checked_add(K.checked_mul(2)?))
            .ok_or(BlobError::TooLarge)?;
        let shape = TransformerShape {
            horizon: N,
            action_dim: K,
            cond_dim,
            width: d.width as usize,
            heads: d.heads as usize,
            layers: d.blocks.len(),
            output: K.checked_mul(P).ok_or(BlobError::TooLarge)?,
        };
        shape.validate().map_err(BlobError::Transformer)?;
        if d.layout.width(M, O, K, N) != shape.cond_dim.checked_add(shape.trajectory_len()) {
            return Err(BlobError::InputLayout);
        }
        let width = shape.width;
        let noise_tokens = finite_any(
            &data,
            d.noise_tokens,
            field(Part::NoiseToken, TensorField::Values),
        )?;
        let variants = noise_tokens
            .len()
            .checked_div(width)
            .filter(|n| *n > 0 && noise_tokens.len().is_multiple_of(width))
            .ok_or(BlobError::SectionLength(field(
                Part::NoiseToken,
                TensorField::Values,
            )))?;
        let active = shared.steps();
        if active
            .iter()
            .any(|s| s.first_layer_bias_index as usize >= variants)
        {
            return Err(BlobError::Steps);
        }
        let positions = data.finite(
            d.positions,
            shape.tokens().checked_mul(width),
            field(Part::Positions, TensorField::Values),
        )?;
        let mut blocks = [EMPTY_BLOCK; MAX_BLOCKS];
        let mut luts = [Lut8::from_table([0; LUT_LEN]); MAX_BLOCKS];
        for (layer, ((desc, block), lut)) in d
            .blocks
            .iter()
            .zip(blocks.iter_mut())
            .zip(luts.iter_mut())
            .enumerate()
        {
            (*block, *lut) = read_block(&data, desc, width, layer)?;
        }
        let loaded = Self {
            shared,
            layout: d.layout,
            control_dt: d.control_dt,
            shape,
            noise_tokens,
            positions,
            traj_in: read_linear(&data, &d.traj_in, K, Part::TrajIn)?,
            cond_in: read_linear(&data, &d.cond_in, cond_dim, Part::CondIn)?,
            blocks,
            luts,
            final_norm: read_norm(&data, &d.final_norm, Part::FinalNorm)?,
            head: read_linear(&data, &d.head, shape.token_values(), Part::Head)?,
        };
        let blocks = loaded.blocks();
        loaded
            .model(&blocks)
            .validate()
            .map_err(BlobError::Transformer)?;
        Ok(loaded)
    }

    /// The backbone's sizes.
    pub fn shape(&self) -> &TransformerShape {
        &self.shape
    }

    /// The step table.
    pub fn steps(&self) -> &[StepConstants] {
        self.shared.steps()
    }

    /// The per-step noise tokens, `W` values each.
    pub fn noise_tokens(&self) -> &'a [f32] {
        self.noise_tokens
    }

    /// The blocks as frmd-core [`Int8Block`]s (GELU tables borrowed from `self`).
    pub fn blocks(&self) -> TransformerBlocks<'_> {
        let mut out = TransformerBlocks {
            blocks: [Int8Block {
                norm1: EMPTY_NORM,
                qkv: EMPTY_LINEAR,
                proj: EMPTY_LINEAR,
                norm2: EMPTY_NORM,
                feed_forward: Int8FeedForward {
                    input: EMPTY_LINEAR.input,
                    fc1: EMPTY_BLOCK.fc1,
                    fc1_requant: EMPTY_BLOCK.fc1_requant,
                    gelu: &ZERO_LUT,
                    fc2: EMPTY_BLOCK.fc2,
                    fc2_scales: &[],
                },
            }; MAX_BLOCKS],
            count: self.shape.layers,
        };
        for ((slot, block), lut) in out.blocks.iter_mut().zip(&self.blocks).zip(&self.luts) {
            *slot = Int8Block {
                norm1: block.norm1,
                qkv: block.qkv,
                proj: block.proj,
                norm2: block.norm2,
                feed_forward: Int8FeedForward {
                    input: block.fc1_input,
                    fc1: block.fc1,
                    fc1_requant: block.fc1_requant,
                    gelu: lut,
                    fc2: block.fc2,
                    fc2_scales: block.fc2_scales,
                },
            };
        }
        out
    }

    /// The int8 backbone with the first step's noise token, over `blocks` ([`Self::blocks`]).
    pub fn model<'b>(&'b self, blocks: &'b TransformerBlocks<'b>) -> Int8Transformer<'b> {
        Int8Transformer {
            shape: self.shape,
            traj_in: TokenLinear::Int8(self.traj_in),
            cond_in: TokenLinear::Int8(self.cond_in),
            noise_token: self.noise_tokens.get(..self.shape.width).unwrap_or(&[]),
            positions: self.positions,
            blocks: blocks.as_slice(),
            final_norm: self.final_norm,
            head: self.head,
        }
    }

    /// The policy network over `blocks` ([`Self::blocks`]) with per-step noise tokens.
    pub fn network<'b, const F: usize, const B: usize, const A: usize>(
        &'b self,
        blocks: &'b TransformerBlocks<'b>,
        scratch: &'b mut TransformerScratch<F, B, A>,
    ) -> Result<Int8TransformerNetwork<'b, F, B, A>, PolicyError> {
        Int8TransformerNetwork::new(self.model(blocks), &self.layout, self.noise_tokens, scratch)
    }

    /// The policy configuration (normalization, sampler) borrowing this blob.
    pub fn config(&self) -> PolicyConfig<'_, O, K, N, P> {
        self.shared.config(self.layout, self.control_dt)
    }
}
