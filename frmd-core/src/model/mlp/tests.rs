//! MLP tests: an f32 network is calibrated and quantized here exactly as the exporter will do it
//! (with the `quant` helpers), then the int8 forward pass is checked bit for bit against a naive
//! wide-integer re-implementation and approximately against the f32 reference.

extern crate std;

use super::*;
use crate::model::linear::{F32Linear, Int8Linear, RequantizedLinear};
use crate::kernels::{Activation, FcRequant, FullyConnected, KernelError, Lut8};
use crate::quant::{
    fold_input_zero_point, quantize_bias, quantize_weights_per_channel, reference,
    requantization_multiplier, QuantParams, FINE_INPUT_BITS,
};
use crate::rng::Rng;
use std::{vec, vec::Vec};

mod wide_input;

const WIDTH: usize = 48;

struct FloatLayer {
    in_features: usize,
    out_features: usize,
    weights: Vec<f32>,
    bias: Vec<f32>,
    activation: Activation,
}

impl FloatLayer {
    fn random(
        rng: &mut Rng,
        in_features: usize,
        out_features: usize,
        activation: Activation,
    ) -> Self {
        let gain = 1.5 / (in_features as f32).sqrt();
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

#[derive(Clone, Copy)]
struct Range {
    min: f32,
    max: f32,
}

impl Range {
    fn new() -> Self {
        Self {
            min: f32::MAX,
            max: f32::MIN,
        }
    }
    fn add(&mut self, values: &[f32]) {
        for v in values {
            self.min = self.min.min(*v);
            self.max = self.max.max(*v);
        }
    }
    fn params(&self) -> QuantParams {
        QuantParams::from_range(self.min, self.max).unwrap()
    }
}

struct QuantLayer {
    fc_weights: Vec<i8>,
    bias: Vec<i32>,
    multipliers: Vec<i32>,
    shifts: Vec<i32>,
    weight_scales: Vec<f32>,
    pre: QuantParams,
    lut: Option<Lut8>,
    in_features: usize,
    out_features: usize,
}

/// Quantizes weights and bias of `layer` for int8 input `input`; requantizes to `pre` if given.
fn quantize_layer(
    layer: &FloatLayer,
    input: QuantParams,
    pre: Option<QuantParams>,
    out: Option<QuantParams>,
) -> QuantLayer {
    let mut fc_weights = vec![0_i8; layer.weights.len()];
    let mut weight_scales = vec![0.0_f32; layer.out_features];
    quantize_weights_per_channel(
        &layer.weights,
        layer.in_features,
        &mut fc_weights,
        &mut weight_scales,
    )
    .unwrap();
    let mut bias = Vec::new();
    let mut multipliers = Vec::new();
    let mut shifts = Vec::new();
    for o in 0..layer.out_features {
        let row = &fc_weights[o * layer.in_features..(o + 1) * layer.in_features];
        let b = quantize_bias(layer.bias[o], input.scale, weight_scales[o]).unwrap();
        bias.push(fold_input_zero_point(b, row, input.zero_point).unwrap());
        if let Some(pre) = pre {
            let (m, s) =
                requantization_multiplier(input.scale, weight_scales[o], pre.scale).unwrap();
            multipliers.push(m);
            shifts.push(s);
        }
    }
    let lut = match (pre, out) {
        (Some(pre), Some(out)) => {
            Some(Lut8::build(|x| layer.activation.apply(x), pre, out).unwrap())
        }
        _ => None,
    };
    QuantLayer {
        fc_weights,
        bias,
        multipliers,
        shifts,
        weight_scales,
        pre: pre.unwrap_or(input),
        lut,
        in_features: layer.in_features,
        out_features: layer.out_features,
    }
}

struct Fixture {
    float_hidden: Vec<FloatLayer>,
    float_output: FloatLayer,
    input_params: QuantParams,
    quant_hidden: Vec<QuantLayer>,
    quant_output: QuantLayer,
    output_scales: Vec<f32>,
}

fn random_input(rng: &mut Rng, width: usize) -> Vec<f32> {
    (0..width)
        .map(|_| (rng.gaussian() * 0.6).clamp(-1.0, 1.0))
        .collect()
}

fn fixture(seed: u64) -> Fixture {
    let mut rng = Rng::new(seed);
    let float_hidden = vec![
        FloatLayer::random(&mut rng, 20, 40, Activation::Mish),
        FloatLayer::random(&mut rng, 40, 48, Activation::Silu),
        FloatLayer::random(&mut rng, 48, 32, Activation::Gelu),
    ];
    let float_output = FloatLayer::random(&mut rng, 32, 12, Activation::Identity);
    // Calibration: ranges of the input, every pre-activation and every hidden output.
    let views: Vec<F32Linear<'_>> = float_hidden.iter().map(FloatLayer::view).collect();
    let net = F32Mlp {
        hidden: &views,
        output: float_output.view(),
    };
    let mut input_range = Range::new();
    let mut pre_ranges = vec![Range::new(); float_hidden.len()];
    let mut out_ranges = vec![Range::new(); float_hidden.len()];
    let mut scratch = F32Scratch::<WIDTH>::new();
    let mut output = [0.0_f32; 12];
    for _ in 0..500 {
        let x = random_input(&mut rng, 20);
        net.forward_observed(&x, &mut output, &mut scratch, |probe, values| match probe {
            Probe::Input => input_range.add(values),
            Probe::PreActivation(l) => pre_ranges[l].add(values),
            Probe::Output(l) => out_ranges[l].add(values),
            Probe::Final => {}
        })
        .unwrap();
    }
    let input_params = input_range.params();
    let mut current = input_params;
    let mut quant_hidden = Vec::new();
    for (l, layer) in float_hidden.iter().enumerate() {
        let out = out_ranges[l].params();
        quant_hidden.push(quantize_layer(
            layer,
            current,
            Some(pre_ranges[l].params()),
            Some(out),
        ));
        current = out;
    }
    let quant_output = quantize_layer(&float_output, current, None, None);
    let output_scales = quant_output
        .weight_scales
        .iter()
        .map(|w| (f64::from(current.scale) * f64::from(*w)) as f32)
        .collect();
    Fixture {
        float_hidden,
        float_output,
        input_params,
        quant_hidden,
        quant_output,
        output_scales,
    }
}

fn int8_layers(quant: &[QuantLayer]) -> Vec<RequantizedLinear<'_>> {
    quant
        .iter()
        .map(|q| RequantizedLinear {
            fc: FullyConnected::new(q.in_features, q.out_features, &q.fc_weights, &q.bias),
            requant: FcRequant {
                multipliers: &q.multipliers,
                shifts: &q.shifts,
                output_zero_point: q.pre.zero_point,
                activation_min: -128,
                activation_max: 127,
            },
            activation: q.lut.as_ref().map(|lut| &lut.table),
        })
        .collect()
}

/// Naive int8 forward: i64 dot products, the wide requantization model, table lookups by index.
fn naive_int8_forward(fix: &Fixture, input: &[f32]) -> Vec<f32> {
    let x: Vec<i8> = input
        .iter()
        .map(|v| fix.input_params.quantize(*v))
        .collect();
    naive_int8_tail(fix, &fix.quant_hidden, x)
}

/// [`naive_int8_forward`] from int8 codes `x` through `layers`, then the output layer.
fn naive_int8_tail(fix: &Fixture, layers: &[QuantLayer], mut x: Vec<i8>) -> Vec<f32> {
    for q in layers {
        let mut y = Vec::new();
        for o in 0..q.out_features {
            let row = &q.fc_weights[o * q.in_features..(o + 1) * q.in_features];
            let acc: i64 = i64::from(q.bias[o])
                + row
                    .iter()
                    .zip(&x)
                    .map(|(w, v)| i64::from(*w) * i64::from(*v))
                    .sum::<i64>();
            let pre = reference::requantize(
                acc as i32,
                q.multipliers[o],
                q.shifts[o],
                q.pre.zero_point,
                -128,
                127,
            );
            let lut = q.lut.as_ref().unwrap();
            y.push(lut.table[(i32::from(pre) + 128) as usize]);
        }
        x = y;
    }
    let q = &fix.quant_output;
    (0..q.out_features)
        .map(|o| {
            let row = &q.fc_weights[o * q.in_features..(o + 1) * q.in_features];
            let acc: i64 = i64::from(q.bias[o])
                + row
                    .iter()
                    .zip(&x)
                    .map(|(w, v)| i64::from(*w) * i64::from(*v))
                    .sum::<i64>();
            acc as i32 as f32 * fix.output_scales[o]
        })
        .collect()
}

#[test]
fn int8_forward_is_bit_exact_with_naive_model_and_close_to_f32() {
    let fix = fixture(1234);
    let hidden = int8_layers(&fix.quant_hidden);
    let q = &fix.quant_output;
    let net = Int8Mlp {
        input: fix.input_params,
        hidden: &hidden,
        output: Int8Linear {
            fc: FullyConnected::new(q.in_features, q.out_features, &q.fc_weights, &q.bias),
            output_scales: &fix.output_scales,
        },
    };
    let float_views: Vec<F32Linear<'_>> = fix.float_hidden.iter().map(FloatLayer::view).collect();
    let float_net = F32Mlp {
        hidden: &float_views,
        output: fix.float_output.view(),
    };
    let mut scratch = Int8Scratch::<WIDTH>::new();
    let mut float_scratch = F32Scratch::<WIDTH>::new();
    let mut rng = Rng::new(99);
    let (mut max_error, mut max_magnitude) = (0.0_f32, 0.0_f32);
    for _ in 0..200 {
        let x = random_input(&mut rng, 20);
        let mut got = [0.0_f32; 12];
        net.forward(&x, &mut got, &mut scratch).unwrap();
        let want = naive_int8_forward(&fix, &x);
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(g.to_bits(), w.to_bits());
        }
        let mut float_out = [0.0_f32; 12];
        float_net
            .forward(&x, &mut float_out, &mut float_scratch)
            .unwrap();
        for (g, f) in got.iter().zip(&float_out) {
            max_error = max_error.max((g - f).abs());
            max_magnitude = max_magnitude.max(f.abs());
        }
    }
    std::eprintln!("int8 MLP vs f32: max abs error {max_error}, max |output| {max_magnitude}");
    assert!(max_magnitude > 0.5, "degenerate fixture: outputs too small");
    assert!(
        max_error < 0.05 * max_magnitude,
        "int8 error {max_error} vs output scale {max_magnitude}"
    );
}

#[test]
fn f32_forward_matches_direct_computation() {
    let fix = fixture(5);
    let views: Vec<F32Linear<'_>> = fix.float_hidden.iter().map(FloatLayer::view).collect();
    let net = F32Mlp {
        hidden: &views,
        output: fix.float_output.view(),
    };
    let mut rng = Rng::new(8);
    let x = random_input(&mut rng, 20);
    let mut out = [0.0_f32; 12];
    net.forward(&x, &mut out, &mut F32Scratch::<WIDTH>::new())
        .unwrap();
    let mut h: Vec<f64> = x.iter().map(|v| f64::from(*v)).collect();
    for layer in fix.float_hidden.iter().chain([&fix.float_output]) {
        h = (0..layer.out_features)
            .map(|o| {
                let row = &layer.weights[o * layer.in_features..(o + 1) * layer.in_features];
                let affine: f64 = f64::from(layer.bias[o])
                    + row
                        .iter()
                        .zip(&h)
                        .map(|(w, v)| f64::from(*w) * v)
                        .sum::<f64>();
                f64::from(layer.activation.apply(affine as f32))
            })
            .collect();
    }
    for (got, want) in out.iter().zip(&h) {
        assert!((f64::from(*got) - want).abs() < 1e-4, "{got} vs {want}");
    }
}

#[test]
fn shape_errors() {
    let fix = fixture(77);
    let hidden = int8_layers(&fix.quant_hidden);
    let q = &fix.quant_output;
    let net = Int8Mlp {
        input: fix.input_params,
        hidden: &hidden,
        output: Int8Linear {
            fc: FullyConnected::new(q.in_features, q.out_features, &q.fc_weights, &q.bias),
            output_scales: &fix.output_scales,
        },
    };
    let x = [0.0_f32; 20];
    let mut out = [0.0_f32; 12];
    assert_eq!(
        net.forward(&x[..19], &mut out, &mut Int8Scratch::<WIDTH>::new()),
        Err(ModelError::InputLength)
    );
    assert_eq!(
        net.forward(&x, &mut out[..11], &mut Int8Scratch::<WIDTH>::new()),
        Err(ModelError::OutputLength)
    );
    assert_eq!(
        net.forward(&x, &mut out, &mut Int8Scratch::<40>::new()),
        Err(ModelError::ScratchTooSmall)
    );
    let skipped = Int8Mlp {
        hidden: &hidden[1..],
        ..net
    };
    assert_eq!(
        skipped.forward(&[0.0; 40], &mut out, &mut Int8Scratch::<WIDTH>::new()),
        Ok(())
    );
    let broken = Int8Mlp {
        hidden: &hidden[..2],
        ..net
    };
    assert_eq!(
        broken.validate(WIDTH),
        Err(ModelError::LayerWidth { index: 2 })
    );
    let scales = Int8Mlp {
        output: Int8Linear {
            output_scales: &fix.output_scales[..3],
            ..net.output
        },
        ..net
    };
    assert_eq!(
        scales.validate(WIDTH),
        Err(ModelError::Kernel(KernelError::ScaleLength))
    );
    let bad_input = Int8Mlp {
        input: QuantParams {
            scale: -1.0,
            zero_point: 0,
        },
        ..net
    };
    assert_eq!(bad_input.validate(WIDTH), Err(ModelError::InputParams));

    let views: Vec<F32Linear<'_>> = fix.float_hidden.iter().map(FloatLayer::view).collect();
    let float_net = F32Mlp {
        hidden: &views,
        output: fix.float_output.view(),
    };
    assert_eq!(
        float_net.forward(&x, &mut out, &mut F32Scratch::<32>::new()),
        Err(ModelError::ScratchTooSmall)
    );
    let broken = F32Mlp {
        hidden: &views[1..],
        ..float_net
    };
    assert_eq!(broken.validate(WIDTH), Ok(()));
    assert_eq!(
        broken.forward(&x, &mut out, &mut F32Scratch::<WIDTH>::new()),
        Err(ModelError::InputLength)
    );
    let broken = F32Mlp {
        hidden: &views[..1],
        ..float_net
    };
    assert_eq!(
        broken.validate(WIDTH),
        Err(ModelError::LayerWidth { index: 1 })
    );
}

/// The fixture's first hidden layer re-quantized for a two-plane input: same weights and bias,
/// multipliers for the input scale `input_scale / 2^FINE_INPUT_BITS`.
fn two_plane_first_layer(fix: &Fixture) -> QuantLayer {
    let first = &fix.quant_hidden[0];
    let mut layer = QuantLayer {
        fc_weights: first.fc_weights.clone(),
        bias: first.bias.clone(),
        multipliers: Vec::new(),
        shifts: Vec::new(),
        weight_scales: first.weight_scales.clone(),
        pre: first.pre,
        lut: first.lut,
        in_features: first.in_features,
        out_features: first.out_features,
    };
    let fine_scale = fix.input_params.scale / (1_u32 << FINE_INPUT_BITS) as f32;
    for w in &first.weight_scales {
        let (m, s) = requantization_multiplier(fine_scale, *w, first.pre.scale).unwrap();
        layer.multipliers.push(m);
        layer.shifts.push(s);
    }
    layer
}

#[test]
fn two_plane_input_is_bit_exact_with_naive_model_and_more_accurate() {
    let fix = fixture(4321);
    let first = two_plane_first_layer(&fix);
    let first_layer = int8_layers(core::slice::from_ref(&first));
    let int8_hidden = int8_layers(&fix.quant_hidden);
    let mut hidden = first_layer.clone();
    hidden.extend_from_slice(&int8_hidden[1..]);
    let q = &fix.quant_output;
    let net = Int8Mlp {
        input: fix.input_params,
        hidden: &hidden,
        output: Int8Linear {
            fc: FullyConnected::new(q.in_features, q.out_features, &q.fc_weights, &q.bias),
            output_scales: &fix.output_scales,
        },
    };
    // Naive first layer: both planes from their definition, i64 dot products, the wide
    // combination and requantization models, the LUT by index.
    let fine_params = QuantParams {
        scale: fix.input_params.scale / 256.0,
        zero_point: 0,
    };
    // Returns the codes and, per channel, the real pre-activation of both planes and of the coarse
    // plane alone (what int8 input quantization gives).
    let naive_first = |x: &[f32]| -> (Vec<i8>, Vec<(f64, f64)>) {
        let planes: Vec<(i8, i8)> = x
            .iter()
            .map(|v| {
                let coarse = fix.input_params.quantize(*v);
                (
                    coarse,
                    fine_params.quantize(v - fix.input_params.dequantize(coarse)),
                )
            })
            .collect();
        let mut pre_real = Vec::new();
        let codes = (0..first.out_features)
            .map(|o| {
                let row = &first.fc_weights[o * first.in_features..(o + 1) * first.in_features];
                let dot = |plane: fn(&(i8, i8)) -> i8| -> i64 {
                    row.iter()
                        .zip(&planes)
                        .map(|(w, p)| i64::from(*w) * i64::from(plane(p)))
                        .sum()
                };
                let coarse = (i64::from(first.bias[o]) + dot(|p| p.0)) as i32;
                let acc = reference::combine_planes(coarse, dot(|p| p.1) as i32);
                let unit = f64::from(fix.input_params.scale) * f64::from(first.weight_scales[o]);
                pre_real.push((f64::from(acc) * unit / 256.0, f64::from(coarse) * unit));
                let m = (first.multipliers[o], first.shifts[o]);
                let pre = reference::requantize(acc, m.0, m.1, first.pre.zero_point, -128, 127);
                first.lut.as_ref().unwrap().table[(i32::from(pre) + 128) as usize]
            })
            .collect();
        (codes, pre_real)
    };
    let mut scratch = Int8Scratch::<WIDTH>::new();
    let mut rng = Rng::new(5);
    let (mut error_two_plane, mut error_int8) = (0.0_f64, 0.0_f64);
    for _ in 0..200 {
        let x = random_input(&mut rng, 20);
        let mut got = [0.0_f32; 12];
        net.forward_with_input(InputPrecision::TwoPlane, &x, &mut got, &mut scratch)
            .unwrap();
        let (codes, pre_real) = naive_first(&x);
        let want = naive_int8_tail(&fix, &fix.quant_hidden[1..], codes);
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(g.to_bits(), w.to_bits());
        }
        // First-layer pre-activations against the exact affine map of the quantized weights
        // (so only the input and bias rounding remain).
        for (o, (two, one)) in pre_real.iter().enumerate() {
            let row = &first.fc_weights[o * first.in_features..(o + 1) * first.in_features];
            let scale = f64::from(first.weight_scales[o]);
            let exact = f64::from(fix.float_hidden[0].bias[o])
                + row
                    .iter()
                    .zip(&x)
                    .map(|(w, v)| f64::from(*w) * scale * f64::from(*v))
                    .sum::<f64>();
            error_two_plane += (two - exact).abs();
            error_int8 += (one - exact).abs();
        }
    }
    std::eprintln!(
        "first-layer pre-activation abs error sums: two-plane {error_two_plane}, int8 {error_int8}"
    );
    assert!(error_two_plane < 0.05 * error_int8);
    // Without a hidden layer no layer takes the fine plane.
    let no_hidden = Int8Mlp {
        hidden: &[],
        output: Int8Linear {
            fc: FullyConnected::new(20, 12, &q.fc_weights[..240], &q.bias),
            output_scales: &fix.output_scales,
        },
        ..net
    };
    let mut output = [0.0_f32; 12];
    assert_eq!(
        no_hidden.forward_with_input(
            InputPrecision::TwoPlane,
            &[0.0; 20],
            &mut output,
            &mut scratch
        ),
        Err(ModelError::TwoPlaneWithoutHiddenLayer)
    );
    let network = crate::policy::Int8MlpNetwork::<WIDTH>::new(
        fix.input_params,
        InputPrecision::TwoPlane,
        &[],
        no_hidden.output,
        &[],
    );
    assert_eq!(
        network.err(),
        Some(crate::policy::PolicyError::Model(
            ModelError::TwoPlaneWithoutHiddenLayer
        ))
    );
}
