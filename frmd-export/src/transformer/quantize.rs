//! Calibration (frmd-core's [`TransformerProbe`]s over the f32 sampler) and quantization of a
//! [`FoldedTransformer`] into an owned [`QuantizedTransformer`].
//!
//! Recipe (docs/design.md section 5, transformer-lite): every linear layer gets per-channel symmetric
//! int8 weights and an int32 bias at `input_scale * weight_scale` with the input zero point folded
//! ([`crate::calibrate::quantize_weights`], [`crate::calibrate::int_bias`]); its input is
//! quantized per tensor with the range of the probe that feeds it (`Trajectory` -> `traj_in`,
//! `Condition` -> `cond_in`, `Norm1` -> `qkv`, `Attention` -> `proj`, `Norm2` -> `fc1`, `Gelu` ->
//! `fc2`, `FinalNorm` -> `head`). `fc1` is requantized (Q31 multiplier + shift) to the `Fc1`
//! range, GELU is a 256-entry table from the `Fc1` to the `Gelu` parameters; the residual stream,
//! LayerNorms, attention and noise tokens stay f32.

use super::fold::{run_on_input, FloatNorm, FoldedTransformer};
use crate::calibrate::{check_rows, int_bias, quantize_weights, RangeMethod, Recorder};
use crate::fold::FloatLayer;
use anyhow::Context;
use frmd_core::blob::{
    encode_transformer, transformer_encoded_len, BlobError, TransformerBlobParts,
};
use frmd_core::kernels::{gelu_sigmoid, FcRequant, FullyConnected, Lut8};
use frmd_core::model::linear::{Int8Linear, QuantizedLinear as LinearView, RequantizedLinear};
use frmd_core::model::transformer::{
    Int8Block, Int8FeedForward, Int8Transformer, TokenLinear, TransformerProbe,
};
use frmd_core::policy::PolicyDims;
use frmd_core::quant::{requantization_multiplier, QuantParams};
use frmd_formats::calibration::CalibrationSet;
use frmd_formats::checkpoint::Normalization;
use std::collections::BTreeMap;

/// Activation parameters per probe, from calibration.
#[derive(Clone, Debug, PartialEq)]
pub struct TransformerRanges {
    /// Parameters of every probe that feeds a quantized tensor.
    pub params: Vec<(TransformerProbe, QuantParams)>,
    /// Calibration rows run (each through every sampling step).
    pub rows: usize,
}

impl TransformerRanges {
    /// The parameters of `probe`.
    pub fn get(&self, probe: TransformerProbe) -> anyhow::Result<QuantParams> {
        self.params
            .iter()
            .find(|(p, _)| *p == probe)
            .map(|(_, q)| *q)
            .with_context(|| format!("calibration has no range for {probe:?}"))
    }
}

/// A stable order for probes (the map key).
fn probe_key(probe: TransformerProbe) -> (usize, usize) {
    use TransformerProbe as P;
    match probe {
        P::Trajectory => (0, 0),
        P::Condition => (1, 0),
        P::Tokens => (2, 0),
        P::Norm1 { layer } => (3, layer),
        P::Attention { layer } => (4, layer),
        P::Norm2 { layer } => (5, layer),
        P::Fc1 { layer } => (6, layer),
        P::Gelu { layer } => (7, layer),
        P::Block { layer } => (8, layer),
        P::FinalNorm => (9, 0),
        P::Output => (10, 0),
    }
}

/// Runs the f32 sampler over `set` and derives the parameters of every probe.
pub fn calibrate(
    model: &FoldedTransformer,
    set: &CalibrationSet,
    method: RangeMethod,
) -> anyhow::Result<TransformerRanges> {
    let c = &model.base.config;
    check_rows(set, c.cond_dim())?;
    let mut recorders: BTreeMap<(usize, usize), (TransformerProbe, Recorder)> = BTreeMap::new();
    for row in 0..set.rows() {
        let noise = set.noise(row, model.base.steps.len(), c.traj_dim());
        model.sample(set.row(row), &noise, |_, probe, values| {
            let entry = recorders
                .entry(probe_key(probe))
                .or_insert_with(|| (probe, Recorder::default()));
            entry.1.values.extend_from_slice(values);
        })?;
    }
    let params = recorders
        .into_values()
        .map(|(probe, mut recorder)| Ok((probe, recorder.params(method, &format!("{probe:?}"))?)))
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok(TransformerRanges {
        params,
        rows: set.rows(),
    })
}

/// An owned int8 linear layer with f32 input and output (frmd-core's `QuantizedLinear`).
#[derive(Clone, Debug, PartialEq)]
pub struct QuantizedLinear {
    /// Quantization of the f32 input.
    pub input: QuantParams,
    /// Input width.
    pub in_features: usize,
    /// Output width.
    pub out_features: usize,
    /// `[out, in]` int8.
    pub weights: Vec<i8>,
    /// Per output channel.
    pub weight_scales: Vec<f32>,
    /// int32 at `input.scale * weight_scale`, input zero point folded.
    pub bias: Vec<i32>,
    /// `input.scale * weight_scale` per channel.
    pub output_scales: Vec<f32>,
}

impl QuantizedLinear {
    /// Quantizes `layer` for inputs with parameters `input`.
    pub fn new(layer: &FloatLayer, input: QuantParams) -> anyhow::Result<Self> {
        let q = quantize_weights(layer)?;
        let bias = int_bias(&layer.bias, &q, input, layer.in_features)?;
        let output_scales = q
            .scales
            .iter()
            .map(|w| (f64::from(input.scale) * f64::from(*w)) as f32)
            .collect();
        Ok(Self {
            input,
            in_features: layer.in_features,
            out_features: layer.out_features,
            weights: q.weights,
            weight_scales: q.scales,
            bias,
            output_scales,
        })
    }

    /// frmd-core's int8 fully connected layer over these weights.
    pub fn fc(&self) -> FullyConnected<'_> {
        FullyConnected::new(
            self.in_features,
            self.out_features,
            &self.weights,
            &self.bias,
        )
    }

    /// frmd-core's view of the layer (f32 in, f32 out).
    pub fn view(&self) -> LinearView<'_> {
        LinearView {
            input: self.input,
            linear: Int8Linear {
                fc: self.fc(),
                output_scales: &self.output_scales,
            },
        }
    }
}

/// One quantized block.
#[derive(Clone, Debug, PartialEq)]
pub struct QuantizedBlock {
    /// LayerNorm before attention (f32).
    pub norm1: FloatNorm,
    /// Query, key and value projection.
    pub qkv: QuantizedLinear,
    /// Attention output projection.
    pub proj: QuantizedLinear,
    /// LayerNorm before the feed-forward (f32).
    pub norm2: FloatNorm,
    /// Feed-forward expansion, requantized to int8 for the GELU table.
    pub fc1: QuantizedLinear,
    /// Parameters of the `fc1` output (GELU table input).
    pub fc1_output: QuantParams,
    /// Per-channel Q31 requantization of `fc1` to `fc1_output`.
    pub fc1_multipliers: Vec<i32>,
    /// Per-channel shifts of that requantization.
    pub fc1_shifts: Vec<i32>,
    /// GELU from the `fc1` output parameters to the `fc2` input parameters.
    pub gelu: Lut8,
    /// Feed-forward contraction.
    pub fc2: QuantizedLinear,
}

/// The owned int8 transformer plus everything the policy needs around it.
#[derive(Clone, Debug)]
pub struct QuantizedTransformer {
    /// The f32 model it was quantized from (norms, tokens, positions stay f32).
    pub folded: FoldedTransformer,
    /// Trajectory token embedding.
    pub traj_in: QuantizedLinear,
    /// Condition token embedding.
    pub cond_in: QuantizedLinear,
    /// The blocks.
    pub blocks: Vec<QuantizedBlock>,
    /// Output layer.
    pub head: QuantizedLinear,
}

/// Quantizes `model` with the calibrated `ranges`.
pub fn quantize(
    model: &FoldedTransformer,
    ranges: &TransformerRanges,
) -> anyhow::Result<QuantizedTransformer> {
    use TransformerProbe as P;
    let blocks = model
        .blocks
        .iter()
        .enumerate()
        .map(|(layer, b)| {
            let context = || format!("block {layer}");
            let fc1 = QuantizedLinear::new(&b.fc1, ranges.get(P::Norm2 { layer })?)
                .with_context(context)?;
            let fc1_output = ranges.get(P::Fc1 { layer })?;
            let gelu_output = ranges.get(P::Gelu { layer })?;
            let (mut fc1_multipliers, mut fc1_shifts) = (Vec::new(), Vec::new());
            for (o, w) in fc1.weight_scales.iter().enumerate() {
                let (m, s) = requantization_multiplier(fc1.input.scale, *w, fc1_output.scale)
                    .with_context(|| {
                        format!("block {layer} fc1 channel {o}: requantization multiplier")
                    })?;
                fc1_multipliers.push(m);
                fc1_shifts.push(s);
            }
            Ok(QuantizedBlock {
                norm1: b.norm1.clone(),
                qkv: QuantizedLinear::new(&b.qkv, ranges.get(P::Norm1 { layer })?)
                    .with_context(context)?,
                proj: QuantizedLinear::new(&b.proj, ranges.get(P::Attention { layer })?)
                    .with_context(context)?,
                norm2: b.norm2.clone(),
                fc1,
                fc1_output,
                fc1_multipliers,
                fc1_shifts,
                gelu: Lut8::build(gelu_sigmoid, fc1_output, gelu_output)
                    .with_context(|| format!("block {layer} GELU table"))?,
                fc2: QuantizedLinear::new(&b.fc2, gelu_output).with_context(context)?,
            })
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let quantized = QuantizedTransformer {
        folded: model.clone(),
        traj_in: QuantizedLinear::new(&model.traj_in, ranges.get(P::Trajectory)?)
            .context("traj_in")?,
        cond_in: QuantizedLinear::new(&model.cond_in, ranges.get(P::Condition)?)
            .context("cond_in")?,
        blocks,
        head: QuantizedLinear::new(&model.head, ranges.get(P::FinalNorm)?).context("head")?,
    };
    quantized
        .view(&quantized.int8_blocks(), 0)?
        .validate()
        .context("quantized transformer")?;
    Ok(quantized)
}

impl QuantizedTransformer {
    /// frmd-core block views (pass to [`Self::view`]).
    pub fn int8_blocks(&self) -> Vec<Int8Block<'_>> {
        self.blocks
            .iter()
            .map(|b| Int8Block {
                norm1: b.norm1.view(),
                qkv: b.qkv.view(),
                proj: b.proj.view(),
                norm2: b.norm2.view(),
                feed_forward: Int8FeedForward {
                    input: b.fc1.input,
                    fc1: RequantizedLinear {
                        fc: b.fc1.fc(),
                        requant: FcRequant {
                            multipliers: &b.fc1_multipliers,
                            shifts: &b.fc1_shifts,
                            output_zero_point: b.fc1_output.zero_point,
                            activation_min: i8::MIN,
                            activation_max: i8::MAX,
                        },
                        activation: Some(&b.gelu.table),
                    },
                    fc2: b.fc2.view(),
                },
            })
            .collect()
    }

    /// frmd-core's int8 transformer with step `step`'s noise token.
    pub fn view<'a>(
        &'a self,
        blocks: &'a [Int8Block<'a>],
        step: usize,
    ) -> anyhow::Result<Int8Transformer<'a>> {
        let f = &self.folded;
        let noise_token = f
            .noise_tokens
            .get(step)
            .with_context(|| format!("step index {step} out of range"))?;
        Ok(Int8Transformer {
            shape: f.shape,
            traj_in: TokenLinear::Int8(self.traj_in.view()),
            cond_in: TokenLinear::Int8(self.cond_in.view()),
            noise_token,
            positions: &f.positions,
            blocks,
            final_norm: f.final_norm.view(),
            head: self.head.view(),
        })
    }

    /// Runs step `step` on the standard-layout model `input` through frmd-core's int8 path.
    pub fn forward(&self, step: usize, input: &[f32]) -> anyhow::Result<Vec<f32>> {
        let blocks = self.int8_blocks();
        let model = self.view(&blocks, step)?;
        run_on_input(
            &model.shape,
            input,
            "int8 transformer forward",
            |t, c, out, scratch| model.forward(t, c, out, scratch),
        )
    }

    /// The int8 consistency sampler (same steps and decode as [`FoldedTransformer::sample`]).
    pub fn sample(&self, cond: &[f32], noise: &[f32]) -> anyhow::Result<Vec<f32>> {
        self.folded
            .base
            .sample(cond, noise, |i, input| self.forward(i, input))
    }

    /// The policy's sizes.
    pub fn dims(&self) -> PolicyDims {
        let c = &self.folded.base.config;
        PolicyDims {
            history: c.history,
            obs_dim: c.obs_dim,
            action_dim: c.action_dim,
            horizon: c.horizon,
            params_per_dof: c.output_dim() / c.action_dim.max(1),
        }
    }

    /// The `FRMT` blob with normalization `norm` (format in [`frmd_core::blob::transformer`]); a
    /// named error if a size does not fit the format (more than
    /// [`frmd_core::blob::transformer::MAX_BLOCKS`] blocks, sizes beyond u32). The loader checks
    /// every shape.
    pub fn blob(&self, norm: &Normalization) -> Result<Vec<u8>, BlobError> {
        let blocks = self.int8_blocks();
        let noise_tokens = self.folded.flat_noise_tokens();
        let parts = TransformerBlobParts {
            config: self.folded.config(norm),
            model: self.view(&blocks, 0).map_err(|_| BlobError::Encode)?,
            noise_tokens: &noise_tokens,
        };
        let mut out = vec![0_u8; transformer_encoded_len(&parts)?];
        let written = encode_transformer(&parts, &mut out)?;
        out.truncate(written);
        Ok(out)
    }
}
