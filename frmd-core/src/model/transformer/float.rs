//! The f32 form of the transformer ([`F32Transformer`]): the reference forward pass, with calibration
//! probes, and the folding of the noise token.

use super::block::{add_assign, attend, embed_tokens, finish, run_blocks, BlockWork, TokenInput};
use super::block::{FeedForwardSteps, LinearSteps};
use super::shape::{prefix, take};
use super::{
    check_io, BlockLinear, CheckedLinear, F32Transformer, FeedForward, Part, ScratchBuffer,
    TransformerBuffers, TransformerError, TransformerScratch, TransformerShape,
};
use crate::kernels::{Activation, KernelError};
use crate::model::linear::F32Linear;
use crate::model::mlp::{F32Buffers, F32Mlp, Probe};

/// The f32 feed-forward: `fc1` (`W -> 4W`, activation [`Activation::GeluSigmoid`]) and `fc2`
/// (`4W -> W`, `Identity`), run as a one-hidden-layer [`F32Mlp`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct F32FeedForward<'a> {
    /// `W -> 4W` with GELU.
    pub fc1: F32Linear<'a>,
    /// `4W -> W`.
    pub fc2: F32Linear<'a>,
}

impl F32FeedForward<'_> {
    /// The feed-forward as an MLP.
    pub fn mlp(&self) -> F32Mlp<'_> {
        F32Mlp {
            hidden: core::slice::from_ref(&self.fc1),
            output: self.fc2,
        }
    }
}

/// Checks an f32 linear layer: consistent slices, `in_features -> out_features`, `activation`.
fn check_linear(
    layer: &F32Linear<'_>,
    in_features: usize,
    out_features: usize,
    activation: Activation,
    part: Part,
) -> Result<(), TransformerError> {
    layer
        .validate()
        .map_err(|error| TransformerError::Weights { part, error })?;
    if layer.in_features != in_features || layer.out_features != out_features {
        return Err(TransformerError::Features { part });
    }
    if layer.activation != activation {
        return Err(TransformerError::Activation { part });
    }
    Ok(())
}

impl CheckedLinear for F32Linear<'_> {
    fn check(
        &self,
        in_features: usize,
        out_features: usize,
        part: Part,
    ) -> Result<(), TransformerError> {
        check_linear(self, in_features, out_features, Activation::Identity, part)
    }
}

impl BlockLinear for F32Linear<'_> {
    type Code = f32;
    type Acc = i32;
}

impl FeedForward for F32FeedForward<'_> {
    fn check(&self, width: usize, hidden: usize, layer: usize) -> Result<(), TransformerError> {
        check_linear(
            &self.fc1,
            width,
            hidden,
            Activation::GeluSigmoid,
            Part::Fc1 { layer },
        )?;
        check_linear(
            &self.fc2,
            hidden,
            width,
            Activation::Identity,
            Part::Fc2 { layer },
        )
    }
}

impl LinearSteps for F32Linear<'_> {
    fn rows(&self, start: usize, count: usize) -> Result<Self, KernelError> {
        F32Linear::rows(self, start, count)
    }

    fn encode(&self, values: &[f32], codes: &mut [f32]) {
        for (code, value) in codes.iter_mut().zip(values) {
            *code = *value;
        }
    }

    fn apply(
        &self,
        codes: &[f32],
        _accumulators: &mut [i32],
        output: &mut [f32],
    ) -> Result<(), KernelError> {
        self.forward(codes, output)
    }

    fn attend_head(
        &self,
        query: &[f32],
        keys: &[f32],
        values: &[f32],
        scale: f32,
        scores: &mut [f32],
        _head_out: &mut [f32],
        out: &mut [f32],
    ) -> Result<(), KernelError> {
        attend(query, keys, values, scale, scores, out)
    }

    fn observed(codes: &[f32]) -> Option<&[f32]> {
        Some(codes)
    }
}

impl FeedForwardSteps<f32, i32> for F32FeedForward<'_> {
    fn run<O: FnMut(TransformerProbe, &[f32])>(
        &self,
        layer: usize,
        row: &mut [f32],
        codes: &mut [f32],
        hidden: &mut [f32],
        _accumulators: &mut [i32],
        observe: &mut O,
    ) -> Result<(), TransformerError> {
        let buffers = F32Buffers {
            ping: codes,
            pong: hidden,
        };
        let probe = |probe| match probe {
            Probe::Input => Some(TransformerProbe::Norm2 { layer }),
            Probe::PreActivation(_) => Some(TransformerProbe::Fc1 { layer }),
            Probe::Output(_) => Some(TransformerProbe::Gelu { layer }),
            Probe::Final => None,
        };
        self.mlp()
            .forward_in_place(row, buffers, |p, values| {
                if let Some(probe) = probe(p) {
                    observe(probe, values);
                }
            })
            .map_err(|error| feed_forward_error(error, layer))
    }
}

/// A feed-forward MLP's error as the transformer's (the shapes were checked by `validate`, so
/// only kernel failures are expected).
pub(super) fn feed_forward_error(
    error: crate::model::mlp::ModelError,
    layer: usize,
) -> TransformerError {
    use crate::model::mlp::ModelError;
    match error {
        ModelError::Kernel(error) => TransformerError::Kernel(error),
        ModelError::ScratchTooSmall => TransformerError::Kernel(KernelError::OutputLength),
        _ => TransformerError::Features {
            part: Part::Fc1 { layer },
        },
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
    /// `fc1` output of one token before GELU (per token, `4W`): the table input.
    Fc1 {
        /// Block index.
        layer: usize,
    },
    /// GELU output of one token (per token, `4W`): the table output and `fc2` input.
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

/// `token = noise_in(embedding) + positions[1]` in f32: the constant noise token for a fixed noise
/// level (exporter) or the per-call token when the noise level varies. `positions` is the full
/// `[T, W]` table; `token` is `W` long.
pub fn fold_noise_token(
    shape: &TransformerShape,
    noise_in: &F32Linear<'_>,
    embedding: &[f32],
    positions: &[f32],
    token: &mut [f32],
) -> Result<(), TransformerError> {
    shape.validate()?;
    check_linear(
        noise_in,
        noise_in.in_features,
        shape.width,
        Activation::Identity,
        Part::NoiseIn,
    )?;
    if embedding.len() != noise_in.in_features {
        return Err(TransformerError::EmbeddingLength);
    }
    if embedding.iter().any(|v| !v.is_finite()) {
        return Err(TransformerError::NonFiniteInput);
    }
    let missing = TransformerError::Features {
        part: Part::Positions,
    };
    if positions.len() != shape.token_values() {
        return Err(missing);
    }
    let position = positions.chunks_exact(shape.width).nth(1).ok_or(missing)?;
    if token.len() != shape.width {
        return Err(TransformerError::Features {
            part: Part::NoiseToken,
        });
    }
    noise_in.forward(embedding, token)?;
    add_assign(token, position);
    Ok(())
}

impl F32Transformer<'_> {
    /// Runs the backbone: `trajectory` is the `c_in`-scaled noisy trajectory (`[n, k]` row-major),
    /// `condition` the `cond_dim` condition vector; writes `shape.output` values to `output`.
    pub fn forward<const F: usize, const B: usize, const A: usize>(
        &self,
        trajectory: &[f32],
        condition: &[f32],
        output: &mut [f32],
        scratch: &mut TransformerScratch<F, B, A>,
    ) -> Result<(), TransformerError> {
        self.forward_in(trajectory, condition, output, scratch.buffers(), |_, _| {})
    }

    /// [`F32Transformer::forward`] that shows the tensors of [`TransformerProbe`] to `observe`
    /// (e.g. to record the calibration ranges of the quantized form's quantization points).
    pub fn forward_observed<const F: usize, const B: usize, const A: usize, O>(
        &self,
        trajectory: &[f32],
        condition: &[f32],
        output: &mut [f32],
        scratch: &mut TransformerScratch<F, B, A>,
        observe: O,
    ) -> Result<(), TransformerError>
    where
        O: FnMut(TransformerProbe, &[f32]),
    {
        self.forward_in(trajectory, condition, output, scratch.buffers(), observe)
    }

    /// [`F32Transformer::forward_observed`] on borrowed buffers (at least
    /// [`TransformerShape::f32_scratch`] floats).
    pub fn forward_in<O>(
        &self,
        trajectory: &[f32],
        condition: &[f32],
        output: &mut [f32],
        buffers: TransformerBuffers<'_>,
        mut observe: O,
    ) -> Result<(), TransformerError>
    where
        O: FnMut(TransformerProbe, &[f32]),
    {
        self.validate()?;
        let shape = &self.shape;
        check_io(shape, trajectory, condition, output)?;
        let buffer = ScratchBuffer::Floats;
        let floats = prefix(buffers.floats, shape.f32_scratch().floats, buffer)?;
        let (tw, head_dim, tokens) = (shape.token_values(), shape.head_dim(), shape.tokens());
        let mut rest = floats;
        let residual = take(&mut rest, tw, buffer)?;
        let normed = take(&mut rest, tw, buffer)?;
        let attention = take(&mut rest, tw, buffer)?;
        let keys = take(&mut rest, tokens * head_dim, buffer)?;
        let values = take(&mut rest, tokens * head_dim, buffer)?;
        let query = take(&mut rest, head_dim, buffer)?;
        let scores = take(&mut rest, tokens, buffer)?;
        let hidden = take(&mut rest, shape.hidden(), buffer)?;
        let row = take(&mut rest, shape.width, buffer)?;

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
                Ok(layer.forward(values, token)?)
            },
        )?;
        observe(TransformerProbe::Tokens, residual);
        let mut work = BlockWork {
            residual,
            normed,
            attention,
            hidden,
            keys,
            values,
            query,
            head_out: &mut [],
            scores,
            row,
            accumulators: &mut [],
        };
        run_blocks(shape, self.blocks, &mut work, &mut observe)?;
        finish(
            shape,
            &self.final_norm,
            &self.head,
            &mut work,
            output,
            &mut observe,
        )
    }
}
