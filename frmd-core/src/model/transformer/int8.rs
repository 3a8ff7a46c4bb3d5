//! Hybrid int8 forward pass of the transformer backbone: int8 linear layers, f32 residual stream,
//! LayerNorm and attention (see the module docs of [`super`]).

use super::{
    add_assign, attend, attention_scale, check_common, check_f32_linear, check_io, embed_tokens,
    take, LayerNormWeights, Part, ScratchBuffer, TokenInput, TransformerError, TransformerScratch,
    TransformerShape,
};
use crate::kernels::{dequantize_accumulators, FcRequant, FullyConnected, KernelError, Lut8};
use crate::model::mlp::F32Layer;
use crate::quant::QuantParams;

/// An int8 linear layer with f32 input and output: the input is quantized per tensor with
/// `input`, multiplied by per-channel symmetric int8 weights with int32 accumulation, and the
/// accumulators are dequantized per channel: `output[o] = acc[o] * output_scales[o]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Int8Linear<'a> {
    /// Quantization of the f32 input (calibrated at the layer's input).
    pub input: QuantParams,
    /// int8 weights `[out, in]` and int32 bias at scale `input.scale * weight_scale[o]` with
    /// `input.zero_point` folded in.
    pub fc: FullyConnected<'a>,
    /// `[out]` dequantization scales `input.scale * weight_scale[o]`.
    pub output_scales: &'a [f32],
}

/// `codes[i] = quantize(values[i], params)` over the common length.
fn quantize_into(values: &[f32], params: QuantParams, codes: &mut [i8]) {
    for (code, value) in codes.iter_mut().zip(values) {
        *code = params.quantize(*value);
    }
}

impl<'a> Int8Linear<'a> {
    fn check(
        &self,
        in_features: usize,
        out_features: usize,
        part: Part,
    ) -> Result<(), TransformerError> {
        self.input
            .validate()
            .map_err(|_| TransformerError::InputParams { part })?;
        self.fc
            .validate()
            .map_err(|error| TransformerError::Weights { part, error })?;
        if self.fc.in_features != in_features || self.fc.out_features != out_features {
            return Err(TransformerError::Features { part });
        }
        if self.output_scales.len() != out_features {
            return Err(TransformerError::Weights {
                part,
                error: KernelError::ScaleLength,
            });
        }
        Ok(())
    }

    /// Output channels `start .. start + count` as a layer of their own (a head's slice of `qkv`).
    pub fn rows(&self, start: usize, count: usize) -> Result<Self, KernelError> {
        let in_features = self.fc.in_features;
        let end = start.checked_add(count).ok_or(KernelError::WeightsLength)?;
        let weights = start
            .checked_mul(in_features)
            .zip(end.checked_mul(in_features))
            .and_then(|(from, to)| self.fc.weights.get(from..to))
            .ok_or(KernelError::WeightsLength)?;
        let bias = self
            .fc
            .bias
            .get(start..end)
            .ok_or(KernelError::BiasLength)?;
        let output_scales = self
            .output_scales
            .get(start..end)
            .ok_or(KernelError::ScaleLength)?;
        Ok(Self {
            input: self.input,
            fc: FullyConnected::new(in_features, count, weights, bias),
            output_scales,
        })
    }

    /// Quantizes `input` into `quantized` (same length), then [`Int8Linear::forward_quantized`].
    pub fn forward(
        &self,
        input: &[f32],
        quantized: &mut [i8],
        accumulators: &mut [i32],
        output: &mut [f32],
    ) -> Result<(), KernelError> {
        if quantized.len() != input.len() {
            return Err(KernelError::InputLength);
        }
        quantize_into(input, self.input, quantized);
        self.forward_quantized(quantized, accumulators, output)
    }

    /// int8 input (already quantized with `self.input`) to dequantized f32 output;
    /// `accumulators` and `output` are `out_features` long.
    pub fn forward_quantized(
        &self,
        input: &[i8],
        accumulators: &mut [i32],
        output: &mut [f32],
    ) -> Result<(), KernelError> {
        self.fc.forward_accumulators(input, accumulators)?;
        dequantize_accumulators(accumulators, self.output_scales, output)
    }
}

/// An input layer (`traj_in`, `cond_in`) that may stay f32 or run as int8.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TokenLinear<'a> {
    /// f32 weights (activation must be `Identity`).
    Float(F32Layer<'a>),
    /// int8 weights.
    Int8(Int8Linear<'a>),
}

impl TokenLinear<'_> {
    fn check(
        &self,
        in_features: usize,
        out_features: usize,
        part: Part,
    ) -> Result<(), TransformerError> {
        match self {
            Self::Float(layer) => check_f32_linear(layer, in_features, out_features, part),
            Self::Int8(layer) => layer.check(in_features, out_features, part),
        }
    }

    /// `output = layer(input)`; the int8 variant uses the first `input.len()` codes of `bytes`
    /// and the first `output.len()` accumulators.
    fn forward(
        &self,
        input: &[f32],
        bytes: &mut [i8],
        accumulators: &mut [i32],
        output: &mut [f32],
    ) -> Result<(), KernelError> {
        match self {
            Self::Float(layer) => layer.forward(input, output, None),
            Self::Int8(layer) => {
                let quantized = bytes
                    .get_mut(..input.len())
                    .ok_or(KernelError::InputLength)?;
                let acc = accumulators
                    .get_mut(..output.len())
                    .ok_or(KernelError::OutputLength)?;
                layer.forward(input, quantized, acc, output)
            }
        }
    }
}

/// int8 feed-forward `fc2(gelu(fc1(x)))` of one token: `x` quantized with `input`, `fc1`
/// requantized to int8 (parameters of the GELU input), GELU by table, `fc2` dequantized to f32.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Int8FeedForward<'a> {
    /// Quantization of the LN2 output (`fc1` input).
    pub input: QuantParams,
    /// `W -> 4W`, bias with `input.zero_point` folded.
    pub fc1: FullyConnected<'a>,
    /// Per-channel requantization of `fc1` to the GELU input parameters (zero point and scale of
    /// the calibrated `fc1` output; clamp normally `-128..=127`).
    pub fc1_requant: FcRequant<'a>,
    /// GELU table from the `fc1` output parameters to the `fc2` input parameters.
    pub gelu: &'a Lut8,
    /// `4W -> W`, bias with the GELU output zero point folded.
    pub fc2: FullyConnected<'a>,
    /// `[W]` dequantization scales `gelu_output_scale * weight_scale[o]`.
    pub fc2_scales: &'a [f32],
}

impl Int8FeedForward<'_> {
    fn check(&self, width: usize, hidden: usize, layer: usize) -> Result<(), TransformerError> {
        let (fc1, fc2) = (Part::Fc1 { layer }, Part::Fc2 { layer });
        self.input
            .validate()
            .map_err(|_| TransformerError::InputParams { part: fc1 })?;
        for (fc, part, in_features, out_features) in [
            (&self.fc1, fc1, width, hidden),
            (&self.fc2, fc2, hidden, width),
        ] {
            fc.validate()
                .map_err(|error| TransformerError::Weights { part, error })?;
            if fc.in_features != in_features || fc.out_features != out_features {
                return Err(TransformerError::Features { part });
            }
        }
        self.fc1_requant
            .validate(hidden)
            .map_err(|error| TransformerError::Weights { part: fc1, error })?;
        if self.fc2_scales.len() != width {
            return Err(TransformerError::Weights {
                part: fc2,
                error: KernelError::ScaleLength,
            });
        }
        Ok(())
    }

    /// Replaces `values` (`W`) by `fc2(gelu(fc1(values)))`, using `quantized` (`W`), `hidden`
    /// (`4W`) and `accumulators` (`W`) as scratch.
    pub fn forward_in_place(
        &self,
        values: &mut [f32],
        quantized: &mut [i8],
        hidden: &mut [i8],
        accumulators: &mut [i32],
    ) -> Result<(), KernelError> {
        if quantized.len() != values.len() {
            return Err(KernelError::InputLength);
        }
        quantize_into(values, self.input, quantized);
        self.fc1.forward(&self.fc1_requant, quantized, hidden)?;
        self.gelu.apply_in_place(hidden);
        self.fc2.forward_accumulators(hidden, accumulators)?;
        dequantize_accumulators(accumulators, self.fc2_scales, values)
    }
}

/// One pre-LayerNorm block with int8 linear layers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Int8Block<'a> {
    /// LayerNorm before attention (f32).
    pub norm1: LayerNormWeights<'a>,
    /// `W -> 3W`, outputs `[q | k | v]`, each `[heads, head_dim]`; input = LN1 output.
    pub qkv: Int8Linear<'a>,
    /// `W -> W`; input = concatenated head outputs.
    pub proj: Int8Linear<'a>,
    /// LayerNorm before the feed-forward (f32).
    pub norm2: LayerNormWeights<'a>,
    /// `fc1`, GELU table, `fc2`.
    pub feed_forward: Int8FeedForward<'a>,
}

impl Int8Block<'_> {
    fn check(&self, shape: &TransformerShape, layer: usize) -> Result<(), TransformerError> {
        let width = shape.width;
        let qkv_width = width.checked_mul(3).ok_or(TransformerError::SizeOverflow)?;
        self.norm1.check(width, Part::Norm1 { layer })?;
        self.qkv.check(width, qkv_width, Part::Qkv { layer })?;
        self.proj.check(width, width, Part::Proj { layer })?;
        self.norm2.check(width, Part::Norm2 { layer })?;
        self.feed_forward.check(width, shape.hidden(), layer)
    }
}

/// Hybrid int8 transformer backbone over borrowed (typically `&'static` baked) weights.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Int8Transformer<'a> {
    /// Sizes.
    pub shape: TransformerShape,
    /// `k -> W`, applied to each trajectory step. Its input is the `c_in`-scaled trajectory; an
    /// exporter may instead fold `c_in(sigma)` into the int8 variant's input scale
    /// (`scale / c_in`) and have the caller pass the unscaled trajectory.
    pub traj_in: TokenLinear<'a>,
    /// `cond_dim -> W`.
    pub cond_in: TokenLinear<'a>,
    /// `[W]` constant noise token `noise_in(embedding(sigma)) + positions[1]`
    /// ([`super::fold_noise_token`]). A few-step sampler keeps one token per noise level and
    /// copies the model with the right one (`Int8Transformer { noise_token, ..model }`).
    pub noise_token: &'a [f32],
    /// `[T, W]` learned positions; row 1 is not read (folded into `noise_token`).
    pub positions: &'a [f32],
    /// `shape.layers` blocks.
    pub blocks: &'a [Int8Block<'a>],
    /// Final LayerNorm (f32).
    pub final_norm: LayerNormWeights<'a>,
    /// `T W -> output`, dequantized to f32; input = final LayerNorm outputs, flattened.
    pub head: Int8Linear<'a>,
}

impl Int8Transformer<'_> {
    /// Checks every part against the shape (including quantization parameters).
    pub fn validate(&self) -> Result<(), TransformerError> {
        let shape = &self.shape;
        check_common(
            shape,
            self.blocks.len(),
            self.positions,
            self.noise_token,
            &self.final_norm,
        )?;
        self.traj_in
            .check(shape.action_dim, shape.width, Part::TrajIn)?;
        self.cond_in
            .check(shape.cond_dim, shape.width, Part::CondIn)?;
        for (layer, block) in self.blocks.iter().enumerate() {
            block.check(shape, layer)?;
        }
        self.head
            .check(shape.token_values(), shape.output, Part::Head)
    }

    /// Runs the backbone (same arguments as [`super::F32Transformer::forward`]); the scratch must
    /// hold at least [`TransformerShape::int8_scratch`] elements in each buffer.
    pub fn forward<const F: usize, const B: usize, const A: usize>(
        &self,
        trajectory: &[f32],
        condition: &[f32],
        output: &mut [f32],
        scratch: &mut TransformerScratch<F, B, A>,
    ) -> Result<(), TransformerError> {
        self.validate()?;
        let shape = &self.shape;
        check_io(shape, trajectory, condition, output)?;
        let lens = shape.int8_scratch();
        let too_small = |buffer, needed| TransformerError::ScratchTooSmall { buffer, needed };
        let floats = scratch
            .floats
            .get_mut(..lens.floats)
            .ok_or(too_small(ScratchBuffer::Floats, lens.floats))?;
        let bytes = scratch
            .bytes
            .get_mut(..lens.bytes)
            .ok_or(too_small(ScratchBuffer::Bytes, lens.bytes))?;
        let accumulators = scratch
            .accumulators
            .get_mut(..lens.accumulators)
            .ok_or(too_small(ScratchBuffer::Accumulators, lens.accumulators))?;
        let (tw, width, head_dim, tokens) = (
            shape.token_values(),
            shape.width,
            shape.head_dim(),
            shape.tokens(),
        );
        let mut rest = floats;
        let buffer = ScratchBuffer::Floats;
        let residual = take(&mut rest, tw, buffer)?;
        let keys = take(&mut rest, tokens * head_dim, buffer)?;
        let values = take(&mut rest, tokens * head_dim, buffer)?;
        let query = take(&mut rest, head_dim, buffer)?;
        let head_out = take(&mut rest, head_dim, buffer)?;
        let scores = take(&mut rest, tokens, buffer)?;
        let row = take(&mut rest, width, buffer)?;

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
        let too_few = TransformerError::ScratchTooSmall {
            buffer: ScratchBuffer::Accumulators,
            needed: lens.accumulators,
        };
        let scale = attention_scale(head_dim);
        for block in self.blocks {
            for (x, n) in residual
                .chunks_exact(width)
                .zip(normed.chunks_exact_mut(width))
            {
                block.norm1.apply(x, row)?;
                quantize_into(row, block.qkv.input, n);
            }
            let acc = accumulators.get_mut(..head_dim).ok_or(too_few)?;
            for head in 0..shape.heads {
                let start = head * head_dim;
                let query_layer = block.qkv.rows(start, head_dim)?;
                let key_layer = block.qkv.rows(width + start, head_dim)?;
                let value_layer = block.qkv.rows(2 * width + start, head_dim)?;
                let rows = normed
                    .chunks_exact(width)
                    .zip(keys.chunks_exact_mut(head_dim))
                    .zip(values.chunks_exact_mut(head_dim));
                for ((n, key), value) in rows {
                    key_layer.forward_quantized(n, acc, key)?;
                    value_layer.forward_quantized(n, acc, value)?;
                }
                for (n, out) in normed
                    .chunks_exact(width)
                    .zip(attention.chunks_exact_mut(width))
                {
                    query_layer.forward_quantized(n, acc, query)?;
                    attend(query, keys, values, scale, scores, head_out)?;
                    let out = out
                        .get_mut(start..start + head_dim)
                        .ok_or(TransformerError::Kernel(KernelError::OutputLength))?;
                    quantize_into(head_out, block.proj.input, out);
                }
            }
            let acc = accumulators.get_mut(..width).ok_or(too_few)?;
            for (x, a) in residual
                .chunks_exact_mut(width)
                .zip(attention.chunks_exact(width))
            {
                block.proj.forward_quantized(a, acc, row)?;
                add_assign(x, row);
            }
            let quantized_row = normed.get_mut(..width).ok_or(too_few)?;
            for x in residual.chunks_exact_mut(width) {
                block.norm2.apply(x, row)?;
                block
                    .feed_forward
                    .forward_in_place(row, quantized_row, hidden, acc)?;
                add_assign(x, row);
            }
        }
        for (x, n) in residual
            .chunks_exact(width)
            .zip(normed.chunks_exact_mut(width))
        {
            self.final_norm.apply(x, row)?;
            quantize_into(row, self.head.input, n);
        }
        let acc = accumulators.get_mut(..shape.output).ok_or(too_few)?;
        self.head.forward_quantized(normed, acc, output)?;
        Ok(())
    }
}
