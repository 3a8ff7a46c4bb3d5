//! Test-only model: a small random f32 student MLP, calibrated and quantized with the `quant`
//! helpers (as the exporter does), with ProDMP tables, step constants and normalization, so the
//! policy and blob tests can run the f32 and int8 paths side by side.

extern crate std;

use std::{vec, vec::Vec};

use super::*;
use crate::blob::MlpBlobParts;
use crate::kernels::{Activation, FcRequant, FullyConnected, Lut8};
use crate::model::linear::{F32Linear, Int8Linear, RequantizedLinear};
use crate::model::mlp::{F32Mlp, F32Scratch, InputPrecision, Int8Mlp, Probe};
use crate::prodmp::{BakedProDmp, ProDmpConfig};
use crate::quant::{
    fold_input_zero_point, quantize_bias, quantize_weights_per_channel, requantization_multiplier,
    QuantParams,
};
use crate::rng::Rng;

pub const M: usize = 2;
pub const O: usize = 3;
pub const K: usize = 2;
pub const N: usize = 6;
pub const NUM_BASIS: usize = 3;
pub const P: usize = NUM_BASIS + 1;
/// Input width of the standard layout: M*O + 2K + N*K.
pub const IN: usize = M * O + 2 * K + N * K;
pub const I: usize = 32;
pub const WIDTH: usize = 40;
pub const DT: f32 = 0.05;

pub type F32Policy<'a> = Policy<'a, F32MlpNetwork<'a, WIDTH>, M, O, K, N, P, I>;
pub type Int8Policy<'a> = Policy<'a, Int8MlpNetwork<'a, WIDTH>, M, O, K, N, P, I>;

/// The test model's sizes.
pub const DIMS: PolicyDims = PolicyDims {
    history: M,
    obs_dim: O,
    action_dim: K,
    horizon: N,
    params_per_dof: P,
};

pub struct FloatLayer {
    pub in_features: usize,
    pub out_features: usize,
    pub weights: Vec<f32>,
    pub bias: Vec<f32>,
    pub activation: Activation,
}

impl FloatLayer {
    fn random(rng: &mut Rng, inputs: usize, outputs: usize, activation: Activation) -> Self {
        let gain = 1.2 / (inputs as f32).sqrt();
        Self {
            in_features: inputs,
            out_features: outputs,
            weights: (0..inputs * outputs)
                .map(|_| rng.gaussian() * gain)
                .collect(),
            bias: (0..outputs).map(|_| 0.1 * rng.gaussian()).collect(),
            activation,
        }
    }

    fn view(&self) -> F32Linear<'_> {
        F32Linear {
            in_features: self.in_features,
            out_features: self.out_features,
            weights: &self.weights,
            bias: &self.bias,
            activation: self.activation,
        }
    }
}

pub struct QuantLayer {
    pub in_features: usize,
    pub out_features: usize,
    pub weights: Vec<i8>,
    pub bias: Vec<i32>,
    pub multipliers: Vec<i32>,
    pub shifts: Vec<i32>,
    pub weight_scales: Vec<f32>,
    pub output: QuantParams,
    pub lut: Option<Lut8>,
}

#[derive(Clone, Copy)]
struct Range(f32, f32);

impl Range {
    fn new() -> Self {
        Self(f32::MAX, f32::MIN)
    }
    fn add(&mut self, values: &[f32]) {
        for v in values {
            self.0 = self.0.min(*v);
            self.1 = self.1.max(*v);
        }
    }
    fn params(self) -> QuantParams {
        QuantParams::from_range(self.0, self.1).unwrap()
    }
}

pub struct TestModel {
    pub hidden: Vec<FloatLayer>,
    pub output: FloatLayer,
    /// Per-step first-layer bias variants (f32), `hidden[0].out_features` each.
    pub bias_variants: Vec<f32>,
    pub input: QuantParams,
    pub quant_hidden: Vec<QuantLayer>,
    pub quant_output: QuantLayer,
    pub output_scales: Vec<f32>,
    pub int8_bias_variants: Vec<i32>,
    pub decoder: BakedProDmp<N, P>,
    pub steps: Vec<StepConstants>,
    /// Observation min and max.
    pub obs_range: ([f32; O], [f32; O]),
    /// Action min and max.
    pub action_range: ([f32; K], [f32; K]),
    pub layout: InputLayout,
}

/// EDM consistency constants for `sigma` (sigma_min 0.002, sigma_data 0.5), computed in f64.
pub fn step_constants(sigma: f64, first: bool, index: u32) -> StepConstants {
    let (sigma_min, sigma_data) = (0.002_f64, 0.5_f64);
    let norm = (sigma * sigma + sigma_data * sigma_data).sqrt();
    let shifted = sigma - sigma_min;
    StepConstants {
        sigma: sigma as f32,
        renoise_std: if first {
            0.0
        } else {
            (sigma * sigma - sigma_min * sigma_min).sqrt() as f32
        },
        c_in: (1.0 / norm) as f32,
        c_skip: (sigma_data * sigma_data / (shifted * shifted + sigma_data * sigma_data)) as f32,
        c_out: (shifted * sigma_data / norm) as f32,
        noise_variant: index,
    }
}

fn quantize_layer(
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

impl TestModel {
    /// A random model with `sigmas.len()` steps (first step at `sigmas[0]`).
    pub fn new(seed: u64, sigmas: &[f64]) -> Self {
        let mut rng = Rng::new(seed);
        let hidden = vec![
            FloatLayer::random(&mut rng, IN, 40, Activation::Silu),
            FloatLayer::random(&mut rng, 40, 32, Activation::Mish),
        ];
        let output = FloatLayer::random(&mut rng, 32, K * P, Activation::Identity);
        let first_out = hidden[0].out_features;
        let mut bias_variants = Vec::new();
        for _ in sigmas {
            bias_variants.extend(hidden[0].bias.iter().map(|b| b + 0.3 * rng.gaussian()));
        }
        let steps: Vec<StepConstants> = sigmas
            .iter()
            .enumerate()
            .map(|(i, s)| step_constants(*s, i == 0, i as u32))
            .collect();
        // Calibration over random inputs shaped like the policy's (trajectory part ~ c_in x).
        let mut input_range = Range::new();
        let mut pre = vec![Range::new(); hidden.len()];
        let mut post = vec![Range::new(); hidden.len()];
        let mut scratch = F32Scratch::<WIDTH>::new();
        let mut out = [0.0_f32; K * P];
        for sample in 0..400 {
            let variant = sample % sigmas.len();
            let mut first = hidden[0].view();
            first.bias = &bias_variants[variant * first_out..(variant + 1) * first_out];
            let views = [first, hidden[1].view()];
            let net = F32Mlp {
                hidden: &views,
                output: output.view(),
            };
            let x: Vec<f32> = (0..IN)
                .map(|j| {
                    if j < IN - N * K {
                        2.0 * rng.uniform() - 1.0
                    } else {
                        (1.2 * rng.gaussian()).clamp(-3.5, 3.5)
                    }
                })
                .collect();
            net.forward_observed(&x, &mut out, &mut scratch, |probe, values| match probe {
                Probe::Input => input_range.add(values),
                Probe::PreActivation(l) => pre[l].add(values),
                Probe::Output(l) => post[l].add(values),
                Probe::Final => {}
            })
            .unwrap();
        }
        let input = input_range.params();
        let mut current = input;
        let mut quant_hidden = Vec::new();
        let mut int8_bias_variants = Vec::new();
        for (l, layer) in hidden.iter().enumerate() {
            let pre_params = pre[l].params();
            let post_params = post[l].params();
            let mut q = quantize_layer(layer, &layer.bias, current, Some(pre_params));
            q.lut =
                Some(Lut8::build(|v| layer.activation.apply(v), pre_params, post_params).unwrap());
            if l == 0 {
                for variant in bias_variants.chunks(first_out) {
                    int8_bias_variants.extend(quantize_layer(layer, variant, current, None).bias);
                }
            }
            quant_hidden.push(q);
            current = post_params;
        }
        let quant_output = quantize_layer(&output, &output.bias, current, None);
        let output_scales = quant_output
            .weight_scales
            .iter()
            .map(|w| (f64::from(current.scale) * f64::from(*w)) as f32)
            .collect();
        let decoder =
            BakedProDmp::from_config(&ProDmpConfig::policy(K, NUM_BASIS, N, f64::from(DT)))
                .unwrap();
        Self {
            hidden,
            output,
            bias_variants,
            input,
            quant_hidden,
            quant_output,
            output_scales,
            int8_bias_variants,
            decoder,
            steps,
            obs_range: ([-1.0, 0.0, 2.0], [1.0, 4.0, 2.0]),
            action_range: ([-0.5, 0.1], [0.5, 0.3]),
            layout: InputLayout::standard(DT),
        }
    }

    pub fn obs_norm(&self) -> RangeNormalizer<'_> {
        RangeNormalizer::new(&self.obs_range.0, &self.obs_range.1)
    }

    pub fn action_norm(&self) -> RangeNormalizer<'_> {
        RangeNormalizer::new(&self.action_range.0, &self.action_range.1)
    }

    pub fn config(&self) -> PolicyConfig<'_> {
        PolicyConfig {
            history: M,
            obs_norm: self.obs_norm(),
            action_norm: self.action_norm(),
            sampler: Sampler {
                steps: StepTable::new(&self.steps),
                decoder: ProDmpTables::from_baked(&self.decoder),
                layout: self.layout,
                control_dt: DT,
            },
        }
    }

    pub fn f32_network(&self) -> F32MlpNetwork<'_, WIDTH> {
        let views: Vec<F32Linear<'_>> = self.hidden.iter().map(FloatLayer::view).collect();
        F32MlpNetwork::new(&views, self.output.view(), &self.bias_variants).unwrap()
    }

    pub fn int8_layers(&self) -> Vec<RequantizedLinear<'_>> {
        self.quant_hidden
            .iter()
            .map(|q| RequantizedLinear {
                fc: FullyConnected::new(q.in_features, q.out_features, &q.weights, &q.bias),
                requant: FcRequant {
                    multipliers: &q.multipliers,
                    shifts: &q.shifts,
                    output_zero_point: q.output.zero_point,
                    activation_min: -128,
                    activation_max: 127,
                },
                activation: q.lut.as_ref().map(|lut| &lut.table),
            })
            .collect()
    }

    pub fn int8_output(&self) -> Int8Linear<'_> {
        let q = &self.quant_output;
        Int8Linear {
            fc: FullyConnected::new(q.in_features, q.out_features, &q.weights, &q.bias),
            output_scales: &self.output_scales,
        }
    }

    pub fn int8_network(&self) -> Int8MlpNetwork<'_, WIDTH> {
        Int8MlpNetwork::new(
            self.input,
            InputPrecision::Int8,
            &self.int8_layers(),
            self.int8_output(),
            &self.int8_bias_variants,
        )
        .unwrap()
    }

    pub fn f32_policy(&self) -> F32Policy<'_> {
        Policy::new(self.config(), self.f32_network()).unwrap()
    }

    pub fn int8_policy(&self) -> Int8Policy<'_> {
        Policy::new(self.config(), self.int8_network()).unwrap()
    }

    /// Blob parts borrowing this model, with its hidden layers in `hidden` (from
    /// [`Self::int8_layers`]).
    pub fn blob_parts<'p>(&'p self, hidden: &'p [RequantizedLinear<'p>]) -> MlpBlobParts<'p> {
        MlpBlobParts {
            config: self.config(),
            mlp: Int8Mlp {
                input: self.input,
                hidden,
                output: self.int8_output(),
            },
            input_precision: InputPrecision::Int8,
            noise_variants: &self.int8_bias_variants,
        }
    }
}
