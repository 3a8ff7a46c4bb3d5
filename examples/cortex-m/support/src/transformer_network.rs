//! [`TransformerNetwork`]: frmd-core's [`Int8Transformer`] behind the policy's [`Network`] trait,
//! so `Policy::act` drives transformer-lite exactly as it drives the MLP (noise, input assembly,
//! consistency output stage, ProDMP decode, denormalization). `core` + frmd-core only: the
//! firmware and the host test share it.
//!
//! The policy assembles one input vector with the standard [`InputLayout`]
//! (`[obs history | previous action | rate * rate_scale | c_in x]`); the first three segments are
//! the transformer's condition (`cond_dim` values) and the last one its trajectory (`n k`). The
//! noise token is folded for the single sampling step, so only first-layer bias index 0 exists.

use frmd_core::model::mlp::ModelError;
use frmd_core::model::transformer::{Int8Transformer, TransformerError, TransformerScratch};
use frmd_core::policy::{InputLayout, InputSegment, Network, PolicyError};

use crate::stages::{Clock, Marks};

fn no_clock() -> u32 {
    0
}

/// Why [`TransformerNetwork::new`] refused its arguments.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TransformerNetworkError {
    /// The backbone does not validate.
    Model(TransformerError),
    /// The input layout is not the standard order (condition segments first, then the noisy
    /// trajectory), so the input cannot be split into condition and trajectory.
    Layout,
}

impl core::fmt::Display for TransformerNetworkError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Model(error) => write!(f, "transformer: {error}"),
            Self::Layout => f.write_str("transformer network needs the standard input layout"),
        }
    }
}

/// The backbone, its scratch (borrowed, so that moving the network or the policy around copies
/// no 20 KB buffers) and the error of the last refused forward pass.
pub struct TransformerNetwork<'a, const F: usize, const B: usize, const A: usize> {
    model: Int8Transformer<'a>,
    scratch: &'a mut TransformerScratch<F, B, A>,
    last_error: Option<TransformerError>,
    /// Entry and exit of the last forward pass.
    marks: Marks<2>,
}

impl<'a, const F: usize, const B: usize, const A: usize> TransformerNetwork<'a, F, B, A> {
    /// Wraps `model` for inputs laid out by `layout`, which must be the standard order (condition
    /// segments first, the noisy trajectory last), with `scratch` as working memory; the model
    /// must validate.
    pub fn new(
        model: Int8Transformer<'a>,
        layout: &InputLayout,
        scratch: &'a mut TransformerScratch<F, B, A>,
    ) -> Result<Self, TransformerNetworkError> {
        model.validate().map_err(TransformerNetworkError::Model)?;
        let standard = [
            InputSegment::ObsHistory,
            InputSegment::PrevAction,
            InputSegment::PrevRate,
            InputSegment::NoisyTrajectory,
        ];
        if layout.segments() != standard {
            return Err(TransformerNetworkError::Layout);
        }
        Ok(Self {
            model,
            scratch,
            last_error: None,
            marks: Marks::new(no_clock),
        })
    }

    /// The backbone.
    pub fn model(&self) -> &Int8Transformer<'a> {
        &self.model
    }

    /// Reads `clock` at the entry and the exit of every forward pass (see [`Self::marks`]).
    pub fn set_clock(&mut self, clock: Clock) {
        self.marks = Marks::new(clock);
    }

    /// Clock readings at the entry and the exit of the last forward pass.
    pub fn marks(&self) -> &Marks<2> {
        &self.marks
    }

    /// Why the last forward pass was refused: the policy only sees
    /// `PolicyError::Model(ModelError::InputLength)`, since `PolicyError` has no transformer variant.
    pub fn last_error(&self) -> Option<TransformerError> {
        self.last_error
    }
}

impl<const F: usize, const B: usize, const A: usize> Network for TransformerNetwork<'_, F, B, A> {
    fn input_width(&self) -> usize {
        let shape = &self.model.shape;
        shape.cond_dim.saturating_add(shape.trajectory_len())
    }

    fn output_width(&self) -> usize {
        self.model.shape.output
    }

    fn num_first_layer_biases(&self) -> usize {
        0
    }

    fn forward(
        &mut self,
        first_layer_bias: usize,
        input: &[f32],
        output: &mut [f32],
    ) -> Result<(), PolicyError> {
        self.marks.clear();
        self.marks.mark();
        if first_layer_bias != 0 {
            return Err(PolicyError::FirstLayerBiasIndex);
        }
        let (condition, trajectory) = input
            .split_at_checked(self.model.shape.cond_dim)
            .ok_or(PolicyError::Model(ModelError::InputLength))?;
        let result = self.model.forward(trajectory, condition, output, self.scratch);
        self.marks.mark();
        self.last_error = result.err();
        result.map_err(|_| PolicyError::Model(ModelError::InputLength))
    }
}
