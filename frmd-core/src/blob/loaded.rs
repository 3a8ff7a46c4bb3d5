//! A blob of any format, told apart by its magic and its activation precision
//! ([`LoadedBlob`]), and the quantized network of any ([`BlobNetwork`]): what a program holds that
//! runs whatever student it is given (the host tools, a firmware that takes policy updates of any
//! backbone). A firmware built for one backbone and precision uses its loader ([`LoadedMlp`],
//! [`LoadedTransformer`]) directly.

use super::{
    activation_bits, transformer_activation_bits, BlobError, LoadedMlp, LoadedMlp16,
    LoadedTransformer, LoadedTransformer16, MLP_MAGIC, TRANSFORMER_MAGIC,
};
use crate::kernels::KernelError;
use crate::model::mlp::ModelError;
use crate::policy::{
    Int16MlpNetwork, Int16TransformerNetwork, Int8MlpNetwork, Int8TransformerNetwork, Network,
    PolicyConfig, PolicyDims, PolicyError, StepConstants, TransformerWork,
};

/// A checked blob of either format, borrowing its bytes.
// No allocator to box the larger variant: a program that takes either format reserves it.
#[allow(clippy::large_enum_variant)]
pub enum LoadedBlob<'a> {
    /// An MLP blob (magic [`MLP_MAGIC`]) with int8 activations.
    Mlp(LoadedMlp<'a>),
    /// An MLP blob with int16 activations.
    Mlp16(LoadedMlp16<'a>),
    /// A transformer blob (magic [`TRANSFORMER_MAGIC`]) with int8 activations.
    Transformer(LoadedTransformer<'a>),
    /// A transformer blob with int16 activations.
    Transformer16(LoadedTransformer16<'a>),
}

impl<'a> LoadedBlob<'a> {
    /// Checks and views `bytes` with the loader of the format its magic names;
    /// [`BlobError::BadMagic`] for any other magic, [`BlobError::Truncated`] below four bytes.
    pub fn load(bytes: &'a [u8]) -> Result<Self, BlobError> {
        match bytes.get(..4) {
            Some(magic) if magic == MLP_MAGIC => match activation_bits(bytes)? {
                16 => LoadedMlp16::load(bytes).map(Self::Mlp16),
                _ => LoadedMlp::load(bytes).map(Self::Mlp),
            },
            Some(magic) if magic == TRANSFORMER_MAGIC => {
                match transformer_activation_bits(bytes)? {
                    16 => LoadedTransformer16::load(bytes).map(Self::Transformer16),
                    _ => LoadedTransformer::load(bytes).map(Self::Transformer),
                }
            }
            Some(_) => Err(BlobError::BadMagic),
            None => Err(BlobError::Truncated),
        }
    }

    /// The policy's sizes.
    pub fn dims(&self) -> PolicyDims {
        match self {
            Self::Mlp(blob) => blob.dims(),
            Self::Mlp16(blob) => blob.dims(),
            Self::Transformer(blob) => blob.dims(),
            Self::Transformer16(blob) => blob.dims(),
        }
    }

    /// [`BlobError::DimensionMismatch`] unless the blob has the sizes `expected`.
    pub fn check_dims(&self, expected: &PolicyDims) -> Result<(), BlobError> {
        match self {
            Self::Mlp(blob) => blob.check_dims(expected),
            Self::Mlp16(blob) => blob.check_dims(expected),
            Self::Transformer(blob) => blob.check_dims(expected),
            Self::Transformer16(blob) => blob.check_dims(expected),
        }
    }

    /// The sampling step table.
    pub fn steps(&self) -> &[StepConstants] {
        match self {
            Self::Mlp(blob) => blob.steps(),
            Self::Mlp16(blob) => blob.steps(),
            Self::Transformer(blob) => blob.steps(),
            Self::Transformer16(blob) => blob.steps(),
        }
    }

    /// The policy configuration (normalization, sampler) borrowing the blob.
    pub fn config(&self) -> PolicyConfig<'a> {
        match self {
            Self::Mlp(blob) => blob.config(),
            Self::Mlp16(blob) => blob.config(),
            Self::Transformer(blob) => blob.config(),
            Self::Transformer16(blob) => blob.config(),
        }
    }

    /// The quantized network: an MLP with scratch for layers up to `WIDTH` wide, or a
    /// transformer running in `scratch` (unused by an MLP; it serves either code width).
    pub fn network<const WIDTH: usize, S: TransformerWork<i8> + TransformerWork<i16>>(
        &self,
        scratch: S,
    ) -> Result<BlobNetwork<'_, WIDTH, S>, PolicyError> {
        Ok(match self {
            Self::Mlp(blob) => BlobNetwork::Mlp(blob.network::<WIDTH>()?),
            Self::Mlp16(blob) => BlobNetwork::Mlp16(blob.network::<WIDTH>()?),
            Self::Transformer(blob) => BlobNetwork::Transformer(blob.network(scratch)?),
            Self::Transformer16(blob) => BlobNetwork::Transformer16(blob.network(scratch)?),
        })
    }

    /// Bits per activation code: 8 or 16.
    pub fn activation_bits(&self) -> u8 {
        match self {
            Self::Mlp(_) | Self::Transformer(_) => 8,
            Self::Mlp16(_) | Self::Transformer16(_) => 16,
        }
    }
}

/// The quantized network of a [`LoadedBlob`].
// As for `LoadedBlob`: the MLP network holds its scratch in place, no allocator to box it.
#[allow(clippy::large_enum_variant)]
pub enum BlobNetwork<'a, const WIDTH: usize, S> {
    /// The MLP of an int8-activation MLP blob.
    Mlp(Int8MlpNetwork<'a, WIDTH>),
    /// The MLP of an int16-activation MLP blob.
    Mlp16(Int16MlpNetwork<'a, WIDTH>),
    /// The transformer of an int8-activation transformer blob.
    Transformer(Int8TransformerNetwork<'a, S>),
    /// The transformer of an int16-activation transformer blob.
    Transformer16(Int16TransformerNetwork<'a, S>),
}

impl<'a, const WIDTH: usize, S> BlobNetwork<'a, WIDTH, S> {
    /// Bytes of the packed weights of an MLP ([`Int8MlpNetwork::packed_len`]); 0 for the
    /// transformers, which run their row-major weights.
    pub fn packed_len(&self) -> usize {
        match self {
            Self::Mlp(net) => net.packed_len(),
            Self::Mlp16(net) => net.packed_len(),
            _ => 0,
        }
    }

    /// Writes the packed weights ([`Int8MlpNetwork::pack_weights`]) into `out` of
    /// [`Self::packed_len`] bytes.
    pub fn pack_weights(&self, out: &mut [u8]) -> Result<(), PolicyError> {
        match self {
            Self::Mlp(net) => net.pack_weights(out),
            Self::Mlp16(net) => net.pack_weights(out),
            _ if out.is_empty() => Ok(()),
            _ => Err(PolicyError::Model(ModelError::Kernel(
                KernelError::OutputLength,
            ))),
        }
    }

    /// Runs the packed weights `bytes` from [`Self::pack_weights`], checked against the
    /// network's ([`Int8MlpNetwork::use_packed_weights`]); empty `bytes` change nothing.
    pub fn use_packed_weights(&mut self, bytes: &'a [u8]) -> Result<(), PolicyError> {
        match self {
            Self::Mlp(net) => net.use_packed_weights(bytes),
            Self::Mlp16(net) => net.use_packed_weights(bytes),
            _ if bytes.is_empty() => Ok(()),
            _ => Err(PolicyError::Model(ModelError::Kernel(
                KernelError::WeightsLength,
            ))),
        }
    }
}

impl<const WIDTH: usize, S> Network for BlobNetwork<'_, WIDTH, S>
where
    S: TransformerWork<i8> + TransformerWork<i16>,
{
    fn input_width(&self) -> usize {
        match self {
            Self::Mlp(net) => net.input_width(),
            Self::Mlp16(net) => net.input_width(),
            Self::Transformer(net) => net.input_width(),
            Self::Transformer16(net) => net.input_width(),
        }
    }

    fn output_width(&self) -> usize {
        match self {
            Self::Mlp(net) => net.output_width(),
            Self::Mlp16(net) => net.output_width(),
            Self::Transformer(net) => net.output_width(),
            Self::Transformer16(net) => net.output_width(),
        }
    }

    fn num_noise_variants(&self) -> usize {
        match self {
            Self::Mlp(net) => net.num_noise_variants(),
            Self::Mlp16(net) => net.num_noise_variants(),
            Self::Transformer(net) => net.num_noise_variants(),
            Self::Transformer16(net) => net.num_noise_variants(),
        }
    }

    fn forward(
        &mut self,
        variant: usize,
        input: &[f32],
        output: &mut [f32],
    ) -> Result<(), PolicyError> {
        match self {
            Self::Mlp(net) => net.forward(variant, input, output),
            Self::Mlp16(net) => net.forward(variant, input, output),
            Self::Transformer(net) => net.forward(variant, input, output),
            Self::Transformer16(net) => net.forward(variant, input, output),
        }
    }
}
