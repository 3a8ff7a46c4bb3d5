//! Tests of the fully connected kernels against the naive wide-integer model.
extern crate std;
use super::*;
use crate::quant::{quantize_multiplier, reference};
use crate::rng::SplitMix64;
use std::{vec, vec::Vec};

struct Case {
    in_features: usize,
    out_features: usize,
    weights: Vec<i8>,
    bias: Vec<i32>,
    multipliers: Vec<i32>,
    shifts: Vec<i32>,
    zero_point: i32,
    clamp: (i8, i8),
    input: Vec<i8>,
}

fn random_case(rng: &mut SplitMix64) -> Case {
    let in_features = 1 + (rng.next_u64() % 97) as usize;
    let out_features = 1 + (rng.next_u64() % 23) as usize;
    let weights = (0..in_features * out_features)
        .map(|_| (rng.next_u64() as u8 as i8).max(-127))
        .collect();
    let bias = (0..out_features)
        .map(|_| (rng.next_u64() as i32) >> 16)
        .collect();
    let mut multipliers = Vec::new();
    let mut shifts = Vec::new();
    for _ in 0..out_features {
        // Real multipliers between 1e-5 and 5e-3, typical of FC layers.
        let u = (rng.next_u64() >> 11) as f64 / (1_u64 << 53) as f64;
        let (m, s) = quantize_multiplier(1e-5 * 500f64.powf(u)).unwrap();
        multipliers.push(m);
        shifts.push(s);
    }
    let zero_point = (rng.next_u64() as u8 as i8) as i32;
    let clamp = if rng.next_u64().is_multiple_of(3) {
        (zero_point as i8, 127) // ReLU
    } else {
        (-128, 127)
    };
    let input = (0..in_features)
        .map(|_| rng.next_u64() as u8 as i8)
        .collect();
    Case {
        in_features,
        out_features,
        weights,
        bias,
        multipliers,
        shifts,
        zero_point,
        clamp,
        input,
    }
}

fn naive_accumulators(case: &Case) -> Vec<i64> {
    (0..case.out_features)
        .map(|o| {
            let row = &case.weights[o * case.in_features..(o + 1) * case.in_features];
            let dot: i64 = row
                .iter()
                .zip(&case.input)
                .map(|(w, x)| i64::from(*w) * i64::from(*x))
                .sum();
            i64::from(case.bias[o]) + dot
        })
        .collect()
}

#[test]
fn matches_naive_wide_reference_on_random_shapes() {
    let mut rng = SplitMix64::new(0xFC);
    let mut unclamped = 0_usize;
    let mut total = 0_usize;
    for _ in 0..400 {
        let case = random_case(&mut rng);
        let layer = FullyConnected::new(
            case.in_features,
            case.out_features,
            &case.weights,
            &case.bias,
        );
        let requant = FcRequant {
            multipliers: &case.multipliers,
            shifts: &case.shifts,
            output_zero_point: case.zero_point,
            activation_min: case.clamp.0,
            activation_max: case.clamp.1,
        };
        let mut acc = vec![0_i32; case.out_features];
        layer.forward_accumulators(&case.input, &mut acc).unwrap();
        let mut dots = Vec::new();
        layer
            .for_each_dot(&case.input, |dot| dots.push(dot))
            .unwrap();
        let without_bias: Vec<i32> = acc
            .iter()
            .zip(&case.bias)
            .map(|(a, b)| a.wrapping_sub(*b))
            .collect();
        assert_eq!(dots, without_bias);
        let mut out = vec![0_i8; case.out_features];
        layer.forward(&requant, &case.input, &mut out).unwrap();
        for (o, wide) in naive_accumulators(&case).into_iter().enumerate() {
            let wide_i32 = i32::try_from(wide).expect("test accumulators fit i32");
            assert_eq!(acc[o], wide_i32);
            let want = reference::requantize(
                wide_i32,
                case.multipliers[o],
                case.shifts[o],
                case.zero_point,
                case.clamp.0,
                case.clamp.1,
            );
            assert_eq!(out[o], want, "channel {o}");
            total += 1;
            if want != case.clamp.0 && want != case.clamp.1 {
                unclamped += 1;
            }
        }
    }
    assert!(
        unclamped * 4 > total,
        "{unclamped} of {total} outputs unclamped"
    );
}

#[test]
fn length_and_parameter_errors() {
    let weights = [1_i8; 6];
    let bias = [0_i32; 2];
    let layer = FullyConnected::new(3, 2, &weights, &bias);
    let m = [1 << 30; 2];
    let s = [-3; 2];
    let good = FcRequant {
        multipliers: &m,
        shifts: &s,
        output_zero_point: 0,
        activation_min: -128,
        activation_max: 127,
    };
    let mut out = [0_i8; 2];
    let mut acc = [0_i32; 2];
    assert!(layer.forward(&good, &[1, 2, 3], &mut out).is_ok());
    assert_eq!(
        layer.forward(&good, &[1, 2], &mut out),
        Err(KernelError::InputLength)
    );
    assert_eq!(
        layer.forward(&good, &[1, 2, 3], &mut out[..1]),
        Err(KernelError::OutputLength)
    );
    assert_eq!(
        layer.forward_accumulators(&[1, 2, 3], &mut acc[..1]),
        Err(KernelError::OutputLength)
    );
    assert_eq!(
        layer.forward_accumulators(&[1, 2, 3, 4], &mut acc),
        Err(KernelError::InputLength)
    );
    let bad_weights = FullyConnected::new(3, 2, &weights[..5], &bias);
    assert_eq!(
        bad_weights.forward_accumulators(&[1, 2, 3], &mut acc),
        Err(KernelError::WeightsLength)
    );
    let zero_in = FullyConnected::new(0, 2, &[], &bias);
    assert_eq!(
        zero_in.forward_accumulators(&[], &mut acc),
        Err(KernelError::WeightsLength)
    );
    let overflow = FullyConnected::new(usize::MAX, 2, &weights, &bias);
    assert_eq!(overflow.validate(), Err(KernelError::WeightsLength));
    let bad_bias = FullyConnected::new(3, 2, &weights, &bias[..1]);
    assert_eq!(
        bad_bias.forward_accumulators(&[1, 2, 3], &mut acc),
        Err(KernelError::BiasLength)
    );
    let (shift, neg) = ([-3, 31], [1 << 30, -1]);
    for (requant, error) in [
        (
            FcRequant {
                multipliers: &m[..1],
                ..good
            },
            KernelError::RequantLength,
        ),
        (
            FcRequant {
                output_zero_point: 128,
                ..good
            },
            KernelError::ZeroPoint,
        ),
        (
            FcRequant {
                activation_min: 5,
                activation_max: 4,
                ..good
            },
            KernelError::ActivationRange,
        ),
        (
            FcRequant {
                shifts: &shift,
                ..good
            },
            KernelError::Multiplier,
        ),
        (
            FcRequant {
                multipliers: &neg,
                ..good
            },
            KernelError::Multiplier,
        ),
    ] {
        assert_eq!(layer.forward(&requant, &[1, 2, 3], &mut out), Err(error));
    }
}

#[test]
fn dequantizes_accumulators_per_channel() {
    let mut out = [0.0_f32; 3];
    dequantize_accumulators(&[4, -8, 0], &[0.5, 0.25, 3.0], &mut out).unwrap();
    assert_eq!(out, [2.0, -2.0, 0.0]);
    assert_eq!(
        dequantize_accumulators(&[1, 2], &[1.0], &mut out[..2]),
        Err(KernelError::ScaleLength)
    );
    assert_eq!(
        dequantize_accumulators(&[1, 2], &[1.0, 1.0], &mut out),
        Err(KernelError::OutputLength)
    );
}
