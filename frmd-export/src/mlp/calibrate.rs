//! Calibration and quantization of a [`FoldedMlp`] into a [`QuantizedMlp`].
//!
//! Calibration runs frmd-core's f32 path (through [`FoldedMlp::sample`], i.e. the same
//! multi-step sampler with re-noising) over calibration conditions with seeded noise, and
//! records per tensor the input, every pre-activation and every hidden output. Ranges are the
//! min/max or a symmetric percentile of the recorded values. Quantization then follows
//! docs/design.md section 5 with frmd-core's `quant` helpers (per-channel symmetric weights, int32 bias
//! with the input zero point folded, Q31 requantization to the pre-activation range, a 256-entry
//! LUT to the output range, a dequantized output layer). With a 16-bit input
//! (`frmd_core::model::mlp::InputPrecision::Int16`, the default of
//! [`crate::ExportOptions`]) the first layer's bias and multipliers are made for the
//! fine input scale `input_scale / 2^8` (zero point `frmd_core::quant::wide_zero_point`); with a
//! two-plane input (`TwoPlane`) only its multipliers are; for both the exporter widens the input
//! range (see [`crate::ExportOptions::input_headroom`]). With int16 activations
//! ([`ExportPrecision`] `i16`) every hidden activation gets symmetric int16 parameters over its
//! calibrated range widened by [`crate::ExportOptions::activation_headroom`], the biases are
//! int64 and the tables interpolated; the input is the 16-bit plane.
use super::fold::{FoldedMlp, InputGains};
use super::precision::ExportPrecision;
use super::quantized::{QuantizedLayer, QuantizedMlp, QuantizedOutput};
use crate::calibrate::{check_rows, requantization, RangeMethod, Recorder};
use crate::rounding::{round_weights, InputMoments, WeightRounding};
use anyhow::{bail, Context};
use frmd_core::model::mlp::{InputPrecision, Probe};
use frmd_core::quant::{wide_scale, wide_zero_point, QuantParams, FINE_INPUT_BITS};
use frmd_formats::calibration::CalibrationSet;
use frmd_formats::checkpoint::Normalization;

/// Activation parameters found by calibration.
#[derive(Clone, Debug, PartialEq)]
pub struct Ranges {
    /// The model input.
    pub input: QuantParams,
    /// Per hidden layer: (pre-activation, output).
    pub hidden: Vec<(QuantParams, QuantParams)>,
    /// Calibration rows run (each through every sampling step).
    pub rows: usize,
}

/// Runs the f32 sampler (every sampling step) over every row of `set` with the row's seeded
/// noise, handing each probed tensor to `observe`: the one pass calibration, GPTQ's input moments
/// and the input gains all read.
fn observe_calibration(
    model: &FoldedMlp,
    set: &CalibrationSet,
    mut observe: impl FnMut(Probe, &[f32]),
) -> anyhow::Result<()> {
    let c = &model.base.config;
    check_rows(set, c.cond_dim())?;
    for row in 0..set.rows() {
        let noise = set.noise(row, model.base.steps.len(), c.traj_dim());
        model.sample(set.row(row), &noise, |_, probe, values| {
            observe(probe, values)
        })?;
    }
    Ok(())
}

/// Runs the f32 sampler over `set` and derives the activation parameters.
pub fn calibrate(
    model: &FoldedMlp,
    set: &CalibrationSet,
    method: RangeMethod,
) -> anyhow::Result<Ranges> {
    let layers = model.hidden.len();
    let mut input = Recorder::default();
    let mut pre: Vec<Recorder> = (0..layers).map(|_| Recorder::default()).collect();
    let mut out: Vec<Recorder> = (0..layers).map(|_| Recorder::default()).collect();
    observe_calibration(model, set, |probe, values| match probe {
        Probe::Input => input.values.extend_from_slice(values),
        Probe::PreActivation(l) => pre[l].values.extend_from_slice(values),
        Probe::Output(l) => out[l].values.extend_from_slice(values),
        Probe::Final => {}
    })?;
    let input = input.params(method, "the model input")?;
    let hidden = pre
        .iter_mut()
        .zip(out.iter_mut())
        .enumerate()
        .map(|(l, (p, o))| {
            Ok((
                p.params(method, &format!("layer {l} pre-activation"))?,
                o.params(method, &format!("layer {l} output"))?,
            ))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok(Ranges {
        input,
        hidden,
        rows: set.rows(),
    })
}

/// The second moments of every layer's inputs (the hidden layers', then the output layer's)
/// over the f32 sampler's calls on `set`, for [`WeightRounding::Gptq`].
pub fn input_moments(model: &FoldedMlp, set: &CalibrationSet) -> anyhow::Result<Vec<InputMoments>> {
    let mut moments: Vec<InputMoments> = model
        .hidden
        .iter()
        .chain([&model.output])
        .map(|layer| InputMoments::new(layer.in_features))
        .collect();
    let mut failed = None;
    observe_calibration(model, set, |probe, values| {
        let layer = match probe {
            Probe::Input => 0,
            Probe::Output(l) => l + 1,
            _ => return,
        };
        if let Err(error) = moments[layer].add(values) {
            failed.get_or_insert(error.context(format!("inputs of layer {layer}")));
        }
    })?;
    match failed {
        Some(error) => Err(error),
        None => Ok(moments),
    }
}

/// Gains that bring the trajectory and rate input segments to the absolute range of the
/// observation and previous-action segments (at least 1), from the f32 sampler's inputs over
/// `set` (see [`FoldedMlp::with_input_gains`]).
pub fn input_gains(model: &FoldedMlp, set: &CalibrationSet) -> anyhow::Result<InputGains> {
    let c = &model.base.config;
    let (obs_len, k) = (c.history * c.obs_dim, c.action_dim);
    let (mut fixed, mut rate, mut traj) = (1f32, 0f32, 0f32);
    observe_calibration(model, set, |probe, values| {
        if probe == Probe::Input {
            for (i, v) in values.iter().enumerate() {
                let a = v.abs();
                if i < obs_len + k {
                    fixed = fixed.max(a);
                } else if i < obs_len + 2 * k {
                    rate = rate.max(a);
                } else {
                    traj = traj.max(a);
                }
            }
        }
    })?;
    let gain = |range: f32| if range > 0.0 { fixed / range } else { 1.0 };
    Ok(InputGains {
        traj_gain: gain(traj),
        rate_gain: gain(rate),
    })
}

/// How far the first layer's accumulators can reach, per channel, given `|bias|` (the largest
/// over the bias variants) and `sum |w|` of its row.
type AccumulatorBound = fn(bias: i64, weight_sum: i64) -> i64;

/// Two-plane input (`frmd_core::quant::combine_plane_accumulators`): with int8 codes of magnitude
/// at most 128, `2^8 (|bias| + 128 sum|w|) + 128 sum|w|`.
const TWO_PLANE_BOUND: AccumulatorBound =
    |bias, weight_sum| ((bias + 128 * weight_sum) << FINE_INPUT_BITS) + 128 * weight_sum;

/// 16-bit input: with codes of magnitude at most 2^15, `|bias| + 2^15 sum|w|`.
const INT16_BOUND: AccumulatorBound = |bias, weight_sum| bias + (weight_sum << 15);

/// Checks that no first-layer accumulator of a wide input can leave i32 (`what` names the input
/// in the error): `bound` must fit for every channel and bias variant.
fn check_accumulator_range(
    weights: &[i8],
    in_features: usize,
    biases: &[i64],
    bound: AccumulatorBound,
    what: &str,
) -> anyhow::Result<()> {
    for (o, row) in weights.chunks_exact(in_features).enumerate() {
        let weight_sum: i64 = row.iter().map(|w| i64::from(*w).abs()).sum();
        let bias = biases
            .iter()
            .skip(o)
            .step_by(weights.len() / in_features)
            .map(|b| b.abs())
            .max()
            .unwrap_or(0);
        let reach = bound(bias, weight_sum);
        if reach > i64::from(i32::MAX) {
            bail!("first layer channel {o}: {what} accumulators could reach {reach} and leave i32 (export with plain int8 input)");
        }
    }
    Ok(())
}

/// Quantizes `model` with the calibrated `ranges`, normalization and ProDMP tables into a
/// [`QuantizedMlp`] with `P` activations, whose first layer takes its input as
/// `input_precision` says; `headroom` widens the activation ranges where `P` affords it;
/// `rounding` says how weights are rounded, with every layer's input moments ([`input_moments`])
/// for [`WeightRounding::Gptq`].
pub fn quantize<P: ExportPrecision>(
    model: &FoldedMlp,
    ranges: &Ranges,
    norm: &Normalization,
    input_precision: InputPrecision,
    headroom: f32,
    rounding: (WeightRounding, Option<&[InputMoments]>),
) -> anyhow::Result<QuantizedMlp<P>> {
    let weights =
        |l: usize, layer| round_weights(layer, rounding.0, rounding.1.and_then(|m| m.get(l)));
    let base = &model.base;
    let c = &base.config;
    if !model.hidden.is_empty() && !P::accepts(input_precision) {
        bail!(
            "{}-bit activations take the 16-bit input only (not {input_precision:?})",
            P::BITS
        );
    }
    let mut current = ranges.input;
    let mut hidden = Vec::new();
    let mut luts = Vec::new();
    let mut first_layer_biases = Vec::new();
    for (l, (layer, &(pre, out))) in model.hidden.iter().zip(&ranges.hidden).enumerate() {
        let what = |part: &str| format!("hidden layer {l} {part}");
        let pre = P::activation(pre, headroom).with_context(|| what("pre-activation"))?;
        let out = P::activation(out, headroom).with_context(|| what("output"))?;
        let q = weights(l, layer).with_context(|| format!("hidden layer {l}"))?;
        // The 16-bit input's codes are on the fine grid: so are the first layer's biases.
        let bias_input = match (l, input_precision) {
            (0, InputPrecision::Int16) => QuantParams {
                scale: wide_scale(current),
                zero_point: wide_zero_point(current),
            },
            _ => current,
        };
        let bias = P::bias(&layer.bias, &q, bias_input, layer.in_features)
            .with_context(|| format!("hidden layer {l}"))?;
        // The scale of the accumulators this layer requantizes.
        let mut accumulator_input_scale = bias_input.scale;
        if l == 0 {
            for variant in &model.first_layer_biases {
                first_layer_biases.extend(
                    P::bias(variant, &q, bias_input, layer.in_features)
                        .context("first-layer bias variant")?,
                );
            }
            let bound = match input_precision {
                InputPrecision::Int16 => Some((INT16_BOUND, "16-bit input")),
                InputPrecision::TwoPlane => Some((TWO_PLANE_BOUND, "two-plane input")),
                InputPrecision::Int8 => None,
            };
            if let Some((bound, what)) = bound.filter(|_| P::INT32_ACCUMULATORS) {
                for biases in [&first_layer_biases, &bias] {
                    let wide: Vec<i64> = biases.iter().map(|&b| b.into()).collect();
                    check_accumulator_range(&q.weights, layer.in_features, &wide, bound, what)?;
                }
            }
            if input_precision == InputPrecision::TwoPlane {
                accumulator_input_scale = current.scale / (1_u32 << FINE_INPUT_BITS) as f32;
            }
        }
        let (multipliers, shifts) = requantization::<P>(
            accumulator_input_scale,
            &q.scales,
            pre.scale,
            &format!("hidden layer {l}"),
        )?;
        let activation = layer.activation;
        let table = P::activation_table(|x| activation.apply(x), pre, out)
            .with_context(|| format!("hidden layer {l}: activation table"))?;
        luts.push(table);
        hidden.push(QuantizedLayer {
            in_features: layer.in_features,
            out_features: layer.out_features,
            weights: q.weights,
            bias,
            multipliers,
            shifts,
            output_zero_point: pre.zero_point,
            activation_min: P::MIN,
            activation_max: P::MAX,
            lut: Some(luts.len() - 1),
        });
        current = out;
    }
    let q = weights(model.hidden.len(), &model.output).context("output layer")?;
    let bias = P::bias(&model.output.bias, &q, current, model.output.in_features)
        .context("output layer")?;
    let output = QuantizedOutput {
        in_features: model.output.in_features,
        out_features: model.output.out_features,
        scales: q.scales.iter().map(|s| current.scale * s).collect(),
        weights: q.weights,
        bias,
    };
    Ok(QuantizedMlp {
        history: c.history,
        obs_dim: c.obs_dim,
        action_dim: c.action_dim,
        horizon: c.horizon,
        params_per_dof: c.output_dim() / c.action_dim,
        control_dt: c.control_dt as f32,
        layout: base.layout,
        input: ranges.input,
        input_precision: if model.hidden.is_empty() {
            InputPrecision::Int8
        } else {
            input_precision
        },
        obs_min: norm.obs.min.clone(),
        obs_max: norm.obs.max.clone(),
        action_min: norm.action.min.clone(),
        action_max: norm.action.max.clone(),
        prodmp: base.prodmp.clone(),
        steps: base.steps.clone(),
        first_layer_biases,
        luts,
        hidden,
        output,
    })
}
