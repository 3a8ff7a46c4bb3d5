//! The 16-bit input plane ([`InputPrecision::Int16`]) against a naive model: codes from their
//! definition (f32 division, f64 rounding), i64 dot products, the wide requantization model.

use super::*;
use crate::quant::{wide_scale, wide_zero_point};

/// The fixture's first hidden layer quantized for the 16-bit input: same weights, bias at the
/// fine scale with the fine zero point folded, multipliers for the fine scale, same table.
fn wide_first_layer(fix: &Fixture) -> QuantLayer {
    let first = &fix.quant.hidden[0];
    let fine = QuantParams {
        scale: wide_scale(fix.quant.input),
        zero_point: wide_zero_point(fix.quant.input),
    };
    let mut layer = quantize_layer(
        &fix.float_hidden[0],
        &fix.float_hidden[0].bias,
        fine,
        Some(first.output),
    );
    assert_eq!(layer.weights, first.weights);
    layer.lut = first.lut;
    layer
}

#[test]
fn sixteen_bit_input_is_bit_exact_with_naive_model_and_as_accurate_as_two_planes() {
    let fix = fixture(4321);
    let wide = wide_first_layer(&fix);
    let two = super::two_plane_first_layer(&fix);
    let (wide_hidden, two_hidden) = (hidden_with(&fix, &wide), hidden_with(&fix, &two));
    let (wide_net, two_net) = (fix.int8_mlp(&wide_hidden), fix.int8_mlp(&two_hidden));
    let fine_scale = fix.quant.input.scale / 256.0;
    let zero = i64::from(fix.quant.input.zero_point) * 256 + 128;
    // Codes and, per channel, the real pre-activation of the first layer.
    let naive_first = |x: &[f32]| -> (Vec<i8>, Vec<f64>) {
        let codes: Vec<i64> = x
            .iter()
            .map(|v| (f64::from(v / fine_scale).round() as i64 + zero).clamp(-32768, 32767))
            .collect();
        let mut pre_real = Vec::new();
        let out = (0..wide.out_features)
            .map(|o| {
                let row = wide.row(o);
                let dot: i64 = row.iter().zip(&codes).map(|(w, c)| i64::from(*w) * c).sum();
                let acc = (i64::from(wide.bias[o]) + dot) as i32;
                let unit = f64::from(fine_scale) * f64::from(wide.weight_scales[o]);
                pre_real.push(f64::from(acc) * unit);
                let pre = reference::requantize(
                    acc,
                    wide.multipliers[o],
                    wide.shifts[o],
                    wide.output.zero_point,
                    -128,
                    127,
                );
                wide.lut.as_ref().unwrap().table[(i32::from(pre) + 128) as usize]
            })
            .collect();
        (out, pre_real)
    };
    let mut scratch = Int8Scratch::<WIDTH>::new();
    let mut rng = Rng::new(5);
    let (mut error_wide, mut error_two, mut differ) = (0.0_f64, 0.0_f64, 0);
    for case in 0..300 {
        let mut x = random_input(&mut rng, 20);
        if case % 10 == 0 {
            // Beyond the calibrated range: the codes saturate.
            x.iter_mut().for_each(|v| *v *= 40.0);
        }
        let mut got = [0.0_f32; 12];
        wide_net
            .forward_with_input(InputPrecision::Int16, &x, &mut got, &mut scratch)
            .unwrap();
        let (codes, pre_real) = naive_first(&x);
        let want = naive_int8_tail(&fix, &fix.quant.hidden[1..], codes);
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(g.to_bits(), w.to_bits());
        }
        let mut two_planes = [0.0_f32; 12];
        two_net
            .forward_with_input(InputPrecision::TwoPlane, &x, &mut two_planes, &mut scratch)
            .unwrap();
        differ += usize::from(got != two_planes);
        if case % 10 == 0 {
            continue;
        }
        for (o, pre) in pre_real.iter().enumerate() {
            let row = wide.row(o);
            let scale = f64::from(wide.weight_scales[o]);
            let exact = f64::from(fix.float_hidden[0].bias[o])
                + row
                    .iter()
                    .zip(&x)
                    .map(|(w, v)| f64::from(*w) * scale * f64::from(*v))
                    .sum::<f64>();
            error_wide += (pre - exact).abs();
        }
        // The two-plane accumulator of the same input, from the two-plane test's model.
        let fine = QuantParams {
            scale: fine_scale,
            zero_point: 0,
        };
        for o in 0..two.out_features {
            let row = two.row(o);
            let (mut coarse_dot, mut fine_dot) = (0_i64, 0_i64);
            for (w, v) in row.iter().zip(&x) {
                let c = fix.quant.input.quantize(*v);
                coarse_dot += i64::from(*w) * i64::from(c);
                fine_dot +=
                    i64::from(*w) * i64::from(fine.quantize(v - fix.quant.input.dequantize(c)));
            }
            let acc = reference::combine_planes(
                (i64::from(two.bias[o]) + coarse_dot) as i32,
                fine_dot as i32,
            );
            let unit = f64::from(fix.quant.input.scale) * f64::from(two.weight_scales[o]) / 256.0;
            let scale = f64::from(two.weight_scales[o]);
            let exact = f64::from(fix.float_hidden[0].bias[o])
                + row
                    .iter()
                    .zip(&x)
                    .map(|(w, v)| f64::from(*w) * scale * f64::from(*v))
                    .sum::<f64>();
            error_two += (f64::from(acc) * unit - exact).abs();
        }
    }
    std::eprintln!(
        "first-layer pre-activation abs error sums: 16-bit {error_wide}, two-plane {error_two}"
    );
    // Same grid, bias at the fine scale instead of the coarse one: no less accurate.
    assert!(
        error_wide <= error_two,
        "16-bit {error_wide} vs two-plane {error_two}"
    );
    // The two paths are different computations (bias rounding, saturation), not one in disguise.
    assert!(differ > 0);
    let q = &fix.quant.output;
    let no_hidden = Int8Mlp {
        hidden: &[],
        output: Int8Linear {
            fc: FullyConnected::new(20, 12, &q.weights[..240], &q.bias),
            ..wide_net.output
        },
        ..wide_net
    };
    let mut out = [0.0_f32; 12];
    assert_eq!(
        no_hidden.forward_with_input(InputPrecision::Int16, &[0.0; 20], &mut out, &mut scratch),
        Err(ModelError::TwoPlaneWithoutHiddenLayer)
    );
}
