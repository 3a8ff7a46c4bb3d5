//! Calibration (frmd-core's [`TransformerProbe`]s over the f32 sampler) and quantization of a
//! [`FoldedTransformer`] into an owned [`QuantizedTransformer`].
//!
//! Recipe (docs/design.md section 5, transformer-lite): every linear layer gets per-channel symmetric
//! int8 weights and a bias at `input_scale * weight_scale` with the input zero point folded
//! ([`crate::calibrate::quantize_weights`], [`ExportPrecision::bias`]); its input is quantized
//! per tensor with the range of the probe that feeds it (`Trajectory` -> `traj_in`, `Condition`
//! -> `cond_in`, `Norm1` -> `qkv`, `Attention` -> `proj`, `Norm2` -> `fc1`, `Gelu` -> `fc2`,
//! `FinalNorm` -> `head`). `fc1` is requantized (multiplier + shift) to the `Fc1` range, GELU is a
//! table from the `Fc1` to the `Gelu` parameters; the residual stream, LayerNorms, attention and
//! noise tokens stay f32. With int8 activations (`P = i8`) the parameters are the calibrated
//! asymmetric ones, the biases int32 and the table has 256 entries; with int16 activations
//! (`P = i16`, the 16x8 scheme) every quantization point is symmetric int16 over its calibrated
//! range widened by the activation headroom ([`ExportPrecision::activation`]), the biases int64
//! and the table interpolated, exactly as the MLP's int16 export does.

use super::fold::{run_on_input, FloatNorm, FoldedTransformer};
use crate::calibrate::{check_rows, quantize_weights, requantization, RangeMethod, Recorder};
use crate::fold::FloatLayer;
use crate::mlp::ExportPrecision;
use anyhow::Context;
use frmd_core::blob::{
    encode_transformer, transformer_encoded_len, BlobError, TransformerBlobParts,
};
use frmd_core::kernels::{gelu_sigmoid, FcRequant, FullyConnected};
use frmd_core::model::linear::{Int8Linear, QuantizedLinear as LinearView, RequantizedLinear};
use frmd_core::model::transformer::{
    QuantBlock, QuantFeedForward, QuantTransformer, TokenLinear, TransformerProbe,
};
use frmd_core::policy::PolicyDims;
use frmd_core::quant::QuantParams;
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

/// An owned int8-weight linear layer with f32 input and output and `P` activation codes
/// (frmd-core's `QuantizedLinear`).
#[derive(Clone, Debug, PartialEq)]
pub struct QuantizedLinear<P: ExportPrecision = i8> {
    /// Quantization of the f32 input (symmetric for int16).
    pub input: QuantParams,
    /// Input width.
    pub in_features: usize,
    /// Output width.
    pub out_features: usize,
    /// `[out, in]` int8.
    pub weights: Vec<i8>,
    /// Per output channel.
    pub weight_scales: Vec<f32>,
    /// At `input.scale * weight_scale`, input zero point folded (int32, or int64 for int16).
    pub bias: Vec<P::Acc>,
    /// `input.scale * weight_scale` per channel.
    pub output_scales: Vec<f32>,
}

impl<P: ExportPrecision> QuantizedLinear<P> {
    /// Quantizes `layer` for inputs with parameters `input`.
    pub fn new(layer: &FloatLayer, input: QuantParams) -> anyhow::Result<Self> {
        let q = quantize_weights(layer)?;
        let bias = P::bias(&layer.bias, &q, input, layer.in_features)?;
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

    /// frmd-core's fully connected layer over these weights.
    pub fn fc(&self) -> FullyConnected<'_, P::Acc> {
        FullyConnected::new(
            self.in_features,
            self.out_features,
            &self.weights,
            &self.bias,
        )
    }

    /// frmd-core's view of the layer (f32 in, f32 out).
    pub fn view(&self) -> LinearView<'_, P> {
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
pub struct QuantizedBlock<P: ExportPrecision = i8> {
    /// LayerNorm before attention (f32).
    pub norm1: FloatNorm,
    /// Query, key and value projection.
    pub qkv: QuantizedLinear<P>,
    /// Attention output projection.
    pub proj: QuantizedLinear<P>,
    /// LayerNorm before the feed-forward (f32).
    pub norm2: FloatNorm,
    /// Feed-forward expansion, requantized to `P` codes for the GELU table.
    pub fc1: QuantizedLinear<P>,
    /// Parameters of the `fc1` output (GELU table input).
    pub fc1_output: QuantParams,
    /// Per-channel requantization multipliers of `fc1` to `fc1_output`.
    pub fc1_multipliers: Vec<i32>,
    /// Per-channel shifts of that requantization.
    pub fc1_shifts: Vec<i32>,
    /// GELU from the `fc1` output parameters to the `fc2` input parameters.
    pub gelu: P::Table,
    /// Feed-forward contraction.
    pub fc2: QuantizedLinear<P>,
}

/// The owned quantized transformer (int8 weights, `P` activations) plus everything the policy
/// needs around it.
#[derive(Clone, Debug)]
pub struct QuantizedTransformer<P: ExportPrecision = i8> {
    /// The f32 model it was quantized from (norms, tokens, positions stay f32).
    pub folded: FoldedTransformer,
    /// Trajectory token embedding.
    pub traj_in: QuantizedLinear<P>,
    /// Condition token embedding.
    pub cond_in: QuantizedLinear<P>,
    /// The blocks.
    pub blocks: Vec<QuantizedBlock<P>>,
    /// Output layer.
    pub head: QuantizedLinear<P>,
}

/// Quantizes `model` with the calibrated `ranges`, with `P` activations; `headroom` (>= 1)
/// widens every activation range where `P` affords it (int16).
pub fn quantize<P: ExportPrecision>(
    model: &FoldedTransformer,
    ranges: &TransformerRanges,
    headroom: f32,
) -> anyhow::Result<QuantizedTransformer<P>> {
    use TransformerProbe as T;
    let params = |probe: TransformerProbe| -> anyhow::Result<QuantParams> {
        P::activation(ranges.get(probe)?, headroom)
            .with_context(|| format!("activation parameters of {probe:?}"))
    };
    let blocks = model
        .blocks
        .iter()
        .enumerate()
        .map(|(layer, b)| {
            let context = || format!("block {layer}");
            let fc1 = QuantizedLinear::<P>::new(&b.fc1, params(T::Norm2 { layer })?)
                .with_context(context)?;
            let fc1_output = params(T::Fc1 { layer })?;
            let gelu_output = params(T::Gelu { layer })?;
            let (fc1_multipliers, fc1_shifts) = requantization::<P>(
                fc1.input.scale,
                &fc1.weight_scales,
                fc1_output.scale,
                &format!("block {layer} fc1"),
            )?;
            Ok(QuantizedBlock {
                norm1: b.norm1.clone(),
                qkv: QuantizedLinear::new(&b.qkv, params(T::Norm1 { layer })?)
                    .with_context(context)?,
                proj: QuantizedLinear::new(&b.proj, params(T::Attention { layer })?)
                    .with_context(context)?,
                norm2: b.norm2.clone(),
                fc1,
                fc1_output,
                fc1_multipliers,
                fc1_shifts,
                gelu: P::activation_table(gelu_sigmoid, fc1_output, gelu_output)
                    .with_context(|| format!("block {layer} GELU table"))?,
                fc2: QuantizedLinear::new(&b.fc2, gelu_output).with_context(context)?,
            })
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let quantized = QuantizedTransformer {
        folded: model.clone(),
        traj_in: QuantizedLinear::new(&model.traj_in, params(T::Trajectory)?).context("traj_in")?,
        cond_in: QuantizedLinear::new(&model.cond_in, params(T::Condition)?).context("cond_in")?,
        blocks,
        head: QuantizedLinear::new(&model.head, params(T::FinalNorm)?).context("head")?,
    };
    quantized
        .view(&quantized.quant_blocks(), 0)?
        .validate()
        .context("quantized transformer")?;
    Ok(quantized)
}

impl<P: ExportPrecision> QuantizedTransformer<P> {
    /// frmd-core block views (pass to [`Self::view`]).
    pub fn quant_blocks(&self) -> Vec<QuantBlock<'_, P>> {
        self.blocks
            .iter()
            .map(|b| QuantBlock {
                norm1: b.norm1.view(),
                qkv: b.qkv.view(),
                proj: b.proj.view(),
                norm2: b.norm2.view(),
                feed_forward: QuantFeedForward {
                    input: b.fc1.input,
                    fc1: RequantizedLinear {
                        fc: b.fc1.fc(),
                        requant: FcRequant {
                            multipliers: &b.fc1_multipliers,
                            shifts: &b.fc1_shifts,
                            output_zero_point: b.fc1_output.zero_point,
                            activation_min: P::MIN,
                            activation_max: P::MAX,
                        },
                        activation: Some(&b.gelu),
                    },
                    fc2: b.fc2.view(),
                },
            })
            .collect()
    }

    /// frmd-core's quantized transformer with step `step`'s noise token.
    pub fn view<'a>(
        &'a self,
        blocks: &'a [QuantBlock<'a, P>],
        step: usize,
    ) -> anyhow::Result<QuantTransformer<'a, P>> {
        let f = &self.folded;
        let noise_token = f
            .noise_tokens
            .get(step)
            .with_context(|| format!("step index {step} out of range"))?;
        Ok(QuantTransformer {
            shape: f.shape,
            traj_in: TokenLinear::Quantized(self.traj_in.view()),
            cond_in: TokenLinear::Quantized(self.cond_in.view()),
            noise_token,
            positions: &f.positions,
            blocks,
            final_norm: f.final_norm.view(),
            head: self.head.view(),
        })
    }

    /// Runs step `step` on the standard-layout model `input` through frmd-core's quantized path.
    pub fn forward(&self, step: usize, input: &[f32]) -> anyhow::Result<Vec<f32>> {
        let blocks = self.quant_blocks();
        let model = self.view(&blocks, step)?;
        run_on_input(
            &model.shape,
            input,
            &format!("int{} transformer forward", P::BITS),
            |t, c, out, scratch| model.forward(t, c, out, scratch),
        )
    }

    /// The quantized consistency sampler (same steps and decode as
    /// [`FoldedTransformer::sample`]).
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
        let blocks = self.quant_blocks();
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
