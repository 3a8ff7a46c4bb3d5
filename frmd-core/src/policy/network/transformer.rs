//! Transformer policy networks ([`TransformerNetwork`] over either form of
//! [`crate::model::transformer::Transformer`]).
//!
//! Input split: the policy assembles one vector with the standard [`InputLayout`]
//! (`[obs history | previous action | rate * rate_scale | c_in x]`); the first three segments are
//! the transformer's condition (`cond_dim` values), the last one its trajectory (`n k`).
//!
//! Noise level: the exporter folds each sampling step's noise embedding into a noise token
//! (`noise_in(embedding(sigma_i)) + positions[1]`,
//! [`crate::model::transformer::fold_noise_token`]) and writes one `W` long token per step back
//! to back; variant `i` selects token `i`. With no tokens, variant 0 uses the model's own
//! `noise_token`.

use super::{Network, NoiseVariants};
use crate::kernels::Precision;
use crate::model::transformer::{
    F32Transformer, Int16Transformer, Int8Transformer, QuantTransformer, TransformerBuffers,
    TransformerError, TransformerScratch, TransformerShape,
};
use crate::policy::{InputLayout, InputSegment, PolicyError};

/// The standard layout order the transformer requires (condition first, trajectory last).
pub(crate) const STANDARD_SEGMENTS: [InputSegment; 4] = [
    InputSegment::ObsHistory,
    InputSegment::PrevAction,
    InputSegment::PrevRate,
    InputSegment::NoisyTrajectory,
];

/// Working memory a [`TransformerNetwork`] runs in, with `P` codes: a [`TransformerScratch`], or
/// a mutable borrow of one (so that moving the network or the policy copies no large buffers).
/// A host that runs either precision may implement it for both `i8` and `i16`.
pub trait TransformerWork<P: Precision = i8> {
    /// The buffers.
    fn buffers(&mut self) -> TransformerBuffers<'_, P>;
}

impl<const F: usize, const B: usize, const A: usize, P: Precision> TransformerWork<P>
    for TransformerScratch<F, B, A, P>
{
    fn buffers(&mut self) -> TransformerBuffers<'_, P> {
        TransformerScratch::buffers(self)
    }
}

impl<P: Precision, T: TransformerWork<P> + ?Sized> TransformerWork<P> for &mut T {
    fn buffers(&mut self) -> TransformerBuffers<'_, P> {
        (**self).buffers()
    }
}

/// A transformer backbone the network can run ([`F32Transformer`], [`QuantTransformer`]).
pub trait TransformerBackbone<'a>: Copy {
    /// The code type of its scratch (`i8` for the f32 form, which uses only the floats).
    type Codes: Precision;
    /// Sizes.
    fn shape(&self) -> &TransformerShape;
    /// Checks every part against the shape.
    fn validate(&self) -> Result<(), TransformerError>;
    /// The same model with another noise token (`W` values).
    fn with_noise_token(&self, noise_token: &'a [f32]) -> Self;
    /// One forward pass on borrowed buffers.
    fn run(
        &self,
        trajectory: &[f32],
        condition: &[f32],
        output: &mut [f32],
        buffers: TransformerBuffers<'_, Self::Codes>,
    ) -> Result<(), TransformerError>;
}

impl<'a> TransformerBackbone<'a> for F32Transformer<'a> {
    type Codes = i8;
    fn shape(&self) -> &TransformerShape {
        &self.shape
    }
    fn validate(&self) -> Result<(), TransformerError> {
        F32Transformer::validate(self)
    }
    fn with_noise_token(&self, noise_token: &'a [f32]) -> Self {
        F32Transformer::with_noise_token(self, noise_token)
    }
    fn run(
        &self,
        trajectory: &[f32],
        condition: &[f32],
        output: &mut [f32],
        buffers: TransformerBuffers<'_>,
    ) -> Result<(), TransformerError> {
        self.forward_in(trajectory, condition, output, buffers, |_, _| {})
    }
}

impl<'a, P: Precision> TransformerBackbone<'a> for QuantTransformer<'a, P> {
    type Codes = P;
    fn shape(&self) -> &TransformerShape {
        &self.shape
    }
    fn validate(&self) -> Result<(), TransformerError> {
        QuantTransformer::validate(self)
    }
    fn with_noise_token(&self, noise_token: &'a [f32]) -> Self {
        QuantTransformer::with_noise_token(self, noise_token)
    }
    fn run(
        &self,
        trajectory: &[f32],
        condition: &[f32],
        output: &mut [f32],
        buffers: TransformerBuffers<'_, P>,
    ) -> Result<(), TransformerError> {
        self.forward_in(trajectory, condition, output, buffers)
    }
}

/// A transformer backbone with per-step noise tokens and its working memory `S`.
pub struct TransformerNetwork<'a, T, S> {
    model: T,
    variants: NoiseVariants<'a, f32>,
    scratch: S,
}

/// [`TransformerNetwork`] over the int8 backbone.
pub type Int8TransformerNetwork<'a, S> = TransformerNetwork<'a, Int8Transformer<'a>, S>;

/// [`TransformerNetwork`] over the int16-activation backbone.
pub type Int16TransformerNetwork<'a, S> = TransformerNetwork<'a, Int16Transformer<'a>, S>;

/// [`TransformerNetwork`] over the f32 reference backbone.
pub type F32TransformerNetwork<'a, S> = TransformerNetwork<'a, F32Transformer<'a>, S>;

impl<'a, T: TransformerBackbone<'a>, S: TransformerWork<T::Codes>> TransformerNetwork<'a, T, S> {
    /// Wraps `model` for inputs laid out by `layout` (must be the standard order: observation
    /// history, previous action, previous rate, noisy trajectory). `noise_tokens` holds one
    /// `width`-long noise token per sampling step back to back, or is empty to use the model's
    /// own token for variant 0. The model must validate.
    ///
    /// Errors: [`PolicyError::Transformer`] when the model does not validate,
    /// [`PolicyError::TransformerLayout`] for another layout (the policy checks the total width
    /// against [`Network::input_width`]), [`PolicyError::NoiseVariantLength`] when the tokens
    /// are not whole rows, [`PolicyError::NonFiniteNoise`] when a token is not finite.
    pub fn new(
        model: T,
        layout: &InputLayout,
        noise_tokens: &'a [f32],
        scratch: S,
    ) -> Result<Self, PolicyError> {
        model.validate().map_err(PolicyError::Transformer)?;
        if layout.segments() != STANDARD_SEGMENTS {
            return Err(PolicyError::TransformerLayout);
        }
        let variants = NoiseVariants::new(noise_tokens, model.shape().width)?;
        if noise_tokens.iter().any(|value| !value.is_finite()) {
            return Err(PolicyError::NonFiniteNoise);
        }
        Ok(Self {
            model,
            variants,
            scratch,
        })
    }

    /// The backbone (with its own noise token).
    pub fn model(&self) -> &T {
        &self.model
    }
}

impl<'a, T, S> Network for TransformerNetwork<'a, T, S>
where
    T: TransformerBackbone<'a>,
    S: TransformerWork<T::Codes>,
{
    fn input_width(&self) -> usize {
        let shape = self.model.shape();
        shape.cond_dim.saturating_add(shape.trajectory_len())
    }

    fn output_width(&self) -> usize {
        self.model.shape().output
    }

    fn num_noise_variants(&self) -> usize {
        self.variants.count()
    }

    fn forward(
        &mut self,
        variant: usize,
        input: &[f32],
        output: &mut [f32],
    ) -> Result<(), PolicyError> {
        let model = match self.variants.select(variant)? {
            Some(token) => self.model.with_noise_token(token),
            None => self.model,
        };
        let (condition, trajectory) = input
            .split_at_checked(model.shape().cond_dim)
            .ok_or(PolicyError::InputWidth)?;
        model
            .run(trajectory, condition, output, self.scratch.buffers())
            .map_err(PolicyError::Transformer)
    }
}

#[cfg(test)]
#[allow(clippy::indexing_slicing)]
mod tests {
    extern crate std;

    use super::*;
    use crate::kernels::Activation;
    use crate::model::linear::F32Linear;
    use crate::model::transformer::TransformerShape;
    use crate::model::transformer::{F32Block, F32FeedForward, LayerNormWeights};
    use crate::policy::InputSegment;
    use crate::rng::Rng;
    use std::{vec, vec::Vec};

    const SHAPE: TransformerShape = TransformerShape {
        horizon: 3,
        action_dim: 2,
        cond_dim: 6,
        width: 8,
        heads: 2,
        layers: 1,
        output: 4,
    };
    type Scratch = TransformerScratch<4096, 4096, 256>;

    fn random(rng: &mut Rng, len: usize) -> Vec<f32> {
        (0..len).map(|_| 0.3 * rng.gaussian()).collect()
    }

    fn layer(weights: &[f32], bias: &[f32], in_features: usize) -> F32Linear<'static> {
        let weights: &'static [f32] = std::boxed::Box::leak(weights.to_vec().into_boxed_slice());
        let bias: &'static [f32] = std::boxed::Box::leak(bias.to_vec().into_boxed_slice());
        F32Linear {
            in_features,
            out_features: bias.len(),
            weights,
            bias,
            activation: Activation::Identity,
        }
    }

    fn linear(rng: &mut Rng, in_features: usize, out_features: usize) -> F32Linear<'static> {
        let weights = random(rng, in_features * out_features);
        let bias = random(rng, out_features);
        layer(&weights, &bias, in_features)
    }

    fn leak(values: Vec<f32>) -> &'static [f32] {
        std::boxed::Box::leak(values.into_boxed_slice())
    }

    fn model(rng: &mut Rng) -> F32Transformer<'static> {
        let width = SHAPE.width;
        let norm = LayerNormWeights {
            gamma: leak(vec![1.0; width]),
            beta: leak(vec![0.0; width]),
        };
        let block = F32Block {
            norm1: norm,
            qkv: linear(rng, width, 3 * width),
            proj: linear(rng, width, width),
            norm2: norm,
            feed_forward: F32FeedForward {
                fc1: F32Linear {
                    activation: Activation::GeluSigmoid,
                    ..linear(rng, width, 4 * width)
                },
                fc2: linear(rng, 4 * width, width),
            },
        };
        F32Transformer {
            shape: SHAPE,
            traj_in: linear(rng, SHAPE.action_dim, width),
            cond_in: linear(rng, SHAPE.cond_dim, width),
            noise_token: leak(random(rng, width)),
            positions: leak(random(rng, SHAPE.tokens() * width)),
            blocks: std::boxed::Box::leak(vec![block].into_boxed_slice()),
            final_norm: norm,
            head: linear(rng, SHAPE.token_values(), SHAPE.output),
        }
    }

    fn layout() -> InputLayout {
        InputLayout::new(&STANDARD_SEGMENTS, 1.0).unwrap()
    }

    #[test]
    fn step_index_selects_its_noise_token() {
        let mut rng = Rng::new(7);
        let model = model(&mut rng);
        let tokens = random(&mut rng, 2 * SHAPE.width);
        let mut scratch = std::boxed::Box::new(Scratch::new());
        let mut direct_scratch = std::boxed::Box::new(Scratch::new());
        let input = random(&mut rng, SHAPE.cond_dim + SHAPE.trajectory_len());
        let mut network =
            F32TransformerNetwork::new(model, &layout(), &tokens, &mut *scratch).unwrap();
        assert_eq!(network.num_noise_variants(), 2);
        assert_eq!(network.input_width(), 12);
        assert_eq!(network.output_width(), 4);
        let mut outputs = [[0.0_f32; 4]; 2];
        for (step, output) in outputs.iter_mut().enumerate() {
            network.forward(step, &input, output).unwrap();
            let token = &tokens[step * SHAPE.width..(step + 1) * SHAPE.width];
            let mut want = [0.0_f32; 4];
            F32Transformer {
                noise_token: token,
                ..model
            }
            .forward(&input[6..], &input[..6], &mut want, &mut *direct_scratch)
            .unwrap();
            assert_eq!(*output, want);
        }
        assert_ne!(outputs[0], outputs[1], "the noise token must matter");
        assert_eq!(
            network.forward(2, &input, &mut [0.0; 4]),
            Err(PolicyError::NoiseVariantIndex)
        );
    }

    #[test]
    fn without_tokens_only_step_zero_uses_the_model_token() {
        let mut rng = Rng::new(8);
        let model = model(&mut rng);
        let mut scratch = std::boxed::Box::new(Scratch::new());
        let input = random(&mut rng, 12);
        let mut network = F32TransformerNetwork::new(model, &layout(), &[], &mut *scratch).unwrap();
        assert_eq!(network.num_noise_variants(), 0);
        network.forward(0, &input, &mut [0.0; 4]).unwrap();
        assert_eq!(
            network.forward(1, &input, &mut [0.0; 4]),
            Err(PolicyError::NoiseVariantIndex)
        );
        assert_eq!(
            network.forward(0, &input[..11], &mut [0.0; 4]),
            Err(PolicyError::Transformer(TransformerError::TrajectoryLength))
        );
    }

    #[test]
    fn refuses_bad_layout_tokens_and_model() {
        let mut rng = Rng::new(9);
        let model = model(&mut rng);
        let mut scratch = std::boxed::Box::new(Scratch::new());
        let swapped = InputLayout::new(
            &[
                InputSegment::PrevAction,
                InputSegment::ObsHistory,
                InputSegment::PrevRate,
                InputSegment::NoisyTrajectory,
            ],
            1.0,
        )
        .unwrap();
        assert_eq!(
            F32TransformerNetwork::new(model, &swapped, &[], &mut *scratch).err(),
            Some(PolicyError::TransformerLayout)
        );
        let ragged = [0.0_f32; 9];
        assert_eq!(
            F32TransformerNetwork::new(model, &layout(), &ragged, &mut *scratch).err(),
            Some(PolicyError::NoiseVariantLength)
        );
        let mut nan = [0.0_f32; 8];
        nan[3] = f32::NAN;
        assert_eq!(
            F32TransformerNetwork::new(model, &layout(), &nan, &mut *scratch).err(),
            Some(PolicyError::NonFiniteNoise)
        );
        let broken = F32Transformer {
            noise_token: &[0.0; 3],
            ..model
        };
        assert!(matches!(
            F32TransformerNetwork::new(broken, &layout(), &[], &mut *scratch).err(),
            Some(PolicyError::Transformer(_))
        ));
    }
}
