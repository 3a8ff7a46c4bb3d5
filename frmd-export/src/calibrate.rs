//! Calibration and quantization of a [`FoldedMlp`] into a [`QuantizedPolicy`].
//!
//! Calibration runs frmd-core's f32 path (through [`FoldedMlp::sample`], i.e. the same
//! multi-step sampler with re-noising) over calibration conditions with seeded noise, and
//! records per tensor the input, every pre-activation and every hidden output. Ranges are the
//! min/max or a symmetric percentile of the recorded values. Quantization then follows
//! docs/design.md section 5 with frmd-core's `quant` helpers (per-channel symmetric weights, int32 bias
//! with the input zero point folded, Q31 requantization to the pre-activation range, a 256-entry
//! LUT to the output range, a dequantized output layer). With a 16-bit input
//! (`frmd_core::model::mlp::InputPrecision::Int16`, the default of
//! [`crate::export::ExportOptions`]) the first layer's bias and multipliers are made for the
//! fine input scale `input_scale / 2^8` (zero point `frmd_core::quant::wide_zero_point`); with a
//! two-plane input (`TwoPlane`) only its multipliers are; for both the exporter widens the input
//! range (see [`crate::export::ExportOptions::input_headroom`]).
use crate::fold::{FloatLayer, FoldedMlp, InputGains};
use crate::{QuantizedLayer, QuantizedOutput, QuantizedPolicy};
use anyhow::{bail, Context};
use frmd_core::blob::LUT_LEN;
use frmd_core::kernels::Lut8;
use frmd_core::model::mlp::InputPrecision;
use frmd_core::model::mlp::Probe;
use frmd_core::quant::{
    fold_input_zero_point, quantize_bias, quantize_weights_per_channel, requantization_multiplier,
    wide_scale, wide_zero_point, QuantParams, FINE_INPUT_BITS,
};
use frmd_core::rng::Rng;

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

/// Calibration conditions: rows of `[obs history, y0, v0]` in normalized units (v0 per second),
/// as in training windows. Noise is drawn per row from `frmd_core::rng::Rng::new(seed + row)`.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationSet {
    /// Width of one row (`m O + 2 K`).
    pub cond_dim: usize,
    /// Row-major conditions.
    pub cond: Vec<f32>,
    pub seed: u64,
}

impl CalibrationSet {
    pub fn rows(&self) -> usize {
        self.cond.len().checked_div(self.cond_dim).unwrap_or(0)
    }

    /// Noise of row `row` for `steps` steps of `traj` values.
    pub fn noise(&self, row: usize, steps: usize, traj: usize) -> Vec<f32> {
        let mut rng = Rng::new(self.seed.wrapping_add(row as u64));
        let mut z = vec![0.0; steps * traj];
        rng.fill_gaussian(&mut z);
        z
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
        QuantParams::from_range(lo, hi)
            .map_err(|e| anyhow::anyhow!("{what}: range [{lo}, {hi}]: {e:?}"))
    }
}

/// Activation parameters found by calibration.
#[derive(Clone, Debug, PartialEq)]
pub struct Ranges {
    pub input: QuantParams,
    /// Per hidden layer: (pre-activation, output).
    pub hidden: Vec<(QuantParams, QuantParams)>,
    /// Calibration rows run (each through every sampling step).
    pub rows: usize,
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
    QuantParams::from_range(lo, hi).map_err(|e| anyhow::anyhow!("range [{lo}, {hi}]: {e:?}"))
}

/// Runs the f32 sampler over `set` and derives the activation parameters.
pub fn calibrate(
    model: &FoldedMlp,
    set: &CalibrationSet,
    method: RangeMethod,
) -> anyhow::Result<Ranges> {
    let c = &model.config;
    let cond_dim = c.cond_dim();
    if set.cond_dim != cond_dim {
        bail!(
            "calibration rows have {} values, the model's condition has {cond_dim}",
            set.cond_dim
        );
    }
    if set.rows() == 0 {
        bail!("the calibration set is empty");
    }
    let layers = model.hidden.len();
    let mut input = Recorder::default();
    let mut pre: Vec<Recorder> = (0..layers).map(|_| Recorder::default()).collect();
    let mut out: Vec<Recorder> = (0..layers).map(|_| Recorder::default()).collect();
    for row in 0..set.rows() {
        let cond = &set.cond[row * cond_dim..(row + 1) * cond_dim];
        let noise = set.noise(row, model.steps.len(), c.traj_dim());
        model.sample(cond, &noise, |_, probe, values| match probe {
            Probe::Input => input.values.extend_from_slice(values),
            Probe::PreActivation(l) => pre[l].values.extend_from_slice(values),
            Probe::Output(l) => out[l].values.extend_from_slice(values),
            Probe::Final => {}
        })?;
    }
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

/// Gains that bring the trajectory and rate input segments to the absolute range of the
/// observation and previous-action segments (at least 1), from the f32 sampler's inputs over
/// `set` (see [`crate::fold`]).
pub fn input_gains(model: &FoldedMlp, set: &CalibrationSet) -> anyhow::Result<InputGains> {
    let c = &model.config;
    let (obs_len, k) = (c.history * c.obs_dim, c.action_dim);
    let (mut fixed, mut rate, mut traj) = (1f32, 0f32, 0f32);
    for row in 0..set.rows() {
        let cond = set
            .cond
            .get(row * set.cond_dim..(row + 1) * set.cond_dim)
            .context("calibration row")?;
        let noise = set.noise(row, model.steps.len(), c.traj_dim());
        model.sample(cond, &noise, |_, probe, values| {
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
    }
    let gain = |range: f32| if range > 0.0 { fixed / range } else { 1.0 };
    Ok(InputGains {
        traj_gain: gain(traj),
        rate_gain: gain(rate),
    })
}

pub(crate) struct QuantizedWeights {
    pub(crate) weights: Vec<i8>,
    pub(crate) scales: Vec<f32>,
}

pub(crate) fn quantize_weights(layer: &FloatLayer) -> anyhow::Result<QuantizedWeights> {
    let mut weights = vec![0i8; layer.weights.len()];
    let mut scales = vec![0f32; layer.out_features];
    quantize_weights_per_channel(&layer.weights, layer.in_features, &mut weights, &mut scales)
        .map_err(|e| {
            anyhow::anyhow!(
                "weights [{} x {}]: {e:?}",
                layer.out_features,
                layer.in_features
            )
        })?;
    Ok(QuantizedWeights { weights, scales })
}

pub(crate) fn int_bias(
    bias: &[f32],
    q: &QuantizedWeights,
    input: QuantParams,
    in_features: usize,
) -> anyhow::Result<Vec<i32>> {
    bias.iter()
        .enumerate()
        .map(|(o, &b)| {
            let b = quantize_bias(b, input.scale, q.scales[o])
                .map_err(|e| anyhow::anyhow!("bias {o}: {e:?}"))?;
            fold_input_zero_point(
                b,
                &q.weights[o * in_features..(o + 1) * in_features],
                input.zero_point,
            )
            .map_err(|e| anyhow::anyhow!("bias {o} with zero point: {e:?}"))
        })
        .collect()
}

/// Checks that no two-plane accumulator of the first layer can saturate
/// (`frmd_core::quant::combine_plane_accumulators`): with int8 codes of magnitude at most 128,
/// `2^8 (|bias| + 128 sum|w|) + 128 sum|w|` must fit in i32 for every channel and bias variant.
fn check_two_plane_range(weights: &[i8], in_features: usize, biases: &[i32]) -> anyhow::Result<()> {
    for (o, row) in weights.chunks_exact(in_features).enumerate() {
        let weight_sum: i64 = row.iter().map(|w| i64::from(*w).abs()).sum();
        let bias = biases
            .iter()
            .skip(o)
            .step_by(weights.len() / in_features)
            .map(|b| i64::from(*b).abs())
            .max()
            .unwrap_or(0);
        let bound = ((bias + 128 * weight_sum) << FINE_INPUT_BITS) + 128 * weight_sum;
        if bound > i64::from(i32::MAX) {
            bail!("first layer channel {o}: two-plane input accumulators could reach {bound} and saturate i32 (export with plain int8 input)");
        }
    }
    Ok(())
}

/// Checks that no first-layer accumulator of a 16-bit input can wrap: with codes of magnitude at
/// most 2^15, `|bias| + 2^15 sum|w|` must fit in i32 for every channel and bias variant.
fn check_int16_range(weights: &[i8], in_features: usize, biases: &[i32]) -> anyhow::Result<()> {
    for (o, row) in weights.chunks_exact(in_features).enumerate() {
        let weight_sum: i64 = row.iter().map(|w| i64::from(*w).abs()).sum();
        let bias = biases
            .iter()
            .skip(o)
            .step_by(weights.len() / in_features)
            .map(|b| i64::from(*b).abs())
            .max()
            .unwrap_or(0);
        let bound = bias + (weight_sum << 15);
        if bound > i64::from(i32::MAX) {
            bail!("first layer channel {o}: 16-bit input accumulators could reach {bound} and wrap i32 (export with int8 input)");
        }
    }
    Ok(())
}

/// Quantizes `model` with the calibrated `ranges`, normalization and ProDMP tables into a
/// [`QuantizedPolicy`] whose first layer takes its input as `input_precision` says.
pub fn quantize(
    model: &FoldedMlp,
    ranges: &Ranges,
    norm: &crate::checkpoint::Normalization,
    input_precision: InputPrecision,
) -> anyhow::Result<QuantizedPolicy> {
    let c = &model.config;
    let mut current = ranges.input;
    let mut hidden = Vec::new();
    let mut luts: Vec<[i8; LUT_LEN]> = Vec::new();
    let mut first_layer_biases = Vec::new();
    for (l, (layer, &(pre, out))) in model.hidden.iter().zip(&ranges.hidden).enumerate() {
        let q = quantize_weights(layer).with_context(|| format!("hidden layer {l}"))?;
        // The 16-bit input's codes are on the fine grid: so are the first layer's biases.
        let bias_input = match (l, input_precision) {
            (0, InputPrecision::Int16) => QuantParams {
                scale: wide_scale(current),
                zero_point: wide_zero_point(current),
            },
            _ => current,
        };
        let bias = int_bias(&layer.bias, &q, bias_input, layer.in_features)
            .with_context(|| format!("hidden layer {l}"))?;
        // The scale of the accumulators this layer requantizes.
        let mut accumulator_input_scale = bias_input.scale;
        if l == 0 {
            for variant in &model.first_layer_biases {
                first_layer_biases.extend(
                    int_bias(variant, &q, bias_input, layer.in_features)
                        .context("first-layer bias variant")?,
                );
            }
            if input_precision == InputPrecision::Int16 {
                check_int16_range(&q.weights, layer.in_features, &first_layer_biases)?;
                check_int16_range(&q.weights, layer.in_features, &bias)?;
            }
            if input_precision == InputPrecision::TwoPlane {
                check_two_plane_range(&q.weights, layer.in_features, &first_layer_biases)?;
                check_two_plane_range(&q.weights, layer.in_features, &bias)?;
                accumulator_input_scale = current.scale / (1_u32 << FINE_INPUT_BITS) as f32;
            }
        }
        let (mut multipliers, mut shifts) = (Vec::new(), Vec::new());
        for (o, scale) in q.scales.iter().enumerate() {
            let (m, s) = requantization_multiplier(accumulator_input_scale, *scale, pre.scale)
                .map_err(|e| {
                    anyhow::anyhow!(
                        "hidden layer {l} channel {o}: requantization multiplier: {e:?}"
                    )
                })?;
            multipliers.push(m);
            shifts.push(s);
        }
        let activation = layer.activation;
        let lut = Lut8::build(|x| activation.apply(x), pre, out)
            .map_err(|e| anyhow::anyhow!("hidden layer {l}: activation table: {e:?}"))?;
        let mut table = [0i8; LUT_LEN];
        for (i, slot) in table.iter_mut().enumerate() {
            *slot = lut.lookup((i as i32 - 128) as i8);
        }
        luts.push(table);
        hidden.push(QuantizedLayer {
            in_features: layer.in_features,
            out_features: layer.out_features,
            weights: q.weights,
            bias,
            multipliers,
            shifts,
            output_zero_point: pre.zero_point,
            activation_min: i8::MIN,
            activation_max: i8::MAX,
            lut: Some(luts.len() - 1),
        });
        current = out;
    }
    let q = quantize_weights(&model.output).context("output layer")?;
    let bias = int_bias(&model.output.bias, &q, current, model.output.in_features)
        .context("output layer")?;
    let output = QuantizedOutput {
        in_features: model.output.in_features,
        out_features: model.output.out_features,
        scales: q.scales.iter().map(|s| current.scale * s).collect(),
        weights: q.weights,
        bias,
    };
    Ok(QuantizedPolicy {
        history: c.history,
        obs_dim: c.obs_dim,
        action_dim: c.action_dim,
        horizon: c.horizon,
        params_per_dof: c.output_dim() / c.action_dim,
        control_dt: c.control_dt as f32,
        layout: model.layout,
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
        prodmp: model.prodmp.clone(),
        steps: model.steps.clone(),
        first_layer_biases,
        luts,
        hidden,
        output,
    })
}
