//! Test fixtures the model, policy and blob tests share: random f32 layers, calibration ranges,
//! and int8 layers quantized with the `quant` helpers the way the exporter does it.

extern crate std;

use std::{vec, vec::Vec};

use crate::kernels::{Activation, FcRequant, FullyConnected, Lut8};
use crate::model::linear::{F32Linear, Int8Linear, RequantizedLinear};
use crate::model::mlp::Probe;
use crate::quant::{
    fold_input_zero_point, quantize_bias, quantize_weights_per_channel, requantization_multiplier,
    QuantParams,
};
use crate::rng::Rng;

/// An owned f32 linear layer.
pub struct FloatLayer {
    pub in_features: usize,
    pub out_features: usize,
    pub weights: Vec<f32>,
    pub bias: Vec<f32>,
    pub activation: Activation,
}

impl FloatLayer {
    /// Gaussian weights of standard deviation `gain / sqrt(in_features)`, biases of 0.1.
    pub fn random(
        rng: &mut Rng,
        in_features: usize,
        out_features: usize,
        gain: f32,
        activation: Activation,
    ) -> Self {
        let gain = gain / (in_features as f32).sqrt();
        Self {
            in_features,
            out_features,
            weights: (0..in_features * out_features)
                .map(|_| rng.gaussian() * gain)
                .collect(),
            bias: (0..out_features).map(|_| 0.1 * rng.gaussian()).collect(),
            activation,
        }
    }

    pub fn view(&self) -> F32Linear<'_> {
        F32Linear {
            in_features: self.in_features,
            out_features: self.out_features,
            weights: &self.weights,
            bias: &self.bias,
            activation: self.activation,
        }
    }

    /// `W x + b` in f64 (the activation is not applied).
    pub fn affine64(&self, x: &[f64]) -> Vec<f64> {
        assert_eq!(x.len(), self.in_features);
        (0..self.out_features)
            .map(|o| {
                let row = &self.weights[o * self.in_features..(o + 1) * self.in_features];
                f64::from(self.bias[o])
                    + row
                        .iter()
                        .zip(x)
                        .map(|(w, v)| f64::from(*w) * v)
                        .sum::<f64>()
            })
            .collect()
    }
}

/// The calibration range of one tensor: min and max over everything shown to [`Range::add`].
#[derive(Clone, Copy)]
pub struct Range {
    pub min: f32,
    pub max: f32,
}

impl Range {
    pub fn new() -> Self {
        Self {
            min: f32::MAX,
            max: f32::MIN,
        }
    }

    pub fn add(&mut self, values: &[f32]) {
        for v in values {
            self.min = self.min.min(*v);
            self.max = self.max.max(*v);
        }
    }

    pub fn params(&self) -> QuantParams {
        QuantParams::from_range(self.min, self.max).unwrap()
    }
}

/// An owned int8 layer: per-channel weights, folded bias, and (hidden layers) the requantization
/// to `output` and the activation table.
pub struct QuantLayer {
    pub in_features: usize,
    pub out_features: usize,
    pub weights: Vec<i8>,
    pub bias: Vec<i32>,
    pub multipliers: Vec<i32>,
    pub shifts: Vec<i32>,
    pub weight_scales: Vec<f32>,
    /// The requantization target (the input parameters where there is none).
    pub output: QuantParams,
    pub lut: Option<Lut8>,
}

impl QuantLayer {
    /// The int8 weights of output channel `o`.
    pub fn row(&self, o: usize) -> &[i8] {
        &self.weights[o * self.in_features..(o + 1) * self.in_features]
    }

    /// The naive accumulator of output channel `o` for codes `x`: i64 dot product plus bias.
    pub fn naive_accumulator(&self, o: usize, x: &[i8]) -> i64 {
        i64::from(self.bias[o])
            + self
                .row(o)
                .iter()
                .zip(x)
                .map(|(w, v)| i64::from(*w) * i64::from(*v))
                .sum::<i64>()
    }

    pub fn fully_connected(&self) -> FullyConnected<'_> {
        FullyConnected::new(
            self.in_features,
            self.out_features,
            &self.weights,
            &self.bias,
        )
    }

    /// The layer as a hidden layer of an int8 MLP (requantized to `output`, full int8 range).
    pub fn requantized(&self) -> RequantizedLinear<'_> {
        RequantizedLinear {
            fc: self.fully_connected(),
            requant: FcRequant {
                multipliers: &self.multipliers,
                shifts: &self.shifts,
                output_zero_point: self.output.zero_point,
                activation_min: -128,
                activation_max: 127,
            },
            activation: self.lut.as_ref().map(|lut| &lut.table),
        }
    }

    /// Dequantization scales `input.scale * weight_scale[o]` (computed in f64).
    pub fn output_scales(&self, input: QuantParams) -> Vec<f32> {
        self.weight_scales
            .iter()
            .map(|w| (f64::from(input.scale) * f64::from(*w)) as f32)
            .collect()
    }
}

/// Quantizes `layer`'s weights and `bias` for inputs with parameters `input`; with `output`, the
/// per-channel requantization to it (no activation table).
pub fn quantize_layer(
    layer: &FloatLayer,
    bias: &[f32],
    input: QuantParams,
    output: Option<QuantParams>,
) -> QuantLayer {
    let mut weights = vec![0_i8; layer.weights.len()];
    let mut weight_scales = vec![0.0_f32; layer.out_features];
    quantize_weights_per_channel(
        &layer.weights,
        layer.in_features,
        &mut weights,
        &mut weight_scales,
    )
    .unwrap();
    let mut q_bias = Vec::new();
    let (mut multipliers, mut shifts) = (Vec::new(), Vec::new());
    for o in 0..layer.out_features {
        let row = &weights[o * layer.in_features..(o + 1) * layer.in_features];
        let b = quantize_bias(bias[o], input.scale, weight_scales[o]).unwrap();
        q_bias.push(fold_input_zero_point(b, row, input.zero_point).unwrap());
        if let Some(out) = output {
            let (m, s) =
                requantization_multiplier(input.scale, weight_scales[o], out.scale).unwrap();
            multipliers.push(m);
            shifts.push(s);
        }
    }
    QuantLayer {
        in_features: layer.in_features,
        out_features: layer.out_features,
        weights,
        bias: q_bias,
        multipliers,
        shifts,
        weight_scales,
        output: output.unwrap_or(input),
        lut: None,
    }
}

/// A hidden layer: [`quantize_layer`] requantized to `pre` (its pre-activation parameters), then
/// the activation as a table from `pre` to `post`.
pub fn quantize_hidden(
    layer: &FloatLayer,
    bias: &[f32],
    input: QuantParams,
    pre: QuantParams,
    post: QuantParams,
) -> QuantLayer {
    let mut q = quantize_layer(layer, bias, input, Some(pre));
    q.lut = Some(Lut8::build(|v| layer.activation.apply(v), pre, post).unwrap());
    q
}

/// Calibration ranges of an MLP's probes: its input, and per hidden layer the pre-activation and
/// the activation output.
pub struct MlpRanges {
    pub input: Range,
    pub pre: Vec<Range>,
    pub post: Vec<Range>,
}

impl MlpRanges {
    pub fn new(hidden_layers: usize) -> Self {
        Self {
            input: Range::new(),
            pre: vec![Range::new(); hidden_layers],
            post: vec![Range::new(); hidden_layers],
        }
    }

    /// The `forward_observed` callback.
    pub fn observe(&mut self, probe: Probe, values: &[f32]) {
        match probe {
            Probe::Input => self.input.add(values),
            Probe::PreActivation(l) => self.pre[l].add(values),
            Probe::Output(l) => self.post[l].add(values),
            Probe::Final => {}
        }
    }

    /// The MLP `hidden` + `output` quantized with these ranges, layer after layer.
    pub fn quantize(&self, hidden: &[FloatLayer], output: &FloatLayer) -> QuantMlp {
        let input = self.input.params();
        let mut current = input;
        let mut quant_hidden = Vec::new();
        for (l, layer) in hidden.iter().enumerate() {
            let post = self.post[l].params();
            quant_hidden.push(quantize_hidden(
                layer,
                &layer.bias,
                current,
                self.pre[l].params(),
                post,
            ));
            current = post;
        }
        let quant_output = quantize_layer(output, &output.bias, current, None);
        QuantMlp {
            input,
            output_scales: quant_output.output_scales(current),
            hidden: quant_hidden,
            output: quant_output,
        }
    }
}

/// A quantized MLP: input parameters, hidden layers, the output layer and its dequantization.
pub struct QuantMlp {
    pub input: QuantParams,
    pub hidden: Vec<QuantLayer>,
    pub output: QuantLayer,
    pub output_scales: Vec<f32>,
}

impl QuantMlp {
    pub fn hidden_layers(&self) -> Vec<RequantizedLinear<'_>> {
        self.hidden.iter().map(QuantLayer::requantized).collect()
    }

    pub fn output_layer(&self) -> Int8Linear<'_> {
        Int8Linear {
            fc: self.output.fully_connected(),
            output_scales: &self.output_scales,
        }
    }
}
