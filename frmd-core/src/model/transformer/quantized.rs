//! The hybrid quantized form of the transformer ([`QuantTransformer`]): linear layers with int8
//! weights and int8 ([`Int8Transformer`]) or int16 ([`Int16Transformer`]) activations, f32
//! residual stream, LayerNorm and attention (see the module docs of [`super`]).

use super::block::{attend, embed_tokens, finish, run_blocks, BlockWork, TokenInput};
use super::block::{FeedForwardSteps, LinearSteps};
use super::shape::{prefix, take};
use super::{
    check_io, BlockLinear, CheckedLinear, FeedForward, Part, QuantTransformer, ScratchBuffer,
    TransformerBuffers, TransformerError, TransformerProbe, TransformerScratch,
};
use crate::kernels::{KernelError, Precision};
use crate::model::linear::{quantize_into, F32Linear, QuantizedLinear, RequantizedLinear};
use crate::quant::QuantParams;

/// An input layer (`traj_in`, `cond_in`) that may stay f32 or run quantized.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TokenLinear<'a, P: Precision = i8> {
    /// f32 weights (activation must be `Identity`).
    Float(F32Linear<'a>),
    /// int8 weights, `P` activations.
    Quantized(QuantizedLinear<'a, P>),
}

impl<P: Precision> TokenLinear<'_, P> {
    /// `output = layer(input)`; the quantized variant uses the first `input.len()` codes of
    /// `codes` and the first `output.len()` accumulators.
    pub fn forward(
        &self,
        input: &[f32],
        codes: &mut [P],
        accumulators: &mut [P::Acc],
        output: &mut [f32],
    ) -> Result<(), KernelError> {
        match self {
            Self::Float(layer) => layer.forward(input, output),
            Self::Quantized(layer) => {
                let codes = codes
                    .get_mut(..input.len())
                    .ok_or(KernelError::InputLength)?;
                let acc = accumulators
                    .get_mut(..output.len())
                    .ok_or(KernelError::OutputLength)?;
                layer.forward(input, codes, acc, output)
            }
        }
    }
}

/// The quantized feed-forward `fc2(gelu(fc1(x)))` of one token: `x` quantized with `input`,
/// `fc1` requantized to the GELU table's input parameters, the table, `fc2` dequantized to f32
/// (the steps of a one-hidden-layer [`crate::model::mlp::QuantMlp`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QuantFeedForward<'a, P: Precision = i8> {
    /// Quantization of the LN2 output (`fc1` input; zero point 0 for int16).
    pub input: QuantParams,
    /// `W -> 4W`, bias with `input.zero_point` folded, requantized to the `fc1` output params
    /// (clamp normally the full code range), then the GELU table (required) to the `fc2` input
    /// params.
    pub fc1: RequantizedLinear<'a, P>,
    /// `4W -> W`: its input parameters are the GELU table's output parameters (the codes arrive
    /// quantized; its bias has their zero point folded, its scales are
    /// `gelu_output_scale * weight_scale[o]`).
    pub fc2: QuantizedLinear<'a, P>,
}

/// The int8-activation feed-forward.
pub type Int8FeedForward<'a> = QuantFeedForward<'a, i8>;
/// The int16-activation feed-forward (int64 bias and accumulators, interpolated GELU table).
pub type Int16FeedForward<'a> = QuantFeedForward<'a, i16>;

fn check_input_params<P: Precision>(
    params: QuantParams,
    part: Part,
) -> Result<(), TransformerError> {
    if params.validate().is_err() || !P::zero_point_valid(params.zero_point) {
        return Err(TransformerError::InputParams { part });
    }
    Ok(())
}

fn check_quantized<P: Precision>(
    layer: &QuantizedLinear<'_, P>,
    in_features: usize,
    out_features: usize,
    part: Part,
) -> Result<(), TransformerError> {
    check_input_params::<P>(layer.input, part)?;
    let fc = &layer.linear.fc;
    fc.validate()
        .map_err(|error| TransformerError::Weights { part, error })?;
    if fc.in_features != in_features || fc.out_features != out_features {
        return Err(TransformerError::Features { part });
    }
    if layer.linear.output_scales.len() != out_features {
        return Err(TransformerError::Weights {
            part,
            error: KernelError::ScaleLength,
        });
    }
    Ok(())
}

impl<P: Precision> CheckedLinear for QuantizedLinear<'_, P> {
    fn check(
        &self,
        in_features: usize,
        out_features: usize,
        part: Part,
    ) -> Result<(), TransformerError> {
        check_quantized(self, in_features, out_features, part)
    }

    fn check_exact(&self, part: Part) -> Result<(), TransformerError> {
        self.linear
            .fc
            .validate_exact()
            .map_err(|error| TransformerError::Weights { part, error })
    }
}

impl<P: Precision> BlockLinear for QuantizedLinear<'_, P> {
    type Code = P;
    type Acc = P::Acc;
}

impl<P: Precision> CheckedLinear for TokenLinear<'_, P> {
    fn check(
        &self,
        in_features: usize,
        out_features: usize,
        part: Part,
    ) -> Result<(), TransformerError> {
        match self {
            TokenLinear::Float(layer) => {
                CheckedLinear::check(layer, in_features, out_features, part)
            }
            TokenLinear::Quantized(layer) => {
                check_quantized(layer, in_features, out_features, part)
            }
        }
    }

    fn check_exact(&self, part: Part) -> Result<(), TransformerError> {
        match self {
            TokenLinear::Float(_) => Ok(()),
            TokenLinear::Quantized(layer) => layer.check_exact(part),
        }
    }
}

impl<P: Precision> FeedForward for QuantFeedForward<'_, P> {
    fn check(&self, width: usize, hidden: usize, layer: usize) -> Result<(), TransformerError> {
        let (fc1, fc2) = (Part::Fc1 { layer }, Part::Fc2 { layer });
        check_input_params::<P>(self.input, fc1)?;
        let fc = &self.fc1.fc;
        fc.validate()
            .map_err(|error| TransformerError::Weights { part: fc1, error })?;
        if fc.in_features != width || fc.out_features != hidden {
            return Err(TransformerError::Features { part: fc1 });
        }
        check_quantized(&self.fc2, hidden, width, fc2)?;
        self.fc1
            .requant
            .validate(hidden)
            .map_err(|error| TransformerError::Weights { part: fc1, error })?;
        if self.fc1.activation.is_none() {
            return Err(TransformerError::Activation { part: fc1 });
        }
        Ok(())
    }

    fn check_exact(&self, layer: usize) -> Result<(), TransformerError> {
        let part = Part::Fc1 { layer };
        self.fc1
            .fc
            .validate_exact()
            .map_err(|error| TransformerError::Weights { part, error })?;
        self.fc2.check_exact(Part::Fc2 { layer })
    }
}

impl<P: Precision> LinearSteps for QuantizedLinear<'_, P> {
    fn rows(&self, start: usize, count: usize) -> Result<Self, KernelError> {
        QuantizedLinear::rows(self, start, count)
    }

    fn encode(&self, values: &[f32], codes: &mut [P]) {
        quantize_into(values, self.input, codes);
    }

    fn apply(
        &self,
        codes: &[P],
        accumulators: &mut [P::Acc],
        output: &mut [f32],
    ) -> Result<(), KernelError> {
        let acc = accumulators
            .get_mut(..output.len())
            .ok_or(KernelError::OutputLength)?;
        self.linear
            .forward_input(P::layer_input(codes), acc, output)
    }

    fn attend_head(
        &self,
        query: &[f32],
        keys: &[f32],
        values: &[f32],
        scale: f32,
        scores: &mut [f32],
        head_out: &mut [f32],
        out: &mut [P],
    ) -> Result<(), KernelError> {
        attend(query, keys, values, scale, scores, head_out)?;
        quantize_into(head_out, self.input, out);
        Ok(())
    }

    fn observed(_codes: &[P]) -> Option<&[f32]> {
        None
    }
}

impl<P: Precision> FeedForwardSteps<P, P::Acc> for QuantFeedForward<'_, P> {
    fn run<O: FnMut(TransformerProbe, &[f32])>(
        &self,
        _layer: usize,
        row: &mut [f32],
        codes: &mut [P],
        hidden: &mut [P],
        accumulators: &mut [P::Acc],
        _observe: &mut O,
    ) -> Result<(), TransformerError> {
        let width = row.len();
        let codes = codes.get_mut(..width).ok_or(KernelError::InputLength)?;
        quantize_into(row, self.input, codes);
        let hidden = hidden
            .get_mut(..self.fc1.fc.out_features)
            .ok_or(KernelError::OutputLength)?;
        self.fc1
            .forward_prevalidated(P::layer_input(codes), hidden)?;
        let acc = accumulators
            .get_mut(..width)
            .ok_or(KernelError::OutputLength)?;
        self.fc2
            .linear
            .forward_input(P::layer_input(hidden), acc, row)?;
        Ok(())
    }
}

impl<P: Precision> QuantTransformer<'_, P> {
    /// Runs the backbone (same arguments as [`super::F32Transformer::forward`]); the scratch must
    /// hold at least [`super::TransformerShape::quantized_scratch`] elements in each buffer.
    pub fn forward<const F: usize, const B: usize, const A: usize>(
        &self,
        trajectory: &[f32],
        condition: &[f32],
        output: &mut [f32],
        scratch: &mut TransformerScratch<F, B, A, P>,
    ) -> Result<(), TransformerError> {
        self.forward_in(trajectory, condition, output, scratch.buffers())
    }

    /// [`Self::forward`] on borrowed buffers.
    pub fn forward_in(
        &self,
        trajectory: &[f32],
        condition: &[f32],
        output: &mut [f32],
        buffers: TransformerBuffers<'_, P>,
    ) -> Result<(), TransformerError> {
        self.validate_shapes()?;
        let shape = &self.shape;
        check_io(shape, trajectory, condition, output)?;
        let lens = shape.quantized_scratch::<P>();
        let floats = prefix(buffers.floats, lens.floats, ScratchBuffer::Floats)?;
        let codes = prefix(buffers.codes, lens.codes, ScratchBuffer::Codes)?;
        let accumulators = prefix(
            buffers.accumulators,
            lens.accumulators,
            ScratchBuffer::Accumulators,
        )?;
        let (tw, head_dim, tokens) = (shape.token_values(), shape.head_dim(), shape.tokens());
        let mut rest = floats;
        let buffer = ScratchBuffer::Floats;
        let residual = take(&mut rest, tw, buffer)?;
        let keys = take(&mut rest, tokens * head_dim, buffer)?;
        let values = take(&mut rest, tokens * head_dim, buffer)?;
        let query = take(&mut rest, head_dim, buffer)?;
        let head_out = take(&mut rest, head_dim, buffer)?;
        let scores = take(&mut rest, tokens, buffer)?;
        let row = take(&mut rest, shape.width, buffer)?;

        embed_tokens(
            shape,
            self.positions,
            self.noise_token,
            trajectory,
            condition,
            residual,
            |input, values, token| {
                let layer = match input {
                    TokenInput::Condition => &self.cond_in,
                    TokenInput::Step => &self.traj_in,
                };
                Ok(layer.forward(values, codes, accumulators, token)?)
            },
        )?;

        let mut rest = codes;
        let normed = take(&mut rest, tw, ScratchBuffer::Codes)?;
        let attention = take(&mut rest, tw, ScratchBuffer::Codes)?;
        let hidden = take(&mut rest, shape.hidden(), ScratchBuffer::Codes)?;
        let mut work = BlockWork {
            residual,
            normed,
            attention,
            hidden,
            keys,
            values,
            query,
            head_out,
            scores,
            row,
            accumulators,
        };
        let mut ignore = |_: TransformerProbe, _: &[f32]| {};
        run_blocks(shape, self.blocks, &mut work, &mut ignore)?;
        finish(
            shape,
            &self.final_norm,
            &self.head,
            &mut work,
            output,
            &mut ignore,
        )
    }
}
