//! The parse side of transformer blobs: [`LoadedQuantTransformer`] ([`LoadedTransformer`] for
//! int8 activations, [`LoadedTransformer16`] for int16).

use heapless::Vec;

use super::{
    BlockDesc, LinearDesc, NormDesc, TensorField, TransformerActivations, TransformerDescriptor,
    TransformerSection, MAX_BLOCKS, TRANSFORMER_ACTIVATIONS_SINCE, TRANSFORMER_MAGIC,
};
use crate::blob::container::{self, Data};
use crate::blob::policy_tables::{self, PolicyTables};
use crate::blob::{BlobError, SectionId};
use crate::kernels::{FcRequant, FullyConnected, Precision};
use crate::model::linear::{Int8Linear, QuantizedLinear, RequantizedLinear};
use crate::model::transformer::{
    LayerNormWeights, Part, QuantBlock, QuantFeedForward, QuantTransformer, TokenLinear,
    TransformerError, TransformerShape,
};
use crate::policy::{
    InputLayout, PolicyConfig, PolicyDims, PolicyError, StepConstants, TransformerNetwork,
    TransformerWork, STANDARD_SEGMENTS,
};
use crate::quant::QuantParams;

/// A validated transformer blob, borrowed: weights, biases, requantization parameters, tables,
/// scales, norms, positions, noise tokens, normalization and decoder tables stay in the blob; the
/// steps are copied. `P` is the activation precision the loader takes: int8
/// ([`LoadedTransformer`]) or int16 ([`LoadedTransformer16`]); a blob of the other precision is
/// refused with [`BlobError::ActivationBits`] ([`crate::blob::LoadedBlob`] takes either).
///
/// ```text
/// let loaded = LoadedTransformer::load(BLOB)?;
/// let mut network = loaded.network(&mut SCRATCH)?;  // Int8TransformerNetwork
/// let mut policy = Policy::<_, 2, 20, 7, 12, 11, 160>::new(loaded.config(), network)?;
/// ```
#[derive(Clone, Debug)]
pub struct LoadedQuantTransformer<'a, P: Precision> {
    tables: PolicyTables<'a>,
    layout: InputLayout,
    shape: TransformerShape,
    noise_tokens: &'a [f32],
    positions: &'a [f32],
    traj_in: QuantizedLinear<'a, P>,
    cond_in: QuantizedLinear<'a, P>,
    blocks: Vec<QuantBlock<'a, P>, MAX_BLOCKS>,
    final_norm: LayerNormWeights<'a>,
    head: QuantizedLinear<'a, P>,
}

/// The loader of int8-activation transformer blobs.
pub type LoadedTransformer<'a> = LoadedQuantTransformer<'a, i8>;
/// The loader of int16-activation transformer blobs (the blob must start 8-byte aligned: its
/// biases are i64, read in place).
pub type LoadedTransformer16<'a> = LoadedQuantTransformer<'a, i16>;

/// Bits per activation of a transformer blob: its trailer's, or 8 for a blob older than format 5.
pub fn transformer_activation_bits(bytes: &[u8]) -> Result<u8, BlobError> {
    let (_, trailer, _) = parse(bytes, false)?;
    Ok(bits(trailer))
}

fn bits(trailer: Option<TransformerActivations>) -> u8 {
    trailer.map_or(8, |t| t.bits)
}

fn parse(
    bytes: &[u8],
    check_crc: bool,
) -> Result<
    (
        TransformerDescriptor,
        Option<TransformerActivations>,
        Data<'_>,
    ),
    BlobError,
> {
    container::parse_versioned::<TransformerDescriptor, TransformerActivations>(
        bytes,
        TRANSFORMER_MAGIC,
        check_crc,
        TRANSFORMER_ACTIVATIONS_SINCE,
    )
}

fn field(part: Part, field: TensorField) -> SectionId {
    TransformerSection { part, field }.into()
}

fn read_norm<'a>(
    data: &Data<'a>,
    d: &NormDesc,
    part: Part,
) -> Result<LayerNormWeights<'a>, BlobError> {
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
/// [`QuantTransformer::validate`] after loading (named by part).
fn read_linear<'a, P: Precision>(
    data: &Data<'a>,
    d: &LinearDesc,
    in_features: usize,
    part: Part,
) -> Result<QuantizedLinear<'a, P>, BlobError> {
    let weights = data.cast::<i8>(d.weights, field(part, TensorField::Weights))?;
    let bias = data.cast::<P::Acc>(d.bias, field(part, TensorField::Bias))?;
    let output_scales = data.finite_any(d.scales, field(part, TensorField::Scales))?;
    Ok(QuantizedLinear {
        input: quant_params(d.input_scale, d.input_zero_point, part)?,
        linear: Int8Linear {
            fc: FullyConnected::new(in_features, bias.len(), weights, bias),
            output_scales,
        },
    })
}

fn read_block<'a, P: Precision>(
    data: &Data<'a>,
    d: &BlockDesc,
    width: usize,
    layer: usize,
) -> Result<QuantBlock<'a, P>, BlobError> {
    let hidden = width.checked_mul(4).ok_or(BlobError::TooLarge)?;
    let fc1_part = Part::Fc1 { layer };
    let fc1 = read_linear::<P>(data, &d.fc1, width, fc1_part)?;
    if !fc1.linear.output_scales.is_empty() {
        return Err(BlobError::SectionLength(field(
            fc1_part,
            TensorField::Scales,
        )));
    }
    let fc2 = read_linear(data, &d.fc2, hidden, Part::Fc2 { layer })?;
    let lut = field(fc1_part, TensorField::Lut);
    let table = data.exact::<P>(d.gelu, Some(P::TABLE_LEN), lut)?;
    let gelu = P::table(table).ok_or(BlobError::SectionLength(lut))?;
    Ok(QuantBlock {
        norm1: read_norm(data, &d.norm1, Part::Norm1 { layer })?,
        qkv: read_linear(data, &d.qkv, width, Part::Qkv { layer })?,
        proj: read_linear(data, &d.proj, width, Part::Proj { layer })?,
        norm2: read_norm(data, &d.norm2, Part::Norm2 { layer })?,
        feed_forward: QuantFeedForward {
            input: fc1.input,
            fc1: RequantizedLinear {
                fc: fc1.linear.fc,
                requant: FcRequant {
                    multipliers: data.cast::<i32>(
                        d.fc1_multipliers,
                        field(fc1_part, TensorField::Multipliers),
                    )?,
                    shifts: data.cast::<i32>(d.fc1_shifts, field(fc1_part, TensorField::Shifts))?,
                    output_zero_point: d.fc1_output_zero_point,
                    activation_min: P::MIN,
                    activation_max: P::MAX,
                },
                activation: Some(gelu),
            },
            fc2,
        },
    })
}

impl<'a, P: Precision> LoadedQuantTransformer<'a, P> {
    /// Validates `bytes` (header, CRC, descriptor, activation bits, sections, shapes, values; the
    /// backbone by [`QuantTransformer::validate`], reported as [`BlobError::Transformer`]) and
    /// borrows it. The buffer must start at a 4-byte (int16: 8-byte) aligned address.
    pub fn load(bytes: &'a [u8]) -> Result<Self, BlobError> {
        Self::parse_checked(bytes, true)
    }

    /// [`Self::load`] without recomputing the CRC, for bytes that passed [`Self::load`] before;
    /// every other check runs.
    pub fn reload(bytes: &'a [u8]) -> Result<Self, BlobError> {
        Self::parse_checked(bytes, false)
    }

    fn parse_checked(bytes: &'a [u8], check_crc: bool) -> Result<Self, BlobError> {
        let (descriptor, trailer, data) = parse(bytes, check_crc)?;
        let found = bits(trailer);
        if found != P::BITS {
            return Err(BlobError::ActivationBits { found });
        }
        Self::view(&descriptor, &data)
    }

    fn view(d: &TransformerDescriptor, data: &Data<'a>) -> Result<Self, BlobError> {
        let tables = policy_tables::read(data, &d.header, &d.tables)?;
        d.header
            .layout
            .validate()
            .map_err(|_| BlobError::InputLayout)?;
        if d.header.layout.segments() != STANDARD_SEGMENTS {
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
        if d.header.layout.width_of(dims) != shape.cond_dim.checked_add(shape.trajectory_len()) {
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
            layout: d.header.layout,
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

    /// The quantized backbone with the first step's noise token (its blocks borrowed from
    /// `self`).
    pub fn model(&self) -> QuantTransformer<'_, P> {
        QuantTransformer {
            shape: self.shape,
            traj_in: TokenLinear::Quantized(self.traj_in),
            cond_in: TokenLinear::Quantized(self.cond_in),
            noise_token: self.noise_tokens.get(..self.shape.width).unwrap_or(&[]),
            positions: self.positions,
            blocks: &self.blocks,
            final_norm: self.final_norm,
            head: self.head,
        }
    }

    /// The policy network with per-step noise tokens, running in `scratch`.
    pub fn network<S: TransformerWork<P>>(
        &self,
        scratch: S,
    ) -> Result<TransformerNetwork<'_, QuantTransformer<'_, P>, S>, PolicyError> {
        TransformerNetwork::new(self.model(), &self.layout, self.noise_tokens, scratch)
    }

    /// The policy configuration (normalization, sampler) borrowing the blob.
    pub fn config(&self) -> PolicyConfig<'a> {
        self.tables.config(self.layout)
    }
}
