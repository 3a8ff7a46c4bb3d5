//! Transformer backbone (transformer-lite) built from [`crate::model::linear`]: one generic
//! [`Transformer`] of [`Block`]s, generic over its layers' precision: f32 ([`F32Transformer`],
//! the reference, with calibration probes) or the hybrid quantized form ([`QuantTransformer`]:
//! [`Int8Transformer`], or [`Int16Transformer`] with int16 activations); every form shares the
//! block skeleton and the validation, over borrowed weights.
//!
//! # Structure (mirrors `frmd-host` `models::transformer::Transformer`)
//!
//! With `n = horizon`, `k = action_dim`, `T = n + 2` tokens of width `W`:
//! 1. tokens `[cond, noise, step_0 .. step_{n-1}]`: `cond = cond_in(condition) + pos[0]`,
//!    `noise = noise_in(embedding(sigma)) + pos[1]` (a constant row folded by the exporter, see
//!    [`fold_noise_token`]), `step_i = traj_in(x[i k .. (i+1) k]) + pos[2 + i]`, where `x` is the
//!    `c_in`-scaled noisy trajectory (row-major `[n, k]`) and `pos` the learned `[T, W]` positions;
//! 2. `L` pre-LayerNorm blocks, each
//!    `x += proj(attention(qkv(LN1(x))))`, then `x += fc2(gelu_sigmoid(fc1(LN2(x))))`, with
//!    `qkv` output laid out `[q | k | v]`, each `[heads, head_dim]` (candle's
//!    `reshape(T, 3, heads, head_dim)`), per-head `softmax(q k^T / sqrt(head_dim)) v`, heads
//!    concatenated in order before `proj`; the feed-forward is a one-hidden-layer MLP
//!    ([`crate::model::mlp`]) `W -> 4W -> W` whose activation is
//!    [`crate::kernels::gelu_sigmoid`] (`x sigmoid(1.702 x)`);
//! 3. a final LayerNorm on every token, then `head` over the flattened `[T * W]` tokens (token
//!    major), giving `output` values (ProDMP parameters or a raw trajectory).
//!
//! LayerNorms use epsilon [`LAYER_NORM_EPSILON`] (candle `layer_norm_slow(.., 1e-5)`).
//!
//! # int8 hybrid form ([`Int8Transformer`])
//!
//! The residual stream stays f32. Every linear layer (`traj_in` and `cond_in` optionally, `qkv`,
//! `proj`, `head`) is a [`QuantizedLinear`]: its f32 input is quantized per tensor (asymmetric,
//! calibrated) and its int8 x int8 -> int32 accumulators are dequantized per channel. The
//! feed-forward is an int8 MLP: `fc1` requantized to int8 and mapped through a 256-entry GELU
//! table, `fc2` dequantized ([`Int8FeedForward`]). LayerNorm and the attention (scores, softmax,
//! weighted sum of values) run in f32.
//!
//! [`Int16Transformer`] is the same with TFLite's 16x8 scheme: every quantization point is a
//! symmetric int16 code (zero point 0), biases and accumulators are int64 and the GELU table is
//! an interpolated int16 table; its scratch holds the same counts at twice the bytes for codes
//! and accumulators ([`TransformerShape::int16_scratch`]).
//!
//! Quantization points, each with its own calibrated parameters recorded by
//! [`F32Transformer::forward_observed`] under the named [`TransformerProbe`]:
//! - `traj_in` / `cond_in` inputs: `Trajectory` / `Condition`;
//! - `qkv` input (LN1 output): `Norm1`; `proj` input (concatenated heads): `Attention`;
//! - `fc1` input (LN2 output): `Norm2`; `fc1` output = table input: `Fc1`; table output = `fc2`
//!   input: `Gelu`;
//! - `head` input (final LayerNorm output): `FinalNorm`.
//!
//! # Flash and compute (transformer-lite, int8)
//!
//! Per block `12 W^2 = 196 608` int8 weights (`qkv`, `proj`, `fc1`, `fc2`), so 589 824 for three
//! blocks, plus `T W output` for the head (137 984 for a 77-value ProDMP head), about 0.75 MB of
//! int8 weights (int32 biases, f32 scales, norms and positions add about 50 KB). A forward pass
//! is about `T (12 W^2 L) + T W output + 2 L T^2 W` = 8.5 M multiply-accumulates.
//!
//! # Scratch memory
//!
//! Attention runs one head at a time and one query at a time, so only the keys and values of one
//! head are held (`2 T head_dim` floats); the feed-forward runs one token at a time (`4W` hidden
//! values). Sizes come from the `const fn`s [`TransformerShape::f32_scratch`] and
//! [`TransformerShape::int8_scratch`] and are held by a [`TransformerScratch`] (or any
//! [`TransformerBuffers`] at least that long):
//!
//! | path | f32 values | int8 values | int32 values |
//! |------|------------|-------------|--------------|
//! | f32  | `3TW + 2T hd + hd + T + 5W` | 0 | 0 |
//! | int8 | `TW + 2T hd + 2hd + T + W` | `max(2TW + 4W, cond_dim, k)` | `max(W, output)` |
//!
//! For transformer-lite (`T = 14`, `W = 128`, 2 heads so `hd = 64`, 3 layers, `output <= 128`) the
//! int8 path needs 3854 f32 + 4096 int8 + 128 int32 = **20 024 bytes** of scratch (independent of
//! the layer count) plus the weights in flash; the f32 path needs 7 886 f32 = 31 544 bytes.

mod block;
mod error;
mod float;
mod quantized;
mod shape;
#[cfg(test)]
mod tests;

pub use error::{Part, ScratchBuffer, TransformerError};
pub use float::{fold_noise_token, F32FeedForward, TransformerProbe};
pub use quantized::{Int16FeedForward, Int8FeedForward, QuantFeedForward, TokenLinear};
pub use shape::{ScratchLens, TransformerBuffers, TransformerScratch, TransformerShape};

#[cfg(test)]
pub(crate) use block::attend;

use crate::kernels::{layer_norm, KernelError};
use crate::model::linear::{F32Linear, QuantizedLinear};

/// LayerNorm epsilon of every norm in the backbone (candle `layer_norm_slow(.., 1e-5)`).
pub const LAYER_NORM_EPSILON: f32 = 1e-5;

/// LayerNorm affine parameters (`[W]` each; candle `weight`, `bias`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LayerNormWeights<'a> {
    /// Scale `[W]`.
    pub gamma: &'a [f32],
    /// Shift `[W]`.
    pub beta: &'a [f32],
}

impl LayerNormWeights<'_> {
    fn check(&self, width: usize, part: Part) -> Result<(), TransformerError> {
        if self.gamma.len() != width || self.beta.len() != width {
            return Err(TransformerError::Features { part });
        }
        Ok(())
    }

    /// `output = LayerNorm(input)` with [`LAYER_NORM_EPSILON`] ([`crate::kernels::layer_norm`]).
    pub fn apply(&self, input: &[f32], output: &mut [f32]) -> Result<(), KernelError> {
        layer_norm(input, self.gamma, self.beta, LAYER_NORM_EPSILON, output)
    }
}

/// A linear layer the backbone checks against its shape: a token input layer (`traj_in`,
/// `cond_in`: [`F32Linear`] or [`TokenLinear`]) or a [`BlockLinear`].
pub trait CheckedLinear: Copy {
    /// Checks consistent slices and `in_features -> out_features`.
    fn check(
        &self,
        in_features: usize,
        out_features: usize,
        part: Part,
    ) -> Result<(), TransformerError>;

    /// Checks what keeps every accumulator exact (int64 accumulators: weight and bias bounds,
    /// O(weights), [`crate::kernels::FullyConnected::validate_exact`]); nothing for f32 and int8.
    fn check_exact(&self, _part: Part) -> Result<(), TransformerError> {
        Ok(())
    }
}

/// A linear layer of a block (`qkv`, `proj`) or the head, in one precision ([`F32Linear`] or
/// [`QuantizedLinear`]).
pub trait BlockLinear: CheckedLinear {
    /// Element of the normalized tokens and attention outputs that feed the layer: `f32`, or an
    /// int8 or int16 code.
    type Code: Copy;
    /// Accumulator of the layer (`i32` or `i64`; unused by the f32 form).
    type Acc: Copy;
}

/// A feed-forward `fc2(gelu(fc1(x)))`: [`F32FeedForward`] or [`Int8FeedForward`].
pub trait FeedForward: Copy {
    /// Checks `width -> hidden -> width` of block `layer`.
    fn check(&self, width: usize, hidden: usize, layer: usize) -> Result<(), TransformerError>;

    /// [`CheckedLinear::check_exact`] of both layers of block `layer`.
    fn check_exact(&self, _layer: usize) -> Result<(), TransformerError> {
        Ok(())
    }
}

/// One pre-LayerNorm block (see the module docs) with linear layers `L` and feed-forward `FF`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Block<'a, L, FF> {
    /// LayerNorm before attention (f32).
    pub norm1: LayerNormWeights<'a>,
    /// `W -> 3W`, outputs `[q | k | v]`, each `[heads, head_dim]`; input = LN1 output.
    pub qkv: L,
    /// `W -> W`; input = concatenated head outputs.
    pub proj: L,
    /// LayerNorm before the feed-forward (f32).
    pub norm2: LayerNormWeights<'a>,
    /// `W -> 4W -> W` with GELU.
    pub feed_forward: FF,
}

/// A transformer backbone over borrowed (typically `&'static` baked) weights, with token input
/// layers `I`, linear layers `L` and feed-forwards `FF` ([`F32Transformer`], [`Int8Transformer`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transformer<'a, I, L, FF> {
    /// Sizes.
    pub shape: TransformerShape,
    /// `k -> W`, applied to each trajectory step. Its input is the `c_in`-scaled trajectory; an
    /// exporter may instead fold `c_in(sigma)` into an int8 layer's input scale (`scale / c_in`)
    /// and have the caller pass the unscaled trajectory.
    pub traj_in: I,
    /// `cond_dim -> W`.
    pub cond_in: I,
    /// `[W]` noise token `noise_in(embedding(sigma)) + positions[1]` ([`fold_noise_token`]). A
    /// few-step sampler keeps one token per noise level and copies the model with the right one
    /// ([`Transformer::with_noise_token`]).
    pub noise_token: &'a [f32],
    /// `[T, W]` learned positions; row 1 is not read (it is folded into `noise_token`).
    pub positions: &'a [f32],
    /// `shape.layers` blocks.
    pub blocks: &'a [Block<'a, L, FF>],
    /// Final LayerNorm (f32).
    pub final_norm: LayerNormWeights<'a>,
    /// `T W -> output`; input = final LayerNorm outputs, flattened.
    pub head: L,
}

/// A block with f32 layers.
pub type F32Block<'a> = Block<'a, F32Linear<'a>, F32FeedForward<'a>>;
/// A block with int8-weight layers and `P` activations.
pub type QuantBlock<'a, P = i8> = Block<'a, QuantizedLinear<'a, P>, QuantFeedForward<'a, P>>;
/// A block with int8 layers.
pub type Int8Block<'a> = QuantBlock<'a, i8>;
/// A block with int8 weights and int16 activations.
pub type Int16Block<'a> = QuantBlock<'a, i16>;
/// The f32 reference backbone.
pub type F32Transformer<'a> = Transformer<'a, F32Linear<'a>, F32Linear<'a>, F32FeedForward<'a>>;
/// The hybrid quantized backbone: int8 weights, `P` activations.
pub type QuantTransformer<'a, P = i8> =
    Transformer<'a, TokenLinear<'a, P>, QuantizedLinear<'a, P>, QuantFeedForward<'a, P>>;
/// The hybrid int8 backbone.
pub type Int8Transformer<'a> = QuantTransformer<'a, i8>;
/// The hybrid backbone with int16 activations (the 16x8 scheme).
pub type Int16Transformer<'a> = QuantTransformer<'a, i16>;

impl<L: BlockLinear, FF: FeedForward> Block<'_, L, FF> {
    fn check(&self, shape: &TransformerShape, layer: usize) -> Result<(), TransformerError> {
        let width = shape.width;
        let qkv_width = width.checked_mul(3).ok_or(TransformerError::SizeOverflow)?;
        self.norm1.check(width, Part::Norm1 { layer })?;
        self.qkv.check(width, qkv_width, Part::Qkv { layer })?;
        self.proj.check(width, width, Part::Proj { layer })?;
        self.norm2.check(width, Part::Norm2 { layer })?;
        self.feed_forward.check(width, shape.hidden(), layer)
    }

    fn check_exact(&self, layer: usize) -> Result<(), TransformerError> {
        self.qkv.check_exact(Part::Qkv { layer })?;
        self.proj.check_exact(Part::Proj { layer })?;
        self.feed_forward.check_exact(layer)
    }
}

impl<'a, I: CheckedLinear, L: BlockLinear, FF: FeedForward> Transformer<'a, I, L, FF> {
    /// Checks every part against the shape (including quantization parameters) and, with int64
    /// accumulators, the weight and bias bounds that keep them exact (O(weights): run it once
    /// when the model is built; a forward pass checks only [`Self::validate_shapes`]).
    pub fn validate(&self) -> Result<(), TransformerError> {
        self.validate_shapes()?;
        self.traj_in.check_exact(Part::TrajIn)?;
        self.cond_in.check_exact(Part::CondIn)?;
        for (layer, block) in self.blocks.iter().enumerate() {
            block.check_exact(layer)?;
        }
        self.head.check_exact(Part::Head)
    }

    /// [`Self::validate`] without the O(weights) exactness checks (what every forward pass
    /// runs; a model that fails only those gives unspecified outputs, never a panic).
    pub fn validate_shapes(&self) -> Result<(), TransformerError> {
        let shape = &self.shape;
        shape.validate()?;
        if self.blocks.len() != shape.layers {
            return Err(TransformerError::LayerCount);
        }
        if self.positions.len() != shape.token_values() {
            return Err(TransformerError::Features {
                part: Part::Positions,
            });
        }
        if self.noise_token.len() != shape.width {
            return Err(TransformerError::Features {
                part: Part::NoiseToken,
            });
        }
        self.final_norm.check(shape.width, Part::FinalNorm)?;
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

    /// The same model with another noise token (`W` values).
    pub fn with_noise_token(&self, noise_token: &'a [f32]) -> Self {
        Self {
            noise_token,
            ..*self
        }
    }
}

/// Checks the forward-pass arguments' lengths and that the inputs are finite.
fn check_io(
    shape: &TransformerShape,
    trajectory: &[f32],
    condition: &[f32],
    output: &[f32],
) -> Result<(), TransformerError> {
    if trajectory.len() != shape.trajectory_len() {
        return Err(TransformerError::TrajectoryLength);
    }
    if condition.len() != shape.cond_dim {
        return Err(TransformerError::ConditionLength);
    }
    if output.len() != shape.output {
        return Err(TransformerError::OutputLength);
    }
    if trajectory.iter().chain(condition).any(|v| !v.is_finite()) {
        return Err(TransformerError::NonFiniteInput);
    }
    Ok(())
}
