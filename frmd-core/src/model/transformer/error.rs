//! Errors of the transformer forward passes: which part of the model or which argument is wrong.

#[cfg(doc)]
use super::{fold_noise_token, TransformerShape};
use crate::kernels::KernelError;

/// A named tensor group of the backbone (used in errors). `layer` is the 0-based block index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Part {
    /// The per-step trajectory input layer (`k -> W`).
    TrajIn,
    /// The condition input layer (`cond_dim -> W`).
    CondIn,
    /// The noise-embedding layer (`embed_dim -> W`) of [`fold_noise_token`].
    NoiseIn,
    /// The folded noise token row (`W`).
    NoiseToken,
    /// The learned positions (`T W`).
    Positions,
    /// First LayerNorm of a block.
    Norm1 {
        /// Block index.
        layer: usize,
    },
    /// Fused query/key/value layer (`W -> 3W`).
    Qkv {
        /// Block index.
        layer: usize,
    },
    /// Attention output projection (`W -> W`).
    Proj {
        /// Block index.
        layer: usize,
    },
    /// Second LayerNorm of a block.
    Norm2 {
        /// Block index.
        layer: usize,
    },
    /// Feed-forward expansion (`W -> 4W`).
    Fc1 {
        /// Block index.
        layer: usize,
    },
    /// Feed-forward contraction (`4W -> W`).
    Fc2 {
        /// Block index.
        layer: usize,
    },
    /// The final LayerNorm.
    FinalNorm,
    /// The output layer (`T W -> output`).
    Head,
}

/// Which scratch buffer is too small.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ScratchBuffer {
    /// The f32 buffer.
    Floats,
    /// The activation-code buffer (int8 or int16).
    Codes,
    /// The accumulator buffer (int32 or int64).
    Accumulators,
}

/// Why a transformer forward pass refused its arguments. Small and `Copy`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TransformerError {
    /// A [`TransformerShape`] size is zero.
    ZeroSize,
    /// `width` is not a multiple of `heads`.
    HeadsDoNotDivideWidth,
    /// A size derived from the shape overflows `usize`.
    SizeOverflow,
    /// The number of blocks differs from `shape.layers`.
    LayerCount,
    /// A part's own slices are inconsistent (e.g. weights length vs its stated features).
    Weights {
        /// The offending part.
        part: Part,
        /// What the kernel check found.
        error: KernelError,
    },
    /// A part's sizes do not match the shape (in/out features, norm, position or token length).
    Features {
        /// The offending part.
        part: Part,
    },
    /// A part's input quantization parameters (or LUT-related requantization) are invalid.
    InputParams {
        /// The offending part.
        part: Part,
    },
    /// An f32 linear layer has an activation other than `Identity` (the block applies GELU itself).
    Activation {
        /// The offending part.
        part: Part,
    },
    /// The trajectory slice is not `horizon * action_dim` long.
    TrajectoryLength,
    /// The condition slice is not `cond_dim` long.
    ConditionLength,
    /// The noise-embedding slice does not match `noise_in`.
    EmbeddingLength,
    /// The output slice is not `output` long.
    OutputLength,
    /// The trajectory, condition or embedding contains NaN or an infinity.
    NonFiniteInput,
    /// A scratch buffer is shorter than the shape needs.
    ScratchTooSmall {
        /// Which buffer.
        buffer: ScratchBuffer,
        /// Elements needed.
        needed: usize,
    },
    /// A kernel failed at run time (e.g. non-finite attention scores from overflowing weights).
    Kernel(KernelError),
}

impl From<KernelError> for TransformerError {
    fn from(error: KernelError) -> Self {
        Self::Kernel(error)
    }
}

impl core::fmt::Display for TransformerError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::ZeroSize => f.write_str("a transformer size is zero"),
            Self::HeadsDoNotDivideWidth => f.write_str("width is not a multiple of heads"),
            Self::SizeOverflow => f.write_str("a transformer size overflows usize"),
            Self::LayerCount => f.write_str("number of blocks differs from shape.layers"),
            Self::Weights { part, .. } => write!(f, "{part:?}: its arrays do not fit its sizes"),
            Self::Features { part } => write!(f, "{part:?}: sizes do not match the shape"),
            Self::InputParams { part } => write!(f, "{part:?}: invalid quantization parameters"),
            Self::Activation { part } => write!(f, "{part:?}: linear layer must be Identity"),
            Self::TrajectoryLength => f.write_str("trajectory length is not horizon * action_dim"),
            Self::ConditionLength => f.write_str("condition length is not cond_dim"),
            Self::EmbeddingLength => f.write_str("embedding length does not match noise_in"),
            Self::OutputLength => f.write_str("output length is not shape.output"),
            Self::NonFiniteInput => f.write_str("input contains NaN or infinity"),
            Self::ScratchTooSmall { buffer, needed } => {
                write!(f, "{buffer:?} scratch too small: {needed} elements needed")
            }
            Self::Kernel(_) => f.write_str("a kernel failed"),
        }
    }
}

impl core::error::Error for TransformerError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        match self {
            Self::Weights { error, .. } | Self::Kernel(error) => Some(error),
            _ => None,
        }
    }
}
