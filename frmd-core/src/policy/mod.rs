//! The policy API a controller loop calls (DESIGN.md s.1, s.3, s.5).
//!
//! Per control tick the controller calls [`Policy::observe`] with the newest observation (raw
//! units) and, when it needs a new chunk, [`Policy::act`], then executes actions from the chunk
//! with [`Policy::next_action`] (which records each emitted action as the last commanded one, so
//! the ProDMP boundary conditions `y0`, `v0` follow the robot). [`Policy::reset`] starts an
//! episode. Internally:
//!
//! 1. observations are checked (NaN/Inf is [`PolicyError::NonFiniteObservation`]), normalized to
//!    `[-1, 1]` ([`RangeNormalizer`]) and pushed into an `M`-deep ring buffer ([`ObsHistory`],
//!    padded with the first observation of an episode);
//! 2. the model input is assembled by the [`InputLayout`] from the history, the last commanded
//!    action and its finite-difference rate (normalized units per second) and the `c_in`-scaled
//!    noisy trajectory;
//! 3. the [`Sampler`] runs the 1..=4-step consistency sampler through any [`Network`] (int8
//!    [`Int8Network`] or f32 [`F32Network`]) and decodes ProDMP parameters with the baked decoder;
//! 4. the chunk is un-normalized to robot units: `N x K` positions and velocities.
//!
//! Const generics: `M` history length, `O` observation dim, `K` action dim (DoF), `N` horizon,
//! `P = num_basis + 1` ProDMP parameters per DoF, `I` capacity of the input buffer (at least the
//! layout's width).

mod baked;
mod history;
mod layout;
mod network;
mod normalize;
mod runtime;
mod sampler;
mod transformer_network;
pub(crate) use transformer_network::STANDARD_SEGMENTS;

#[cfg(test)]
pub(crate) mod test_model;
#[cfg(test)]
mod tests;

pub use baked::{baked_slice, AlignedBytes};
pub use history::ObsHistory;
pub use layout::{InputLayout, InputSegment, InputSources, MAX_INPUT_SEGMENTS};
pub(crate) use network::EMPTY_INT8_LAYER;
pub use network::{F32Network, Int8Network, Network, MAX_HIDDEN_LAYERS};
pub use normalize::{denormalize_value, normalize_value, RangeNormalizer};
pub use runtime::{Policy, PolicyConfig};
pub use transformer_network::{
    F32TransformerNetwork, Int8TransformerNetwork, TransformerBackbone, TransformerNetwork,
};
pub use sampler::{
    skip_output, validate_steps, Conditioning, Noise, Sampler, SamplerWork, StepConstants, Trajectory,
    MAX_STEPS,
};

use crate::model::mlp::ModelError;
use crate::model::transformer::TransformerError;

use crate::prodmp::ProDmpError;

/// Why the policy refused a call. Small and `Copy`; each variant names the problem.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PolicyError {
    /// Observation element `index` is NaN or infinite.
    NonFiniteObservation {
        /// Offending dimension.
        index: usize,
    },
    /// Action (or rate) element `index` given by the caller is NaN or infinite.
    NonFiniteAction {
        /// Offending dimension.
        index: usize,
    },
    /// [`Policy::act`] before any observation of the episode.
    NoObservation,
    /// [`Policy::act`] before the last commanded action is known ([`Policy::reset`]).
    NoPreviousAction,
    /// A normalization bound is not finite or `min > max`.
    InvalidNormalization,
    /// The input layout repeats a segment, lacks the noisy trajectory, has too many segments or a
    /// non-finite rate scale.
    InvalidLayout,
    /// The layout's width differs from the network's input width or exceeds the input buffer.
    InputWidth,
    /// The network's output width is not `K * P`.
    OutputWidth,
    /// A step constant is not finite, `sigma` or `c_in` is not positive, `renoise_std` is
    /// negative, or the first step re-noises.
    InvalidStepConstants,
    /// The step table has 0 or more than [`MAX_STEPS`] entries.
    StepCount,
    /// The control period is not finite and positive.
    InvalidControlPeriod,
    /// A step selects a first-layer bias variant the network does not have.
    FirstLayerBiasIndex,
    /// The first-layer bias variants are not a whole number of `out_features` rows.
    FirstLayerBiasLength,
    /// The network has more than [`MAX_HIDDEN_LAYERS`] hidden layers.
    TooManyLayers,
    /// Caller-supplied noise does not hold `steps * N * K` values.
    NoiseLength,
    /// Caller-supplied noise contains NaN or infinity.
    NonFiniteNoise,
    /// The sampled chunk contains NaN or infinity.
    NonFiniteOutput,
    /// A baked weight section lies outside the weight file or is misaligned for its type.
    BakedData,
    /// The forward pass refused its arguments.
    Model(ModelError),
    /// The ProDMP decoder refused its arguments.
    Decode(ProDmpError),
    /// The transformer backbone refused its weights or arguments.
    Transformer(TransformerError),
    /// A transformer network needs the standard input layout (observation history, previous
    /// action, previous rate, noisy trajectory) to split condition and trajectory.
    TransformerLayout,
}

impl core::fmt::Display for PolicyError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NonFiniteObservation { index } => {
                write!(f, "observation element {index} is not finite")
            }
            Self::NonFiniteAction { index } => write!(f, "action element {index} is not finite"),
            Self::NoObservation => f.write_str("no observation since the episode started"),
            Self::NoPreviousAction => f.write_str("last commanded action unknown (call reset)"),
            Self::InvalidNormalization => {
                f.write_str("normalization bound not finite or min > max")
            }
            Self::InvalidLayout => f.write_str("invalid model input layout"),
            Self::InputWidth => {
                f.write_str("input layout width differs from the network or the input buffer")
            }
            Self::OutputWidth => f.write_str("network output width is not K * P"),
            Self::InvalidStepConstants => f.write_str("invalid sampling step constants"),
            Self::StepCount => f.write_str("step table must have 1..=4 steps"),
            Self::InvalidControlPeriod => f.write_str("control period is not finite and positive"),
            Self::FirstLayerBiasIndex => f.write_str("first-layer bias variant index out of range"),
            Self::FirstLayerBiasLength => {
                f.write_str("first-layer bias variants are not whole rows")
            }
            Self::TooManyLayers => f.write_str("too many hidden layers"),
            Self::NoiseLength => f.write_str("supplied noise has the wrong length"),
            Self::NonFiniteNoise => f.write_str("supplied noise is not finite"),
            Self::NonFiniteOutput => f.write_str("sampled chunk is not finite"),
            Self::BakedData => f.write_str("baked weight section out of range or misaligned"),
            Self::Model(e) => write!(f, "network: {e}"),
            Self::Decode(e) => write!(f, "ProDMP decode: {e}"),
            Self::Transformer(e) => write!(f, "transformer: {e}"),
            Self::TransformerLayout => {
                f.write_str("transformer network needs the standard input layout")
            }
        }
    }
}
