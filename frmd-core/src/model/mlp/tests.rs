//! MLP tests: an f32 network is calibrated and quantized here exactly as the exporter will do it
//! (with the `quant` helpers), then the int8 forward pass is checked bit for bit against a naive
//! wide-integer re-implementation and approximately against the f32 reference.

extern crate std;

use super::*;
use crate::kernels::{Activation, FullyConnected, KernelError};
use crate::model::fixture::{quantize_layer, FloatLayer, MlpRanges, QuantLayer, QuantMlp};
use crate::model::linear::{F32Linear, Int8Linear, RequantizedLinear};
use crate::quant::{reference, requantization_multiplier, QuantParams, FINE_INPUT_BITS};
use crate::rng::Rng;
use std::{vec, vec::Vec};

mod wide_input;

const WIDTH: usize = 48;

struct Fixture {
    float_hidden: Vec<FloatLayer>,
    float_output: FloatLayer,
    quant: QuantMlp,
}

impl Fixture {
    /// The int8 network with `hidden` as its hidden layers.
    fn int8_mlp<'a>(&'a self, hidden: &'a [RequantizedLinear<'a>]) -> Int8Mlp<'a> {
        Int8Mlp {
            input: self.quant.input,
            hidden,
            output: self.quant.output_layer(),
        }
    }
}

fn random_input(rng: &mut Rng, width: usize) -> Vec<f32> {
    (0..width)
        .map(|_| (rng.gaussian() * 0.6).clamp(-1.0, 1.0))
        .collect()
}

fn fixture(seed: u64) -> Fixture {
    let mut rng = Rng::new(seed);
    let float_hidden = vec![
        FloatLayer::random(&mut rng, 20, 40, 1.5, Activation::Mish),
        FloatLayer::random(&mut rng, 40, 48, 1.5, Activation::Silu),
        FloatLayer::random(&mut rng, 48, 32, 1.5, Activation::Gelu),
    ];
    let float_output = FloatLayer::random(&mut rng, 32, 12, 1.5, Activation::Identity);
    // Calibration: ranges of the input, every pre-activation and every hidden output.
    let views: Vec<F32Linear<'_>> = float_hidden.iter().map(FloatLayer::view).collect();
    let net = F32Mlp {
        hidden: &views,
        output: float_output.view(),
    };
    let mut ranges = MlpRanges::new(float_hidden.len());
    let mut scratch = F32Scratch::<WIDTH>::new();
    let mut output = [0.0_f32; 12];
    for _ in 0..500 {
        let x = random_input(&mut rng, 20);
        net.forward_observed(&x, &mut output, &mut scratch, |probe, values| {
            ranges.observe(probe, values)
        })
        .unwrap();
    }
    let quant = ranges.quantize(&float_hidden, &float_output);
    Fixture {
        float_hidden,
        float_output,
        quant,
    }
}

/// The fixture's hidden layers with `first` in place of the first one.
fn hidden_with<'a>(fix: &'a Fixture, first: &'a QuantLayer) -> Vec<RequantizedLinear<'a>> {
    let mut hidden = vec![first.requantized()];
    hidden.extend_from_slice(&fix.quant.hidden_layers()[1..]);
    hidden
}

/// Naive int8 forward: i64 dot products, the wide requantization model, table lookups by index.
fn naive_int8_forward(fix: &Fixture, input: &[f32]) -> Vec<f32> {
    let x: Vec<i8> = input.iter().map(|v| fix.quant.input.quantize(*v)).collect();
    naive_int8_tail(fix, &fix.quant.hidden, x)
}

/// [`naive_int8_forward`] from int8 codes `x` through `layers`, then the output layer.
fn naive_int8_tail(fix: &Fixture, layers: &[QuantLayer], mut x: Vec<i8>) -> Vec<f32> {
    for q in layers {
        let mut y = Vec::new();
        for o in 0..q.out_features {
            let pre = reference::requantize(
                q.naive_accumulator(o, &x) as i32,
                q.multipliers[o],
                q.shifts[o],
                q.output.zero_point,
                -128,
                127,
            );
            let lut = q.lut.as_ref().unwrap();
            y.push(lut.table[(i32::from(pre) + 128) as usize]);
        }
        x = y;
    }
    let q = &fix.quant.output;
    (0..q.out_features)
        .map(|o| q.naive_accumulator(o, &x) as i32 as f32 * fix.quant.output_scales[o])
        .collect()
}

#[test]
fn int8_forward_is_bit_exact_with_naive_model_and_close_to_f32() {
    let fix = fixture(1234);
    let hidden = fix.quant.hidden_layers();
    let net = fix.int8_mlp(&hidden);
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
        h = layer
            .affine64(&h)
            .iter()
            .map(|affine| f64::from(layer.activation.apply(*affine as f32)))
            .collect();
    }
    for (got, want) in out.iter().zip(&h) {
        assert!((f64::from(*got) - want).abs() < 1e-4, "{got} vs {want}");
    }
}

#[test]
fn shape_errors() {
    let fix = fixture(77);
    let hidden = fix.quant.hidden_layers();
    let net = fix.int8_mlp(&hidden);
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
            output_scales: &fix.quant.output_scales[..3],
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
    let first = &fix.quant.hidden[0];
    let mut layer = QuantLayer {
        weights: first.weights.clone(),
        bias: first.bias.clone(),
        multipliers: Vec::new(),
        shifts: Vec::new(),
        weight_scales: first.weight_scales.clone(),
        output: first.output,
        lut: first.lut,
        in_features: first.in_features,
        out_features: first.out_features,
    };
    let fine_scale = fix.quant.input.scale / (1_u32 << FINE_INPUT_BITS) as f32;
    for w in &first.weight_scales {
        let (m, s) = requantization_multiplier(fine_scale, *w, first.output.scale).unwrap();
        layer.multipliers.push(m);
        layer.shifts.push(s);
    }
    layer
}

#[test]
fn two_plane_input_is_bit_exact_with_naive_model_and_more_accurate() {
    let fix = fixture(4321);
    let first = two_plane_first_layer(&fix);
    let hidden = hidden_with(&fix, &first);
    let net = fix.int8_mlp(&hidden);
    // Naive first layer: both planes from their definition, i64 dot products, the wide
    // combination and requantization models, the LUT by index.
    let fine_params = QuantParams {
        scale: fix.quant.input.scale / 256.0,
        zero_point: 0,
    };
    // Returns the codes and, per channel, the real pre-activation of both planes and of the coarse
    // plane alone (what int8 input quantization gives).
    let naive_first = |x: &[f32]| -> (Vec<i8>, Vec<(f64, f64)>) {
        let planes: Vec<(i8, i8)> = x
            .iter()
            .map(|v| {
                let coarse = fix.quant.input.quantize(*v);
                (
                    coarse,
                    fine_params.quantize(v - fix.quant.input.dequantize(coarse)),
                )
            })
            .collect();
        let mut pre_real = Vec::new();
        let codes = (0..first.out_features)
            .map(|o| {
                let row = first.row(o);
                let dot = |plane: fn(&(i8, i8)) -> i8| -> i64 {
                    row.iter()
                        .zip(&planes)
                        .map(|(w, p)| i64::from(*w) * i64::from(plane(p)))
                        .sum()
                };
                let coarse = (i64::from(first.bias[o]) + dot(|p| p.0)) as i32;
                let acc = reference::combine_planes(coarse, dot(|p| p.1) as i32);
                let unit = f64::from(fix.quant.input.scale) * f64::from(first.weight_scales[o]);
                pre_real.push((f64::from(acc) * unit / 256.0, f64::from(coarse) * unit));
                let m = (first.multipliers[o], first.shifts[o]);
                let pre = reference::requantize(acc, m.0, m.1, first.output.zero_point, -128, 127);
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
        let want = naive_int8_tail(&fix, &fix.quant.hidden[1..], codes);
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(g.to_bits(), w.to_bits());
        }
        // First-layer pre-activations against the exact affine map of the quantized weights
        // (so only the input and bias rounding remain).
        for (o, (two, one)) in pre_real.iter().enumerate() {
            let row = first.row(o);
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
    let q = &fix.quant.output;
    let no_hidden = Int8Mlp {
        hidden: &[],
        output: Int8Linear {
            fc: FullyConnected::new(20, 12, &q.weights[..240], &q.bias),
            output_scales: &fix.quant.output_scales,
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
        fix.quant.input,
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
