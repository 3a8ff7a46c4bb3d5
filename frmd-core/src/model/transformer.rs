//! Transformer backbone (transformer-lite): an f32 reference forward pass ([`F32Transformer`]) and
//! a hybrid int8 forward pass ([`Int8Transformer`]) through one structure, over borrowed weights.
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
//!    concatenated in order before `proj`; `fc1` is `W -> 4W`, GELU is
//!    [`crate::kernels::gelu_sigmoid`] (`x sigmoid(1.702 x)`);
//! 3. a final LayerNorm on every token, then `head` over the flattened `[T * W]` tokens (token
//!    major), giving `output` values (ProDMP parameters or a raw trajectory).
//!
//! LayerNorms use epsilon [`LAYER_NORM_EPSILON`] (candle `layer_norm_slow(.., 1e-5)`). Linear
//! weights are row-major `[out_features, in_features]` (candle `Linear` layout).
//!
//! # int8 hybrid scheme ([`Int8Transformer`])
//!
//! The residual stream stays f32. Every linear layer (`traj_in` and `cond_in` optionally, `qkv`,
//! `proj`, `fc1`, `fc2`, `head`) is an int8 x int8 -> int32 [`crate::kernels::FullyConnected`]
//! with per-output-channel symmetric int8 weights and int32 bias (input zero point folded).
//! Its f32 input is quantized per tensor (asymmetric, calibrated [`crate::quant::QuantParams`])
//! and its accumulators are dequantized per channel with `input_scale * weight_scale[o]`
//! ([`Int8Linear`]), except `fc1`, whose accumulators are requantized to int8, mapped through a
//! 256-entry GELU [`crate::kernels::Lut8`] and fed to `fc2` as int8 ([`Int8FeedForward`]).
//! LayerNorm and the attention (scores, softmax, weighted sum of values) run in f32.
//!
//! Quantization points, each with its own calibrated parameters recorded by
//! [`F32Transformer::forward_observed`] under the named [`TransformerProbe`]:
//! - `traj_in` / `cond_in` inputs: `Trajectory` / `Condition`;
//! - `qkv` input (LN1 output): `Norm1`; `proj` input (concatenated heads): `Attention`;
//! - `fc1` input (LN2 output): `Norm2`; `fc1` output = LUT input: `Fc1`; LUT output = `fc2`
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
//! [`TransformerShape::int8_scratch`] and are held by a [`TransformerScratch`]:
//!
//! | path | f32 values | int8 values | int32 values |
//! |------|------------|-------------|--------------|
//! | f32  | `3TW + 2T hd + hd + T + 5W` | 0 | 0 |
//! | int8 | `TW + 2T hd + 2hd + T + W` | `max(2TW + 4W, cond_dim, k)` | `max(W, output)` |
//!
//! For transformer-lite (`T = 14`, `W = 128`, 2 heads so `hd = 64`, 3 layers, `output <= 128`) the
//! int8 path needs 3854 f32 + 4096 int8 + 128 int32 = **20 024 bytes** of scratch (independent of
//! the layer count) plus the weights in flash; the f32 path needs 7 886 f32 = 31 544 bytes.

mod error;
mod float;
mod int8;
#[cfg(test)]
mod tests;

pub use error::{Part, ScratchBuffer, TransformerError};
pub use float::{fold_noise_token, F32Block, F32Transformer, TransformerProbe};
pub use int8::{Int8Block, Int8FeedForward, Int8Linear, Int8Transformer, TokenLinear};

use super::mlp::F32Layer;
use crate::kernels::{layer_norm, softmax_in_place, Activation, KernelError};

/// LayerNorm epsilon of every norm in the backbone (candle `layer_norm_slow(.., 1e-5)`).
pub const LAYER_NORM_EPSILON: f32 = 1e-5;

/// Sizes of a transformer backbone.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TransformerShape {
    /// `n`: number of trajectory-step tokens.
    pub horizon: usize,
    /// `k`: values per trajectory step (`traj_in` input width).
    pub action_dim: usize,
    /// Length of the condition vector `[obs history, y0, v0 * control_dt]` (`cond_in` input).
    pub cond_dim: usize,
    /// Token width `W`.
    pub width: usize,
    /// Attention heads; must divide `width`.
    pub heads: usize,
    /// Number of blocks `L`.
    pub layers: usize,
    /// Width of the head's output.
    pub output: usize,
}

/// Scratch lengths (in elements) one forward pass needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ScratchLens {
    /// f32 values.
    pub floats: usize,
    /// int8 values.
    pub bytes: usize,
    /// int32 values.
    pub accumulators: usize,
}

impl ScratchLens {
    /// Total RAM in bytes (`4 floats + bytes + 4 accumulators`, saturating).
    pub const fn ram_bytes(&self) -> usize {
        self.floats
            .saturating_mul(4)
            .saturating_add(self.bytes)
            .saturating_add(self.accumulators.saturating_mul(4))
    }
}

const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

impl TransformerShape {
    /// `T = horizon + 2` tokens.
    pub const fn tokens(&self) -> usize {
        self.horizon.saturating_add(2)
    }

    /// `W / heads` (0 if `heads == 0`).
    pub const fn head_dim(&self) -> usize {
        match self.width.checked_div(self.heads) {
            Some(d) => d,
            None => 0,
        }
    }

    /// Feed-forward hidden width `4 W`.
    pub const fn hidden(&self) -> usize {
        self.width.saturating_mul(4)
    }

    /// `n k`: length of the trajectory input.
    pub const fn trajectory_len(&self) -> usize {
        self.horizon.saturating_mul(self.action_dim)
    }

    /// `T W`: length of the token matrix (and of the head's input).
    pub const fn token_values(&self) -> usize {
        self.tokens().saturating_mul(self.width)
    }

    /// Scratch needed by [`F32Transformer`]: `3TW + 2T hd + hd + T + 5W` floats (residual, LN1
    /// outputs, attention outputs, one head's keys and values, one query, one score row, the
    /// feed-forward hidden row and one token row). Saturates on overflow (then
    /// [`TransformerShape::validate`] fails).
    pub const fn f32_scratch(&self) -> ScratchLens {
        let tw = self.token_values();
        let hd = self.head_dim();
        let floats = tw
            .saturating_mul(3)
            .saturating_add(self.tokens().saturating_mul(hd).saturating_mul(2))
            .saturating_add(hd)
            .saturating_add(self.tokens())
            .saturating_add(self.width.saturating_mul(5));
        ScratchLens {
            floats,
            bytes: 0,
            accumulators: 0,
        }
    }

    /// Scratch needed by [`Int8Transformer`]: floats `TW + 2T hd + 2hd + T + W` (residual, one
    /// head's keys and values, one query, one head output, one score row, one token row); bytes
    /// `max(2TW + 4W, cond_dim, k)` (quantized LN1 outputs, quantized attention outputs, the
    /// feed-forward hidden row); accumulators `max(W, output)`. Saturates on overflow.
    pub const fn int8_scratch(&self) -> ScratchLens {
        let tw = self.token_values();
        let hd = self.head_dim();
        let floats = tw
            .saturating_add(self.tokens().saturating_mul(hd).saturating_mul(2))
            .saturating_add(hd.saturating_mul(2))
            .saturating_add(self.tokens())
            .saturating_add(self.width);
        let bytes = tw.saturating_mul(2).saturating_add(self.hidden());
        ScratchLens {
            floats,
            bytes: max(bytes, max(self.cond_dim, self.action_dim)),
            accumulators: max(self.width, self.output),
        }
    }

    /// Checks that every size is positive, `heads` divides `width` and no derived size overflows.
    pub fn validate(&self) -> Result<(), TransformerError> {
        let sizes = [
            self.horizon,
            self.action_dim,
            self.cond_dim,
            self.width,
            self.heads,
            self.layers,
            self.output,
        ];
        if sizes.contains(&0) {
            return Err(TransformerError::ZeroSize);
        }
        if !self.width.is_multiple_of(self.heads) {
            return Err(TransformerError::HeadsDoNotDivideWidth);
        }
        // Largest products the forward passes form: the head's weights (T W output), fc1's
        // weights (4 W W), the scratch (below 32 T W elements), the input layers' weights.
        let token_values = self
            .horizon
            .checked_add(2)
            .and_then(|t| t.checked_mul(self.width));
        let products = [
            token_values.and_then(|tw| tw.checked_mul(self.output)),
            token_values.and_then(|tw| tw.checked_mul(32)),
            self.width
                .checked_mul(self.width)
                .and_then(|ww| ww.checked_mul(4)),
            self.horizon.checked_mul(self.action_dim),
            self.cond_dim.checked_mul(self.width),
            self.action_dim.checked_mul(self.width),
        ];
        if products.iter().any(Option::is_none) {
            return Err(TransformerError::SizeOverflow);
        }
        Ok(())
    }
}

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

/// Scratch buffers for both forward passes, sized by `const` lengths from
/// [`TransformerShape::f32_scratch`] / [`TransformerShape::int8_scratch`] (longer is fine):
///
/// ```
/// use frmd_core::model::transformer::{ScratchLens, TransformerScratch, TransformerShape};
/// const SHAPE: TransformerShape = TransformerShape {
///     horizon: 12, action_dim: 7, cond_dim: 54, width: 128, heads: 2, layers: 3, output: 77,
/// };
/// const LENS: ScratchLens = SHAPE.int8_scratch();
/// type Scratch = TransformerScratch<{ LENS.floats }, { LENS.bytes }, { LENS.accumulators }>;
/// let scratch = Scratch::new();
/// assert_eq!(LENS.ram_bytes(), 20_024);
/// # let _ = scratch;
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct TransformerScratch<const FLOATS: usize, const BYTES: usize, const ACCUMULATORS: usize> {
    pub(crate) floats: [f32; FLOATS],
    pub(crate) bytes: [i8; BYTES],
    pub(crate) accumulators: [i32; ACCUMULATORS],
}

impl<const FLOATS: usize, const BYTES: usize, const ACCUMULATORS: usize>
    TransformerScratch<FLOATS, BYTES, ACCUMULATORS>
{
    /// Zeroed scratch.
    pub const fn new() -> Self {
        Self {
            floats: [0.0; FLOATS],
            bytes: [0; BYTES],
            accumulators: [0; ACCUMULATORS],
        }
    }
}

impl<const FLOATS: usize, const BYTES: usize, const ACCUMULATORS: usize> Default
    for TransformerScratch<FLOATS, BYTES, ACCUMULATORS>
{
    fn default() -> Self {
        Self::new()
    }
}

/// Splits the first `len` elements off `rest`.
fn take<'s, T>(
    rest: &mut &'s mut [T],
    len: usize,
    buffer: ScratchBuffer,
) -> Result<&'s mut [T], TransformerError> {
    let all = core::mem::take(rest);
    let needed = len;
    let (head, tail) = all
        .split_at_mut_checked(len)
        .ok_or(TransformerError::ScratchTooSmall { buffer, needed })?;
    *rest = tail;
    Ok(head)
}

/// Checks an f32 linear layer: consistent slices, `in_features -> out_features`, `Identity`.
fn check_f32_linear(
    layer: &F32Layer<'_>,
    in_features: usize,
    out_features: usize,
    part: Part,
) -> Result<(), TransformerError> {
    layer
        .validate()
        .map_err(|error| TransformerError::Weights { part, error })?;
    if layer.in_features != in_features || layer.out_features != out_features {
        return Err(TransformerError::Features { part });
    }
    if layer.activation != Activation::Identity {
        return Err(TransformerError::Activation { part });
    }
    Ok(())
}

/// Output rows `start .. start + count` of an f32 linear layer, as a layer of its own.
fn f32_rows<'a>(
    layer: &F32Layer<'a>,
    start: usize,
    count: usize,
) -> Result<F32Layer<'a>, KernelError> {
    let end = start.checked_add(count).ok_or(KernelError::WeightsLength)?;
    let weights = start
        .checked_mul(layer.in_features)
        .zip(end.checked_mul(layer.in_features))
        .and_then(|(from, to)| layer.weights.get(from..to))
        .ok_or(KernelError::WeightsLength)?;
    let bias = layer.bias.get(start..end).ok_or(KernelError::BiasLength)?;
    Ok(F32Layer {
        in_features: layer.in_features,
        out_features: count,
        weights,
        bias,
        activation: layer.activation,
    })
}

/// Checks the parts both paths share: shape, block count, positions, noise token, final norm.
fn check_common(
    shape: &TransformerShape,
    blocks: usize,
    positions: &[f32],
    noise_token: &[f32],
    final_norm: &LayerNormWeights<'_>,
) -> Result<(), TransformerError> {
    shape.validate()?;
    if blocks != shape.layers {
        return Err(TransformerError::LayerCount);
    }
    if positions.len() != shape.token_values() {
        return Err(TransformerError::Features {
            part: Part::Positions,
        });
    }
    if noise_token.len() != shape.width {
        return Err(TransformerError::Features {
            part: Part::NoiseToken,
        });
    }
    final_norm.check(shape.width, Part::FinalNorm)
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

/// Which input a token projection receives in [`embed_tokens`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum TokenInput {
    /// The condition vector (`cond_in`).
    Condition,
    /// One trajectory step (`traj_in`).
    Step,
}

/// Fills `residual` (`[T, W]`) with the embedded tokens `[cond, noise, steps]` plus positions;
/// `project` maps a condition or step vector to a `W` row.
fn embed_tokens<F>(
    shape: &TransformerShape,
    positions: &[f32],
    noise_token: &[f32],
    trajectory: &[f32],
    condition: &[f32],
    residual: &mut [f32],
    mut project: F,
) -> Result<(), TransformerError>
where
    F: FnMut(TokenInput, &[f32], &mut [f32]) -> Result<(), TransformerError>,
{
    let width = shape.width;
    let mut rows = residual.chunks_exact_mut(width);
    let mut position_rows = positions.chunks_exact(width);
    let missing = TransformerError::Features {
        part: Part::Positions,
    };
    let (cond_row, cond_position) = rows.next().zip(position_rows.next()).ok_or(missing)?;
    project(TokenInput::Condition, condition, cond_row)?;
    add_assign(cond_row, cond_position);
    let (noise_row, _folded) = rows.next().zip(position_rows.next()).ok_or(missing)?;
    for (value, folded) in noise_row.iter_mut().zip(noise_token) {
        *value = *folded;
    }
    let steps = trajectory.chunks_exact(shape.action_dim);
    let mut count = 0_usize;
    for ((row, position), step) in rows.zip(position_rows).zip(steps) {
        project(TokenInput::Step, step, row)?;
        add_assign(row, position);
        count += 1;
    }
    if count != shape.horizon {
        return Err(TransformerError::TrajectoryLength);
    }
    Ok(())
}

/// `target[i] += addend[i]`.
fn add_assign(target: &mut [f32], addend: &[f32]) {
    for (t, a) in target.iter_mut().zip(addend) {
        *t += *a;
    }
}

/// `1 / sqrt(head_dim)` computed in f64 and rounded to f32 (candle divides the scores by the f64
/// `sqrt(head_dim)` through `affine(1 / sqrt, 0)`).
fn attention_scale(head_dim: usize) -> f32 {
    (1.0 / libm::sqrt(head_dim as f64)) as f32
}

/// One query of one head: `output = sum_s softmax_s(scale * query . keys[s]) values[s]`, with
/// `keys`, `values` row-major `[T, head_dim]` and `scores` `[T]` (sequential f32 sums).
fn attend(
    query: &[f32],
    keys: &[f32],
    values: &[f32],
    scale: f32,
    scores: &mut [f32],
    output: &mut [f32],
) -> Result<(), KernelError> {
    let head_dim = query.len();
    if head_dim == 0 || scores.is_empty() {
        return Err(KernelError::Empty);
    }
    let expected = scores.len().checked_mul(head_dim);
    if expected != Some(keys.len()) || expected != Some(values.len()) {
        return Err(KernelError::InputLength);
    }
    if output.len() != head_dim {
        return Err(KernelError::OutputLength);
    }
    for (score, key) in scores.iter_mut().zip(keys.chunks_exact(head_dim)) {
        let dot = query
            .iter()
            .zip(key)
            .fold(0.0_f32, |acc, (q, k)| acc + q * k);
        *score = dot * scale;
    }
    softmax_in_place(scores)?;
    output.fill(0.0);
    for (weight, value) in scores.iter().zip(values.chunks_exact(head_dim)) {
        for (out, v) in output.iter_mut().zip(value) {
            *out += weight * v;
        }
    }
    Ok(())
}
