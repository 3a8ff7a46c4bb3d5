//! The hybrid int8 form of the transformer ([`Int8Transformer`]): int8 linear layers, f32 residual
//! stream, LayerNorm and attention (see the module docs of [`super`]).

use super::block::{attend, embed_tokens, finish, run_blocks, BlockWork, TokenInput};
use super::block::{FeedForwardSteps, LinearSteps};
use super::float::feed_forward_error;
use super::shape::{prefix, take};
use super::{
    check_io, BlockLinear, CheckedLinear, FeedForward, Int8Transformer, Part, ScratchBuffer,
    TransformerBuffers, TransformerError, TransformerProbe, TransformerScratch,
};
use crate::kernels::KernelError;
use crate::model::linear::{quantize_into, F32Linear, QuantizedLinear, RequantizedLinear};
use crate::model::mlp::{Int8Buffers, Int8Mlp};
use crate::quant::QuantParams;

/// An input layer (`traj_in`, `cond_in`) that may stay f32 or run as int8.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TokenLinear<'a> {
    /// f32 weights (activation must be `Identity`).
    Float(F32Linear<'a>),
    /// int8 weights.
    Int8(QuantizedLinear<'a>),
}

impl TokenLinear<'_> {
    /// `output = layer(input)`; the int8 variant uses the first `input.len()` codes of `bytes`
    /// and the first `output.len()` accumulators.
    pub fn forward(
        &self,
        input: &[f32],
        bytes: &mut [i8],
        accumulators: &mut [i32],
        output: &mut [f32],
    ) -> Result<(), KernelError> {
        match self {
            Self::Float(layer) => layer.forward(input, output),
            Self::Int8(layer) => {
                let codes = bytes
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

/// The int8 feed-forward `fc2(gelu(fc1(x)))` of one token as a one-hidden-layer [`Int8Mlp`]:
/// `x` quantized with `input`, `fc1` requantized to the GELU table's input parameters, the table,
/// `fc2` dequantized to f32.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Int8FeedForward<'a> {
    /// Quantization of the LN2 output (`fc1` input).
    pub input: QuantParams,
    /// `W -> 4W`, bias with `input.zero_point` folded, requantized to the `fc1` output params
    /// (clamp normally `-128..=127`), then the GELU table (required) to the `fc2` input params.
    pub fc1: RequantizedLinear<'a>,
    /// `4W -> W`: its input parameters are the GELU table's output parameters (the codes arrive
    /// quantized; its bias has their zero point folded, its scales are
    /// `gelu_output_scale * weight_scale[o]`).
    pub fc2: QuantizedLinear<'a>,
}

impl Int8FeedForward<'_> {
    /// The feed-forward as an MLP.
    pub fn mlp(&self) -> Int8Mlp<'_> {
        Int8Mlp {
            input: self.input,
            hidden: core::slice::from_ref(&self.fc1),
            output: self.fc2.linear,
        }
    }
}

fn check_quantized(
    layer: &QuantizedLinear<'_>,
    in_features: usize,
    out_features: usize,
    part: Part,
) -> Result<(), TransformerError> {
    layer
        .input
        .validate()
        .map_err(|_| TransformerError::InputParams { part })?;
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

impl CheckedLinear for QuantizedLinear<'_> {
    fn check(
        &self,
        in_features: usize,
        out_features: usize,
        part: Part,
    ) -> Result<(), TransformerError> {
        check_quantized(self, in_features, out_features, part)
    }
}

impl BlockLinear for QuantizedLinear<'_> {
    type Code = i8;
}

impl CheckedLinear for TokenLinear<'_> {
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
            TokenLinear::Int8(layer) => check_quantized(layer, in_features, out_features, part),
        }
    }
}

impl FeedForward for Int8FeedForward<'_> {
    fn check(&self, width: usize, hidden: usize, layer: usize) -> Result<(), TransformerError> {
        let (fc1, fc2) = (Part::Fc1 { layer }, Part::Fc2 { layer });
        self.input
            .validate()
            .map_err(|_| TransformerError::InputParams { part: fc1 })?;
        for (fc, part, in_features, out_features) in [
            (&self.fc1.fc, fc1, width, hidden),
            (&self.fc2.linear.fc, fc2, hidden, width),
        ] {
            fc.validate()
                .map_err(|error| TransformerError::Weights { part, error })?;
            if fc.in_features != in_features || fc.out_features != out_features {
                return Err(TransformerError::Features { part });
            }
        }
        self.fc1
            .requant
            .validate(hidden)
            .map_err(|error| TransformerError::Weights { part: fc1, error })?;
        if self.fc1.activation.is_none() {
            return Err(TransformerError::Activation { part: fc1 });
        }
        if self.fc2.linear.output_scales.len() != width {
            return Err(TransformerError::Weights {
                part: fc2,
                error: KernelError::ScaleLength,
            });
        }
        Ok(())
    }
}

impl LinearSteps for QuantizedLinear<'_> {
    fn rows(&self, start: usize, count: usize) -> Result<Self, KernelError> {
        QuantizedLinear::rows(self, start, count)
    }

    fn encode(&self, values: &[f32], codes: &mut [i8]) {
        quantize_into(values, self.input, codes);
    }

    fn apply(
        &self,
        codes: &[i8],
        accumulators: &mut [i32],
        output: &mut [f32],
    ) -> Result<(), KernelError> {
        let acc = accumulators
            .get_mut(..output.len())
            .ok_or(KernelError::OutputLength)?;
        self.linear.forward(codes, acc, output)
    }

    fn attend_head(
        &self,
        query: &[f32],
        keys: &[f32],
        values: &[f32],
        scale: f32,
        scores: &mut [f32],
        head_out: &mut [f32],
        out: &mut [i8],
    ) -> Result<(), KernelError> {
        attend(query, keys, values, scale, scores, head_out)?;
        quantize_into(head_out, self.input, out);
        Ok(())
    }

    fn observed(_codes: &[i8]) -> Option<&[f32]> {
        None
    }
}

impl FeedForwardSteps<i8> for Int8FeedForward<'_> {
    fn run<O: FnMut(TransformerProbe, &[f32])>(
        &self,
        layer: usize,
        row: &mut [f32],
        codes: &mut [i8],
        hidden: &mut [i8],
        accumulators: &mut [i32],
        _observe: &mut O,
    ) -> Result<(), TransformerError> {
        let buffers = Int8Buffers {
            ping: codes,
            pong: hidden,
            accumulators,
        };
        self.mlp()
            .forward_in_place_prevalidated(row, buffers)
            .map_err(|error| feed_forward_error(error, layer))
    }
}

impl Int8Transformer<'_> {
    /// Runs the backbone (same arguments as [`super::F32Transformer::forward`]); the scratch must
    /// hold at least [`super::TransformerShape::int8_scratch`] elements in each buffer.
    pub fn forward<const F: usize, const B: usize, const A: usize>(
        &self,
        trajectory: &[f32],
        condition: &[f32],
        output: &mut [f32],
        scratch: &mut TransformerScratch<F, B, A>,
    ) -> Result<(), TransformerError> {
        self.forward_in(trajectory, condition, output, scratch.buffers())
    }

    /// [`Self::forward`] on borrowed buffers.
    pub fn forward_in(
        &self,
        trajectory: &[f32],
        condition: &[f32],
        output: &mut [f32],
        buffers: TransformerBuffers<'_>,
    ) -> Result<(), TransformerError> {
        self.validate()?;
        let shape = &self.shape;
        check_io(shape, trajectory, condition, output)?;
        let lens = shape.int8_scratch();
        let floats = prefix(buffers.floats, lens.floats, ScratchBuffer::Floats)?;
        let bytes = prefix(buffers.bytes, lens.bytes, ScratchBuffer::Bytes)?;
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
                Ok(layer.forward(values, bytes, accumulators, token)?)
            },
        )?;

        let mut rest = bytes;
        let normed = take(&mut rest, tw, ScratchBuffer::Bytes)?;
        let attention = take(&mut rest, tw, ScratchBuffer::Bytes)?;
        let hidden = take(&mut rest, shape.hidden(), ScratchBuffer::Bytes)?;
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
