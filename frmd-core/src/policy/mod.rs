//! The policy API a controller loop calls (docs/design.md s.1, s.3, s.5).
//!
//! Per control tick the controller calls [`Policy::observe`] with the newest observation (raw
//! units) and, when it needs a new chunk, [`Policy::act`], then executes actions from the chunk
//! with [`Policy::next_action`] (which records each emitted action as the last commanded one, so
//! the ProDMP boundary conditions `y0`, `v0` follow the robot). [`Policy::reset`] starts an
//! episode. Internally:
//!
//! 1. observations are checked (NaN/Inf is [`PolicyError::NonFiniteObservation`]), normalized to
//!    `[-1, 1]` ([`RangeNormalizer`]) and pushed into an `m`-deep ring buffer ([`ObsHistory`],
//!    padded with the first observation of an episode);
//! 2. the model input is assembled by the [`InputLayout`] from the history, the last commanded
//!    action and its finite-difference rate (normalized units per second) and the `c_in`-scaled
//!    noisy trajectory;
//! 3. the [`Sampler`] runs the 1..=4-step consistency sampler through any [`Network`] (an MLP,
//!    [`Int8MlpNetwork`] or [`F32MlpNetwork`], or a transformer, [`TransformerNetwork`]) and
//!    decodes ProDMP parameters with the baked decoder tables ([`ProDmpTables`]);
//! 4. the chunk is un-normalized to robot units: `n x k` positions and velocities.
//!
//! Sizes ([`PolicyDims`]): `m` history length, `o` observation dim, `k` action dim (DoF), `n`
//! horizon, `p = num_basis + 1` ProDMP parameters per DoF, known at run time from the
//! configuration. The [`Policy`]'s const generics `M, O, K, N, P, I` are the capacities of its
//! buffers (`I` the model input), at least those sizes: a firmware image bakes them exactly, a
//! host picks capacities large enough for any exported shape.
//!
//! # Example
//!
//! A policy over hand-made parts (a firmware gets them from a baked module or a blob, see
//! [`crate::blob::LoadedMlp`]): one observation of 2 values, 1 DoF, chunks of 4 actions from 3
//! basis functions and a goal, one sampling step, a tiny f32 MLP.
//!
//! ```
//! use frmd_core::kernels::Activation;
//! use frmd_core::model::linear::F32Linear;
//! use frmd_core::policy::{
//!     F32MlpNetwork, InputLayout, Noise, Policy, PolicyConfig, ProDmpTables, RangeNormalizer,
//!     Sampler, StepConstants, StepTable,
//! };
//! use frmd_core::prodmp::{BakedProDmp, ProDmpConfig};
//! use frmd_core::rng::Rng;
//! use frmd_core::sigma::SigmaConfig;
//!
//! const DT: f32 = 0.05;
//! let decoder = BakedProDmp::<4, 4>::from_config(&ProDmpConfig::policy(1, 3, 4, DT.into()))?;
//! let sigma = SigmaConfig::default();
//! let steps = [StepConstants::consistency(&sigma, sigma.sigma_max, 0)?];
//! let (obs_min, obs_max, action_min, action_max) = ([-1.0; 2], [1.0; 2], [-0.5], [0.5]);
//! let config = PolicyConfig {
//!     history: 1,
//!     obs_norm: RangeNormalizer::new(&obs_min, &obs_max),
//!     action_norm: RangeNormalizer::new(&action_min, &action_max),
//!     sampler: Sampler {
//!         steps: StepTable::new(&steps),
//!         decoder: ProDmpTables::from_baked(&decoder),
//!         layout: InputLayout::standard(DT),
//!         control_dt: DT,
//!     },
//! };
//! // Model input: 2 observations, the last action and its rate, the 4-step noisy chunk.
//! let (w1, b1, w2, b2) = ([0.1_f32; 8 * 6], [0.0; 6], [0.2; 6 * 4], [0.0; 4]);
//! let hidden = [F32Linear {
//!     in_features: 8,
//!     out_features: 6,
//!     weights: &w1,
//!     bias: &b1,
//!     activation: Activation::Silu,
//! }];
//! let output = F32Linear {
//!     in_features: 6,
//!     out_features: 4,
//!     weights: &w2,
//!     bias: &b2,
//!     activation: Activation::Identity,
//! };
//! let network = F32MlpNetwork::<8>::new(&hidden, output, &[])?;
//! // Capacities M, O, K, N, P and the model input I: at least the sizes above.
//! let mut policy = Policy::<_, 1, 2, 1, 4, 4, 8>::new(config, network)?;
//! policy.reset(&[0.0])?; // the last commanded action
//! policy.observe(&[0.3, -0.2])?; // every control tick
//! let chunk = policy.act(Noise::Rng(&mut Rng::new(7)))?; // when a new chunk is needed
//! assert!(chunk.positions.iter().flatten().all(|p| p.is_finite()));
//! let mut executed = 0;
//! while let Some(action) = policy.next_action() {
//!     assert!(action[0].abs() <= 10.0); // command it (robot units)
//!     executed += 1;
//! }
//! assert_eq!(executed, 4);
//! # Ok::<(), Box<dyn core::error::Error>>(())
//! ```

mod baked;
mod decoder;
mod dims;
mod history;
mod layout;
pub mod network;
mod normalize;
mod runtime;
mod sampler;
mod steps;

#[cfg(test)]
pub(crate) mod test_model;
#[cfg(test)]
mod tests;

pub use baked::{baked_slice, AlignedBytes};
pub use decoder::ProDmpTables;
pub use dims::PolicyDims;
pub use history::ObsHistory;
pub use layout::{InputLayout, InputSegment, InputSources, MAX_INPUT_SEGMENTS};
pub use network::mlp::{
    F32MlpNetwork, Int16MlpNetwork, Int8MlpNetwork, QuantMlpNetwork, MAX_HIDDEN_LAYERS,
};
pub(crate) use network::transformer::STANDARD_SEGMENTS;
pub use network::transformer::{
    F32TransformerNetwork, Int16TransformerNetwork, Int8TransformerNetwork, TransformerBackbone,
    TransformerNetwork, TransformerWork,
};
pub use network::{Network, NoiseVariants};
pub use normalize::{denormalize_value, normalize_value, RangeNormalizer};
pub use runtime::{Policy, PolicyConfig};
pub use sampler::{
    skip_output, Conditioning, Noise, Sampler, SamplerBuffers, SamplerWork, Trajectory,
};
pub use steps::{validate_steps, StepConstants, StepTable, MAX_STEPS};

use crate::model::mlp::ModelError;
use crate::model::transformer::TransformerError;

use crate::prodmp::ProDmpError;

/// Why the policy refused a call. Small and `Copy`; each variant names the problem.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
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
    /// The layout's width differs from the network's input width, or an argument (observation,
    /// action, rate) does not have its size.
    InputWidth,
    /// The network's output width is not `k p`.
    OutputWidth,
    /// A size exceeds the capacity of the policy's buffers (or is zero).
    Capacity,
    /// A step constant is not finite, `sigma` or `c_in` is not positive, `renoise_std` is
    /// negative, or the first step re-noises.
    InvalidStepConstants,
    /// The step table has 0 or more than [`MAX_STEPS`] entries.
    StepCount,
    /// The control period is not finite and positive.
    InvalidControlPeriod,
    /// A step selects a noise-level variant the network does not have.
    NoiseVariantIndex,
    /// The noise-level variants are not a whole number of rows (first-layer `out_features` of
    /// an MLP, `W` of a transformer).
    NoiseVariantLength,
    /// The network has more than [`MAX_HIDDEN_LAYERS`] hidden layers.
    TooManyLayers,
    /// Caller-supplied noise does not hold `steps n k` values.
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
                f.write_str("input layout width differs from the network, or an argument's size")
            }
            Self::OutputWidth => f.write_str("network output width is not k * p"),
            Self::Capacity => f.write_str("a size exceeds the policy's buffers"),
            Self::InvalidStepConstants => f.write_str("invalid sampling step constants"),
            Self::StepCount => f.write_str("step table must have 1..=4 steps"),
            Self::InvalidControlPeriod => f.write_str("control period is not finite and positive"),
            Self::NoiseVariantIndex => f.write_str("noise-level variant index out of range"),
            Self::NoiseVariantLength => f.write_str("noise-level variants are not whole rows"),
            Self::TooManyLayers => f.write_str("too many hidden layers"),
            Self::NoiseLength => f.write_str("supplied noise has the wrong length"),
            Self::NonFiniteNoise => f.write_str("supplied noise is not finite"),
            Self::NonFiniteOutput => f.write_str("sampled chunk is not finite"),
            Self::BakedData => f.write_str("baked weight section out of range or misaligned"),
            Self::Model(_) => f.write_str("the network failed"),
            Self::Decode(_) => f.write_str("the ProDMP decode failed"),
            Self::Transformer(_) => f.write_str("the transformer network failed"),
            Self::TransformerLayout => {
                f.write_str("transformer network needs the standard input layout")
            }
        }
    }
}

impl core::error::Error for PolicyError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        match self {
            Self::Model(error) => Some(error),
            Self::Decode(error) => Some(error),
            Self::Transformer(error) => Some(error),
            _ => None,
        }
    }
}
