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
use crate::model::transformer::{
    F32Transformer, Int8Transformer, TransformerBuffers, TransformerError, TransformerScratch,
    TransformerShape,
};
use crate::policy::{InputLayout, InputSegment, PolicyError};

/// The standard layout order the transformer requires (condition first, trajectory last).
pub(crate) const STANDARD_SEGMENTS: [InputSegment; 4] = [
    InputSegment::ObsHistory,
    InputSegment::PrevAction,
    InputSegment::PrevRate,
    InputSegment::NoisyTrajectory,
];

/// Working memory a [`TransformerNetwork`] runs in: a [`TransformerScratch`], or a mutable
/// borrow of one (so that moving the network or the policy copies no large buffers).
pub trait TransformerWork {
    /// The buffers.
    fn buffers(&mut self) -> TransformerBuffers<'_>;
}

impl<const F: usize, const B: usize, const A: usize> TransformerWork for TransformerScratch<F, B, A> {
    fn buffers(&mut self) -> TransformerBuffers<'_> {
        TransformerScratch::buffers(self)
    }
}

impl<T: TransformerWork + ?Sized> TransformerWork for &mut T {
    fn buffers(&mut self) -> TransformerBuffers<'_> {
        (**self).buffers()
    }
}

/// A transformer backbone the network can run ([`F32Transformer`], [`Int8Transformer`]).
pub trait TransformerBackbone<'a>: Copy {
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
        buffers: TransformerBuffers<'_>,
    ) -> Result<(), TransformerError>;
}

impl<'a> TransformerBackbone<'a> for F32Transformer<'a> {
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

impl<'a> TransformerBackbone<'a> for Int8Transformer<'a> {
    fn shape(&self) -> &TransformerShape {
        &self.shape
    }
    fn validate(&self) -> Result<(), TransformerError> {
        Int8Transformer::validate(self)
    }
    fn with_noise_token(&self, noise_token: &'a [f32]) -> Self {
        Int8Transformer::with_noise_token(self, noise_token)
    }
    fn run(
        &self,
        trajectory: &[f32],
        condition: &[f32],
        output: &mut [f32],
        buffers: TransformerBuffers<'_>,
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

/// [`TransformerNetwork`] over the f32 reference backbone.
pub type F32TransformerNetwork<'a, S> = TransformerNetwork<'a, F32Transformer<'a>, S>;

impl<'a, T: TransformerBackbone<'a>, S: TransformerWork> TransformerNetwork<'a, T, S> {
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

impl<'a, T: TransformerBackbone<'a>, S: TransformerWork> Network for TransformerNetwork<'a, T, S> {
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
