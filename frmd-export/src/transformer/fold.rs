//! The transformer-lite student folded into frmd-core's transformer structure, in f32.
//!
//! The candle model (frmd-host `models/transformer.rs`, variables under `transformer.`) embeds
//! the tokens `[cond_in(cond), noise_in(embedding(c_noise)), traj_in(c_in x_i) ...]`, adds
//! `pos_embedding`, runs pre-LayerNorm blocks (`norm1`, `qkv`, `proj`, `norm2`, `fc1`, GELU,
//! `fc2`), `final_norm` and a `head` over the flattened tokens. Per sampling step `i` the noise
//! level is fixed, so `noise_in(embedding(c_noise(sigma_i))) + pos_embedding[1]` is one constant
//! `W`-long token ([`frmd_core::model::transformer::fold_noise_token`]); the runtime selects it by
//! the step's `noise_variant` ([`frmd_core::policy::TransformerNetwork`]), the way the MLP selects
//! its per-step first-layer bias. The result ([`FoldedTransformer`]) runs on frmd-core's own f32
//! path ([`F32Transformer`]).

use crate::fold::{FloatLayer, StudentBase};
use crate::host::{boxed_scratch, HostScratchOf, HOST_ACCUMULATORS, HOST_CODES, HOST_FLOATS};
use anyhow::{bail, Context};
use frmd_core::kernels::{Activation, Precision};
use frmd_core::model::linear::F32Linear;
use frmd_core::model::transformer::{
    fold_noise_token, F32Block, F32FeedForward, F32Transformer, LayerNormWeights, TransformerError,
    TransformerProbe, TransformerShape,
};
use frmd_core::policy::{PolicyConfig, RangeNormalizer, Sampler, StepTable};
use frmd_formats::checkpoint::{BackboneConfig, Checkpoint, Normalization};

/// LayerNorm affine parameters (`[W]` each).
#[derive(Clone, Debug, PartialEq)]
pub struct FloatNorm {
    /// Scale.
    pub gamma: Vec<f32>,
    /// Shift.
    pub beta: Vec<f32>,
}

impl FloatNorm {
    /// frmd-core's view of the parameters.
    pub fn view(&self) -> LayerNormWeights<'_> {
        LayerNormWeights {
            gamma: &self.gamma,
            beta: &self.beta,
        }
    }
}

/// One pre-LayerNorm block in f32.
#[derive(Clone, Debug, PartialEq)]
pub struct FloatBlock {
    /// LayerNorm before attention.
    pub norm1: FloatNorm,
    /// Query, key and value projection (`3 W` outputs).
    pub qkv: FloatLayer,
    /// Attention output projection.
    pub proj: FloatLayer,
    /// LayerNorm before the feed-forward.
    pub norm2: FloatNorm,
    /// Feed-forward expansion (`4 W`, GELU).
    pub fc1: FloatLayer,
    /// Feed-forward contraction.
    pub fc2: FloatLayer,
}

/// A transformer student folded for `steps.len()` sampling steps.
#[derive(Clone, Debug)]
pub struct FoldedTransformer {
    /// What every student carries.
    pub base: StudentBase,
    /// Sizes of frmd-core's transformer.
    pub shape: TransformerShape,
    /// Embedding of each trajectory step.
    pub traj_in: FloatLayer,
    /// Embedding of the condition.
    pub cond_in: FloatLayer,
    /// Per step: `noise_in(embedding(c_noise(sigma_i))) + pos_embedding[1]`, `W` values.
    pub noise_tokens: Vec<Vec<f32>>,
    /// `[T, W]` learned positions (row 1 unused at run time).
    pub positions: Vec<f32>,
    /// The blocks.
    pub blocks: Vec<FloatBlock>,
    /// LayerNorm after the last block.
    pub final_norm: FloatNorm,
    /// Output layer over the flattened tokens.
    pub head: FloatLayer,
}

pub(crate) fn f32_view(layer: &FloatLayer) -> F32Linear<'_> {
    layer.view(&layer.bias)
}

/// Reads linear layer `transformer.{name}` (`[out, in]` weight, `[out]` bias).
fn linear(
    ckpt: &Checkpoint,
    name: &str,
    in_features: usize,
    out_features: usize,
) -> anyhow::Result<FloatLayer> {
    let weights = ckpt.tensor(&format!("transformer.{name}.weight"))?.to_vec();
    let bias = ckpt.tensor(&format!("transformer.{name}.bias"))?.to_vec();
    if weights.len() != in_features * out_features || bias.len() != out_features {
        bail!("transformer.{name}: {} weights and {} biases, expected [{out_features} x {in_features}]", weights.len(), bias.len());
    }
    Ok(FloatLayer {
        in_features,
        out_features,
        weights,
        bias,
        activation: Activation::Identity,
    })
}

fn norm(ckpt: &Checkpoint, name: &str, width: usize) -> anyhow::Result<FloatNorm> {
    let gamma = ckpt.tensor(&format!("transformer.{name}.weight"))?.to_vec();
    let beta = ckpt.tensor(&format!("transformer.{name}.bias"))?.to_vec();
    if gamma.len() != width || beta.len() != width {
        bail!(
            "transformer.{name}: LayerNorm of {} / {} values, expected {width}",
            gamma.len(),
            beta.len()
        );
    }
    Ok(FloatNorm { gamma, beta })
}

impl FoldedTransformer {
    /// Folds a transformer student checkpoint for `steps` sampling steps, refusing what the
    /// runtime cannot represent (naming the reason).
    pub fn new(ckpt: &Checkpoint, steps: usize) -> anyhow::Result<Self> {
        let base = StudentBase::new(&ckpt.meta, steps)?;
        let config = &base.config;
        let BackboneConfig::Transformer {
            layers,
            heads,
            width,
        } = config.backbone
        else {
            bail!("an MLP backbone folds with mlp::FoldedMlp");
        };
        let shape = TransformerShape {
            horizon: config.horizon,
            action_dim: config.action_dim,
            cond_dim: config.cond_dim(),
            width,
            heads,
            layers,
            output: config.output_dim(),
        };
        shape
            .validate()
            .with_context(|| format!("transformer shape {shape:?}"))?;
        let lens = shape.f32_scratch();
        // The same element counts for int8 and int16 codes.
        let quantized = shape.int8_scratch();
        if lens.floats.max(quantized.floats) > HOST_FLOATS
            || lens.codes.max(quantized.codes) > HOST_CODES
            || lens.accumulators.max(quantized.accumulators) > HOST_ACCUMULATORS
        {
            bail!("transformer shape {shape:?} needs more scratch than the exporter's host scratch holds");
        }
        let (w, tokens) = (width, shape.tokens());
        let positions = ckpt.tensor("transformer.pos_embedding")?.to_vec();
        if positions.len() != tokens * w {
            bail!(
                "transformer.pos_embedding has {} values, expected [{tokens} x {w}]",
                positions.len()
            );
        }
        let noise_in = linear(ckpt, "noise_in", config.embed_dim, w)?;
        let noise_tokens = base
            .embeddings
            .iter()
            .enumerate()
            .map(|(i, embedding)| {
                let mut token = vec![0.0f32; w];
                fold_noise_token(
                    &shape,
                    &f32_view(&noise_in),
                    embedding,
                    &positions,
                    &mut token,
                )
                .with_context(|| format!("folding the noise token of step {i}"))?;
                Ok(token)
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        let blocks = (0..layers)
            .map(|i| {
                let p = format!("blocks.{i}");
                Ok(FloatBlock {
                    norm1: norm(ckpt, &format!("{p}.norm1"), w)?,
                    qkv: linear(ckpt, &format!("{p}.qkv"), w, 3 * w)?,
                    proj: linear(ckpt, &format!("{p}.proj"), w, w)?,
                    norm2: norm(ckpt, &format!("{p}.norm2"), w)?,
                    fc1: FloatLayer {
                        activation: Activation::GeluSigmoid,
                        ..linear(ckpt, &format!("{p}.fc1"), w, 4 * w)?
                    },
                    fc2: linear(ckpt, &format!("{p}.fc2"), 4 * w, w)?,
                })
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        let folded = FoldedTransformer {
            shape,
            traj_in: linear(ckpt, "traj_in", config.action_dim, w)?,
            cond_in: linear(ckpt, "cond_in", config.cond_dim(), w)?,
            noise_tokens,
            positions,
            blocks,
            final_norm: norm(ckpt, "final_norm", w)?,
            head: linear(ckpt, "head", shape.token_values(), shape.output)?,
            base,
        };
        folded
            .view(&folded.f32_blocks(), 0)?
            .validate()
            .context("folded transformer")?;
        Ok(folded)
    }

    /// frmd-core block views (pass to [`Self::view`]).
    pub fn f32_blocks(&self) -> Vec<F32Block<'_>> {
        self.blocks
            .iter()
            .map(|b| F32Block {
                norm1: b.norm1.view(),
                qkv: f32_view(&b.qkv),
                proj: f32_view(&b.proj),
                norm2: b.norm2.view(),
                feed_forward: F32FeedForward {
                    fc1: f32_view(&b.fc1),
                    fc2: f32_view(&b.fc2),
                },
            })
            .collect()
    }

    /// frmd-core's f32 transformer with step `step`'s noise token.
    pub fn view<'a>(
        &'a self,
        blocks: &'a [F32Block<'a>],
        step: usize,
    ) -> anyhow::Result<F32Transformer<'a>> {
        let noise_token = self
            .noise_tokens
            .get(step)
            .with_context(|| format!("step index {step} out of range"))?;
        Ok(F32Transformer {
            shape: self.shape,
            traj_in: f32_view(&self.traj_in),
            cond_in: f32_view(&self.cond_in),
            noise_token,
            positions: &self.positions,
            blocks,
            final_norm: self.final_norm.view(),
            head: f32_view(&self.head),
        })
    }

    /// The policy configuration with normalization `norm` as frmd-core's view.
    pub fn config<'a>(&'a self, norm: &'a Normalization) -> PolicyConfig<'a> {
        let base = &self.base;
        PolicyConfig {
            history: base.config.history,
            obs_norm: RangeNormalizer::new(&norm.obs.min, &norm.obs.max),
            action_norm: RangeNormalizer::new(&norm.action.min, &norm.action.max),
            sampler: Sampler {
                steps: StepTable::new(&base.steps),
                decoder: base.prodmp.view(),
                layout: base.layout,
                control_dt: base.config.control_dt as f32,
            },
        }
    }

    /// All noise tokens back to back (the layout [`frmd_core::policy::TransformerNetwork`]
    /// takes).
    pub fn flat_noise_tokens(&self) -> Vec<f32> {
        self.noise_tokens.concat()
    }

    /// Runs step `step` on the standard-layout model `input` through frmd-core's f32 path,
    /// reporting every probe to `observe`; returns the `K * P` ProDMP parameters.
    pub fn forward_observed(
        &self,
        step: usize,
        input: &[f32],
        observe: impl FnMut(TransformerProbe, &[f32]),
    ) -> anyhow::Result<Vec<f32>> {
        let blocks = self.f32_blocks();
        let model = self.view(&blocks, step)?;
        run_on_input(
            &model.shape,
            input,
            "f32 transformer forward",
            |t, c, out, scratch| model.forward_observed(t, c, out, scratch, observe),
        )
    }

    /// The f32 consistency sampler ([`StudentBase::sample`]), calling
    /// `observe(step, probe, values)` for every probe of every step.
    pub fn sample(
        &self,
        cond: &[f32],
        noise: &[f32],
        mut observe: impl FnMut(usize, TransformerProbe, &[f32]),
    ) -> anyhow::Result<Vec<f32>> {
        self.base.sample(cond, noise, |i, input| {
            self.forward_observed(i, input, |p, v| observe(i, p, v))
        })
    }
}

/// Runs one pass of a transformer of `shape` on the standard-layout model `input` (the
/// condition, then the trajectory) with a host scratch: `forward(trajectory, condition, output,
/// scratch)` fills the returned `shape.output` values; `what` names the pass in its error.
pub(super) fn run_on_input<P: Precision>(
    shape: &TransformerShape,
    input: &[f32],
    what: &str,
    forward: impl FnOnce(
        &[f32],
        &[f32],
        &mut [f32],
        &mut HostScratchOf<P>,
    ) -> Result<(), TransformerError>,
) -> anyhow::Result<Vec<f32>> {
    let (condition, trajectory) = input.split_at_checked(shape.cond_dim).with_context(|| {
        format!(
            "model input of {} values is shorter than the condition",
            input.len()
        )
    })?;
    let mut scratch = boxed_scratch::<P>();
    let mut out = vec![0.0; shape.output];
    forward(trajectory, condition, &mut out, &mut scratch).with_context(|| what.to_string())?;
    Ok(out)
}
