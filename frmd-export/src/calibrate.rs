//! Calibration and quantization helpers both backbones use: how ranges are chosen from the
//! recorded values ([`RangeMethod`], `Recorder`), range widening, and per-channel symmetric int8
//! weights with an int32 (or int64) bias at `input_scale * weight_scale`, the input zero point
//! folded, and the per-channel requantization of a layer (docs/design.md section 5, with
//! frmd-core's `quant` helpers).
use anyhow::{bail, Context};
use frmd_core::kernels::Precision;
use frmd_core::quant::{
    fold_input_zero_point, fold_input_zero_point_i64, quantize_bias, quantize_bias_i64,
    quantize_weights_per_channel, requantization_multiplier, QuantParams,
};
use frmd_formats::calibration::CalibrationSet;

use crate::fold::FloatLayer;

/// How activation ranges are chosen from the calibration values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RangeMethod {
    /// Smallest and largest value seen.
    MinMax,
    /// The `p`-th and `(100 - p)`-th percentiles (p in (50, 100]).
    Percentile(f64),
}

impl std::str::FromStr for RangeMethod {
    type Err = anyhow::Error;
    fn from_str(text: &str) -> anyhow::Result<Self> {
        if text == "minmax" {
            return Ok(RangeMethod::MinMax);
        }
        let p: f64 = text
            .strip_prefix("percentile:")
            .and_then(|p| p.parse().ok())
            .with_context(|| {
                format!(
                    "calibration `{text}`: expected minmax or percentile:P (e.g. percentile:99.9)"
                )
            })?;
        if !(p > 50.0 && p <= 100.0) {
            bail!("calibration percentile {p} must lie in (50, 100]");
        }
        Ok(RangeMethod::Percentile(p))
    }
}

/// `minmax` or `percentile:P`, what [`RangeMethod::from_str`](std::str::FromStr) reads.
impl std::fmt::Display for RangeMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RangeMethod::MinMax => f.write_str("minmax"),
            RangeMethod::Percentile(p) => write!(f, "percentile:{p}"),
        }
    }
}

/// Recorded values of one quantization point.
#[derive(Default)]
pub(crate) struct Recorder {
    pub(crate) values: Vec<f32>,
}

impl Recorder {
    pub(crate) fn params(
        &mut self,
        method: RangeMethod,
        what: &str,
    ) -> anyhow::Result<QuantParams> {
        if self.values.is_empty() {
            bail!("calibration recorded no values for {what}");
        }
        let (lo, hi) = match method {
            RangeMethod::MinMax => self
                .values
                .iter()
                .fold((f32::MAX, f32::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v))),
            RangeMethod::Percentile(p) => {
                self.values.sort_by(f32::total_cmp);
                let last = self.values.len() - 1;
                let at = |q: f64| self.values[((q / 100.0) * last as f64).round() as usize];
                (at(100.0 - p), at(p))
            }
        };
        QuantParams::from_range(lo, hi).with_context(|| format!("{what}: range [{lo}, {hi}]"))
    }
}

/// `params` with its represented range (`dequantize(-128) ..= dequantize(127)`) scaled by
/// `factor` (finite, >= 1).
pub fn widen(params: QuantParams, factor: f32) -> anyhow::Result<QuantParams> {
    if !(factor.is_finite() && factor >= 1.0) {
        bail!("range widening factor {factor} must be finite and at least 1");
    }
    let (lo, hi) = (
        params.dequantize(i8::MIN) * factor,
        params.dequantize(i8::MAX) * factor,
    );
    QuantParams::from_range(lo, hi).with_context(|| format!("range [{lo}, {hi}]"))
}

/// Refuses calibration rows that do not fit a model condition of `cond_dim` values, or none.
pub(crate) fn check_rows(set: &CalibrationSet, cond_dim: usize) -> anyhow::Result<()> {
    if set.cond_dim != cond_dim {
        bail!(
            "calibration rows have {} values, the model's condition has {cond_dim}",
            set.cond_dim
        );
    }
    if set.rows() == 0 {
        bail!("the calibration set is empty");
    }
    Ok(())
}

/// Per-channel symmetric int8 weights of a layer and their scales.
#[derive(Clone, Debug, PartialEq)]
pub struct QuantizedWeights {
    /// `[out, in]` row-major codes in `[-127, 127]`.
    pub weights: Vec<i8>,
    /// `[out]` scales.
    pub scales: Vec<f32>,
}

/// `layer`'s weights quantized per output channel.
pub(crate) fn quantize_weights(layer: &FloatLayer) -> anyhow::Result<QuantizedWeights> {
    let mut weights = vec![0i8; layer.weights.len()];
    let mut scales = vec![0f32; layer.out_features];
    quantize_weights_per_channel(&layer.weights, layer.in_features, &mut weights, &mut scales)
        .with_context(|| format!("weights [{} x {}]", layer.out_features, layer.in_features))?;
    Ok(QuantizedWeights { weights, scales })
}

/// `bias` as int64 at `input.scale * weight_scale` (int16 activations), with the input zero
/// point folded in, each at most `frmd_core::quant::BIAS16_MAX` in magnitude.
pub(crate) fn int_bias_i64(
    bias: &[f32],
    q: &QuantizedWeights,
    input: QuantParams,
    in_features: usize,
) -> anyhow::Result<Vec<i64>> {
    bias.iter()
        .enumerate()
        .map(|(o, &b)| {
            let b = quantize_bias_i64(b, input.scale, q.scales[o])
                .with_context(|| format!("bias {o}"))?;
            fold_input_zero_point_i64(
                b,
                &q.weights[o * in_features..(o + 1) * in_features],
                input.zero_point,
            )
            .with_context(|| format!("bias {o} with zero point"))
        })
        .collect()
}

/// Per-channel requantization of a layer from accumulators at `input_scale * weight_scales[o]`
/// to codes at `output_scale`: the multipliers and shifts of
/// [`requantization_multiplier`], each shift checked against the range of `P`'s kernels. `what`
/// names the layer in errors.
pub(crate) fn requantization<P: Precision>(
    input_scale: f32,
    weight_scales: &[f32],
    output_scale: f32,
    what: &str,
) -> anyhow::Result<(Vec<i32>, Vec<i32>)> {
    let (mut multipliers, mut shifts) = (Vec::new(), Vec::new());
    for (o, scale) in weight_scales.iter().enumerate() {
        let (m, s) = requantization_multiplier(input_scale, *scale, output_scale)
            .with_context(|| format!("{what} channel {o}: requantization multiplier"))?;
        if !(P::SHIFT_MIN..=P::SHIFT_MAX).contains(&s) {
            bail!(
                "{what} channel {o}: requantization shift {s} outside {}..={} (input scale \
                 {input_scale:e}, weight scale {scale:e}, output scale {output_scale:e})",
                P::SHIFT_MIN,
                P::SHIFT_MAX,
            );
        }
        multipliers.push(m);
        shifts.push(s);
    }
    Ok((multipliers, shifts))
}

/// `bias` as int32 at `input.scale * weight_scale`, with the input zero point folded in.
pub(crate) fn int_bias(
    bias: &[f32],
    q: &QuantizedWeights,
    input: QuantParams,
    in_features: usize,
) -> anyhow::Result<Vec<i32>> {
    bias.iter()
        .enumerate()
        .map(|(o, &b)| {
            let b =
                quantize_bias(b, input.scale, q.scales[o]).with_context(|| format!("bias {o}"))?;
            fold_input_zero_point(
                b,
                &q.weights[o * in_features..(o + 1) * in_features],
                input.zero_point,
            )
            .with_context(|| format!("bias {o} with zero point"))
        })
        .collect()
}
