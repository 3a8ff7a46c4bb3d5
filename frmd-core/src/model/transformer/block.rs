//! The skeleton both precisions run: token embedding, the pre-LayerNorm blocks (attention one
//! head and one query at a time, then the feed-forward one token at a time) and the final norm
//! and head. The steps that depend on the precision (how a linear layer reads its input, where a
//! head's output goes, the feed-forward) are [`LinearSteps`] and [`FeedForwardSteps`].

use super::{Block, BlockLinear, FeedForward, LayerNormWeights, Part, TransformerError};
use super::{TransformerProbe, TransformerShape};
use crate::kernels::{softmax_in_place, KernelError};

/// The precision-dependent steps of a linear layer.
pub(super) trait LinearSteps: BlockLinear {
    /// Output channels `start .. start + count` as a layer of their own.
    fn rows(&self, start: usize, count: usize) -> Result<Self, KernelError>;

    /// `values` (f32) as this layer's input codes (a copy in f32, quantized with the layer's
    /// input parameters in the quantized form).
    fn encode(&self, values: &[f32], codes: &mut [Self::Code]);

    /// `output = layer(codes)`; the quantized form uses the first `output.len()` accumulators.
    fn apply(
        &self,
        codes: &[Self::Code],
        accumulators: &mut [Self::Acc],
        output: &mut [f32],
    ) -> Result<(), KernelError>;

    /// One head's attention output for one query ([`attend`]) as this (`proj`) layer's input
    /// codes in `out` (`head_dim` long); the quantized form attends into `head_out` first.
    #[allow(clippy::too_many_arguments)]
    fn attend_head(
        &self,
        query: &[f32],
        keys: &[f32],
        values: &[f32],
        scale: f32,
        scores: &mut [f32],
        head_out: &mut [f32],
        out: &mut [Self::Code],
    ) -> Result<(), KernelError>;

    /// `codes` as f32 values when they are (the f32 form, for the probes), else `None`.
    fn observed(codes: &[Self::Code]) -> Option<&[f32]>;
}

/// The precision-dependent feed-forward of one token, with codes `C` and accumulators `A`.
pub(super) trait FeedForwardSteps<C, A>: FeedForward {
    /// Replaces `row` (`W`, the LN2 output of one token) by `fc2(gelu(fc1(row)))`, with `codes`
    /// (`>= W`), `hidden` (`>= 4W`) and `accumulators` as scratch; the f32 form shows the
    /// `Norm2`, `Fc1` and `Gelu` probes of block `layer` to `observe`.
    fn run<O: FnMut(TransformerProbe, &[f32])>(
        &self,
        layer: usize,
        row: &mut [f32],
        codes: &mut [C],
        hidden: &mut [C],
        accumulators: &mut [A],
        observe: &mut O,
    ) -> Result<(), TransformerError>;
}

/// Working memory of [`run_blocks`] and [`finish`].
pub(super) struct BlockWork<'s, C, A> {
    /// `[T, W]` residual stream.
    pub(super) residual: &'s mut [f32],
    /// `[T, W]` normalized tokens as codes.
    pub(super) normed: &'s mut [C],
    /// `[T, W]` concatenated head outputs as codes.
    pub(super) attention: &'s mut [C],
    /// `[4W]` feed-forward hidden row.
    pub(super) hidden: &'s mut [C],
    /// `[T, hd]` one head's keys and values.
    pub(super) keys: &'s mut [f32],
    pub(super) values: &'s mut [f32],
    /// `[hd]` one query.
    pub(super) query: &'s mut [f32],
    /// `[hd]` one head output (quantized form; empty in f32).
    pub(super) head_out: &'s mut [f32],
    /// `[T]` one score row.
    pub(super) scores: &'s mut [f32],
    /// `[W]` one token row.
    pub(super) row: &'s mut [f32],
    /// Accumulators (quantized form; empty in f32).
    pub(super) accumulators: &'s mut [A],
}

/// Runs `blocks` on `work.residual`.
pub(super) fn run_blocks<L, FF, O>(
    shape: &TransformerShape,
    blocks: &[Block<'_, L, FF>],
    work: &mut BlockWork<'_, L::Code, L::Acc>,
    observe: &mut O,
) -> Result<(), TransformerError>
where
    L: LinearSteps,
    FF: FeedForwardSteps<L::Code, L::Acc>,
    O: FnMut(TransformerProbe, &[f32]),
{
    let (width, head_dim) = (shape.width, shape.head_dim());
    let scale = attention_scale(head_dim);
    let w = work;
    for (layer, block) in blocks.iter().enumerate() {
        for (x, n) in w
            .residual
            .chunks_exact(width)
            .zip(w.normed.chunks_exact_mut(width))
        {
            block.norm1.apply(x, w.row)?;
            block.qkv.encode(w.row, n);
        }
        if let Some(values) = L::observed(w.normed) {
            observe(TransformerProbe::Norm1 { layer }, values);
        }
        for head in 0..shape.heads {
            let start = head * head_dim;
            let query_layer = block.qkv.rows(start, head_dim)?;
            let key_layer = block.qkv.rows(width + start, head_dim)?;
            let value_layer = block.qkv.rows(2 * width + start, head_dim)?;
            let rows = w
                .normed
                .chunks_exact(width)
                .zip(w.keys.chunks_exact_mut(head_dim))
                .zip(w.values.chunks_exact_mut(head_dim));
            for ((n, key), value) in rows {
                key_layer.apply(n, w.accumulators, key)?;
                value_layer.apply(n, w.accumulators, value)?;
            }
            for (n, out) in w
                .normed
                .chunks_exact(width)
                .zip(w.attention.chunks_exact_mut(width))
            {
                query_layer.apply(n, w.accumulators, w.query)?;
                let out = out
                    .get_mut(start..start + head_dim)
                    .ok_or(TransformerError::Kernel(KernelError::OutputLength))?;
                block
                    .proj
                    .attend_head(w.query, w.keys, w.values, scale, w.scores, w.head_out, out)?;
            }
        }
        if let Some(values) = L::observed(w.attention) {
            observe(TransformerProbe::Attention { layer }, values);
        }
        for (x, a) in w
            .residual
            .chunks_exact_mut(width)
            .zip(w.attention.chunks_exact(width))
        {
            block.proj.apply(a, w.accumulators, w.row)?;
            add_assign(x, w.row);
        }
        for x in w.residual.chunks_exact_mut(width) {
            block.norm2.apply(x, w.row)?;
            block
                .feed_forward
                .run(layer, w.row, w.normed, w.hidden, w.accumulators, observe)?;
            add_assign(x, w.row);
        }
        observe(TransformerProbe::Block { layer }, w.residual);
    }
    Ok(())
}

/// The final LayerNorm on every token and `head` over the flattened tokens into `output`.
pub(super) fn finish<L: LinearSteps, O: FnMut(TransformerProbe, &[f32])>(
    shape: &TransformerShape,
    final_norm: &LayerNormWeights<'_>,
    head: &L,
    work: &mut BlockWork<'_, L::Code, L::Acc>,
    output: &mut [f32],
    observe: &mut O,
) -> Result<(), TransformerError> {
    let width = shape.width;
    for (x, n) in work
        .residual
        .chunks_exact(width)
        .zip(work.normed.chunks_exact_mut(width))
    {
        final_norm.apply(x, work.row)?;
        head.encode(work.row, n);
    }
    if let Some(values) = L::observed(work.normed) {
        observe(TransformerProbe::FinalNorm, values);
    }
    head.apply(work.normed, work.accumulators, output)?;
    observe(TransformerProbe::Output, output);
    Ok(())
}

/// Which input a token projection receives in [`embed_tokens`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum TokenInput {
    /// The condition vector (`cond_in`).
    Condition,
    /// One trajectory step (`traj_in`).
    Step,
}

/// Fills `residual` (`[T, W]`) with the embedded tokens `[cond, noise, steps]` plus positions;
/// `project` maps a condition or step vector to a `W` row.
pub(super) fn embed_tokens<F>(
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
pub(super) fn add_assign(target: &mut [f32], addend: &[f32]) {
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
pub(crate) fn attend(
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
