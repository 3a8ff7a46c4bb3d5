//! f32 reference forward pass of the transformer backbone, with calibration probes.

use super::{
    add_assign, attend, attention_scale, check_common, check_f32_linear, check_io, embed_tokens,
    f32_rows, take, LayerNormWeights, Part, ScratchBuffer, TokenInput, TransformerError,
    TransformerScratch, TransformerShape, LAYER_NORM_EPSILON,
};
use crate::kernels::{gelu_sigmoid, layer_norm_in_place, KernelError};
use crate::model::mlp::F32Layer;

/// One pre-LayerNorm block with f32 weights. Every linear layer must have
/// `activation: Identity`; the block applies [`gelu_sigmoid`] after `fc1` itself.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct F32Block<'a> {
    /// LayerNorm before attention.
    pub norm1: LayerNormWeights<'a>,
    /// `W -> 3W`, outputs `[q | k | v]`, each `[heads, head_dim]`.
    pub qkv: F32Layer<'a>,
    /// `W -> W` attention output projection.
    pub proj: F32Layer<'a>,
    /// LayerNorm before the feed-forward.
    pub norm2: LayerNormWeights<'a>,
    /// `W -> 4W`.
    pub fc1: F32Layer<'a>,
    /// `4W -> W`.
    pub fc2: F32Layer<'a>,
}

impl F32Block<'_> {
    fn check(&self, shape: &TransformerShape, layer: usize) -> Result<(), TransformerError> {
        let (width, hidden) = (shape.width, shape.hidden());
        let qkv_width = width.checked_mul(3).ok_or(TransformerError::SizeOverflow)?;
        self.norm1.check(width, Part::Norm1 { layer })?;
        check_f32_linear(&self.qkv, width, qkv_width, Part::Qkv { layer })?;
        check_f32_linear(&self.proj, width, width, Part::Proj { layer })?;
        self.norm2.check(width, Part::Norm2 { layer })?;
        check_f32_linear(&self.fc1, width, hidden, Part::Fc1 { layer })?;
        check_f32_linear(&self.fc2, hidden, width, Part::Fc2 { layer })
    }
}

/// A tensor shown to the [`F32Transformer::forward_observed`] callback. Probes marked "per token"
/// are reported once per token row (`W` or `4W` values), the others once per forward pass; a
/// calibration range is the union over all calls.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TransformerProbe {
    /// The trajectory input (`n k`): `traj_in`'s input.
    Trajectory,
    /// The condition vector (`cond_dim`): `cond_in`'s input.
    Condition,
    /// The embedded tokens plus positions (`T W`), before the first block.
    Tokens,
    /// LN1 outputs of block `layer` (`T W`): the `qkv` input.
    Norm1 {
        /// Block index.
        layer: usize,
    },
    /// Concatenated head outputs of block `layer` (`T W`): the `proj` input.
    Attention {
        /// Block index.
        layer: usize,
    },
    /// LN2 output of one token (per token, `W`): the `fc1` input.
    Norm2 {
        /// Block index.
        layer: usize,
    },
    /// `fc1` output of one token before GELU (per token, `4W`): the LUT input.
    Fc1 {
        /// Block index.
        layer: usize,
    },
    /// GELU output of one token (per token, `4W`): the LUT output and `fc2` input.
    Gelu {
        /// Block index.
        layer: usize,
    },
    /// The residual stream after block `layer` (`T W`).
    Block {
        /// Block index.
        layer: usize,
    },
    /// Final LayerNorm outputs (`T W`): the `head` input.
    FinalNorm,
    /// The head output (`output`).
    Output,
}

/// f32 transformer backbone over borrowed weights (see the module docs for the structure).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct F32Transformer<'a> {
    /// Sizes.
    pub shape: TransformerShape,
    /// `k -> W`, applied to each trajectory step.
    pub traj_in: F32Layer<'a>,
    /// `cond_dim -> W`.
    pub cond_in: F32Layer<'a>,
    /// `[W]` noise token `noise_in(embedding(sigma)) + positions[1]` ([`fold_noise_token`]).
    pub noise_token: &'a [f32],
    /// `[T, W]` learned positions; row 1 is not read (it is folded into `noise_token`).
    pub positions: &'a [f32],
    /// `shape.layers` blocks.
    pub blocks: &'a [F32Block<'a>],
    /// Final LayerNorm.
    pub final_norm: LayerNormWeights<'a>,
    /// `T W -> output`.
    pub head: F32Layer<'a>,
}

/// `token = noise_in(embedding) + positions[1]` in f32: the constant noise token for a fixed noise
/// level (exporter) or the per-call token when the noise level varies. `positions` is the full
/// `[T, W]` table; `token` is `W` long.
pub fn fold_noise_token(
    shape: &TransformerShape,
    noise_in: &F32Layer<'_>,
    embedding: &[f32],
    positions: &[f32],
    token: &mut [f32],
) -> Result<(), TransformerError> {
    shape.validate()?;
    check_f32_linear(noise_in, noise_in.in_features, shape.width, Part::NoiseIn)?;
    if embedding.len() != noise_in.in_features {
        return Err(TransformerError::EmbeddingLength);
    }
    if embedding.iter().any(|v| !v.is_finite()) {
        return Err(TransformerError::NonFiniteInput);
    }
    if positions.len() != shape.token_values() {
        return Err(TransformerError::Features {
            part: Part::Positions,
        });
    }
    let position =
        positions
            .chunks_exact(shape.width)
            .nth(1)
            .ok_or(TransformerError::Features {
                part: Part::Positions,
            })?;
    if token.len() != shape.width {
        return Err(TransformerError::Features {
            part: Part::NoiseToken,
        });
    }
    noise_in.forward(embedding, token, None)?;
    add_assign(token, position);
    Ok(())
}

impl F32Transformer<'_> {
    /// Checks every part against the shape.
    pub fn validate(&self) -> Result<(), TransformerError> {
        let shape = &self.shape;
        check_common(
            shape,
            self.blocks.len(),
            self.positions,
            self.noise_token,
            &self.final_norm,
        )?;
        check_f32_linear(&self.traj_in, shape.action_dim, shape.width, Part::TrajIn)?;
        check_f32_linear(&self.cond_in, shape.cond_dim, shape.width, Part::CondIn)?;
        for (layer, block) in self.blocks.iter().enumerate() {
            block.check(shape, layer)?;
        }
        check_f32_linear(&self.head, shape.token_values(), shape.output, Part::Head)
    }

    /// Runs the backbone: `trajectory` is the `c_in`-scaled noisy trajectory (`[n, k]` row-major),
    /// `condition` the `cond_dim` condition vector; writes `shape.output` values to `output`.
    pub fn forward<const F: usize, const B: usize, const A: usize>(
        &self,
        trajectory: &[f32],
        condition: &[f32],
        output: &mut [f32],
        scratch: &mut TransformerScratch<F, B, A>,
    ) -> Result<(), TransformerError> {
        self.forward_observed(trajectory, condition, output, scratch, |_, _| {})
    }

    /// [`F32Transformer::forward`] that shows the tensors of [`TransformerProbe`] to `observe`
    /// (e.g. to record the calibration ranges of the int8 path's quantization points).
    pub fn forward_observed<const F: usize, const B: usize, const A: usize, O>(
        &self,
        trajectory: &[f32],
        condition: &[f32],
        output: &mut [f32],
        scratch: &mut TransformerScratch<F, B, A>,
        mut observe: O,
    ) -> Result<(), TransformerError>
    where
        O: FnMut(TransformerProbe, &[f32]),
    {
        self.validate()?;
        let shape = &self.shape;
        check_io(shape, trajectory, condition, output)?;
        let needed = shape.f32_scratch().floats;
        let floats = scratch
            .floats
            .get_mut(..needed)
            .ok_or(TransformerError::ScratchTooSmall {
                buffer: ScratchBuffer::Floats,
                needed,
            })?;
        let (tw, width, head_dim, tokens) = (
            shape.token_values(),
            shape.width,
            shape.head_dim(),
            shape.tokens(),
        );
        let mut rest = floats;
        let buffer = ScratchBuffer::Floats;
        let residual = take(&mut rest, tw, buffer)?;
        let normed = take(&mut rest, tw, buffer)?;
        let attention = take(&mut rest, tw, buffer)?;
        let keys = take(&mut rest, tokens * head_dim, buffer)?;
        let values = take(&mut rest, tokens * head_dim, buffer)?;
        let query = take(&mut rest, head_dim, buffer)?;
        let scores = take(&mut rest, tokens, buffer)?;
        let hidden = take(&mut rest, shape.hidden(), buffer)?;
        let row = take(&mut rest, width, buffer)?;

        observe(TransformerProbe::Trajectory, trajectory);
        observe(TransformerProbe::Condition, condition);
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
                Ok(layer.forward(values, token, None)?)
            },
        )?;
        observe(TransformerProbe::Tokens, residual);

        let scale = attention_scale(head_dim);
        for (layer, block) in self.blocks.iter().enumerate() {
            for (x, n) in residual
                .chunks_exact(width)
                .zip(normed.chunks_exact_mut(width))
            {
                block.norm1.apply(x, n)?;
            }
            observe(TransformerProbe::Norm1 { layer }, normed);
            for head in 0..shape.heads {
                let start = head * head_dim;
                let query_layer = f32_rows(&block.qkv, start, head_dim)?;
                let key_layer = f32_rows(&block.qkv, width + start, head_dim)?;
                let value_layer = f32_rows(&block.qkv, 2 * width + start, head_dim)?;
                let rows = normed
                    .chunks_exact(width)
                    .zip(keys.chunks_exact_mut(head_dim))
                    .zip(values.chunks_exact_mut(head_dim));
                for ((n, key), value) in rows {
                    key_layer.forward(n, key, None)?;
                    value_layer.forward(n, value, None)?;
                }
                for (n, out) in normed
                    .chunks_exact(width)
                    .zip(attention.chunks_exact_mut(width))
                {
                    query_layer.forward(n, query, None)?;
                    let out = out
                        .get_mut(start..start + head_dim)
                        .ok_or(TransformerError::Kernel(KernelError::OutputLength))?;
                    attend(query, keys, values, scale, scores, out)?;
                }
            }
            observe(TransformerProbe::Attention { layer }, attention);
            for (x, a) in residual
                .chunks_exact_mut(width)
                .zip(attention.chunks_exact(width))
            {
                block.proj.forward(a, row, None)?;
                add_assign(x, row);
            }
            for x in residual.chunks_exact_mut(width) {
                block.norm2.apply(x, row)?;
                observe(TransformerProbe::Norm2 { layer }, row);
                block.fc1.forward(row, hidden, None)?;
                observe(TransformerProbe::Fc1 { layer }, hidden);
                for h in hidden.iter_mut() {
                    *h = gelu_sigmoid(*h);
                }
                observe(TransformerProbe::Gelu { layer }, hidden);
                block.fc2.forward(hidden, row, None)?;
                add_assign(x, row);
            }
            observe(TransformerProbe::Block { layer }, residual);
        }
        for x in residual.chunks_exact_mut(width) {
            layer_norm_in_place(
                x,
                self.final_norm.gamma,
                self.final_norm.beta,
                LAYER_NORM_EPSILON,
            )?;
        }
        observe(TransformerProbe::FinalNorm, residual);
        self.head.forward(residual, output, None)?;
        observe(TransformerProbe::Output, output);
        Ok(())
    }
}
