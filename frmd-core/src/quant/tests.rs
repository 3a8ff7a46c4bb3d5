//! Quantization tests: the fixed-point path against the wide-integer model of [`super::reference`],
//! plus the parameter helpers.

extern crate std;

use super::reference;
use super::*;
use crate::rng::SplitMix64;
use std::vec::Vec;

const Q31_MAX: i32 = i32::MAX;

use reference::{edge_accumulators, EDGE_CLAMPS, EDGE_MULTIPLIERS, EDGE_ZERO_POINTS};

#[test]
fn high_mul_matches_model_and_rounds_half_up() {
    assert_eq!(
        saturating_rounding_doubling_high_mul(i32::MIN, i32::MIN),
        i32::MAX
    );
    assert_eq!(reference::high_mul(i32::MIN, i32::MIN), i32::MAX);
    // Exact ties: (2k + 1) * 2^30 / 2^31 = k + 1/2 rounds up to k + 1; the negative tie
    // -(k + 1/2) rounds up to -k.
    for k in [0_i32, 1, 2, 7, 1000, 1 << 20] {
        let odd = 2 * k + 1;
        assert_eq!(
            saturating_rounding_doubling_high_mul(odd, 1 << 30),
            k + 1,
            "k={k}"
        );
        assert_eq!(
            saturating_rounding_doubling_high_mul(-odd, 1 << 30),
            -k,
            "k={k}"
        );
        assert_eq!(
            saturating_rounding_doubling_high_mul(1 << 30, -odd),
            -k,
            "k={k}"
        );
    }
    let edges = edge_accumulators();
    for &a in &edges {
        for &b in &edges {
            assert_eq!(
                saturating_rounding_doubling_high_mul(a, b),
                reference::high_mul(a, b),
                "a={a} b={b}"
            );
        }
    }
}

#[test]
fn divide_by_pot_matches_model_and_rounds_half_away() {
    for e in 1..=31_i32 {
        let half = 1_i64 << (e - 1);
        for k in [0_i64, 1, 2, 5, 100] {
            // x = (2k + 1) * 2^(e-1): the quotient is k + 1/2.
            let x = (2 * k + 1) * half;
            if x > i64::from(i32::MAX) {
                continue;
            }
            let x = x as i32;
            assert_eq!(rounding_divide_by_pot(x, e), (k + 1) as i32, "x={x} e={e}");
            assert_eq!(
                rounding_divide_by_pot(-x, e),
                -(k + 1) as i32,
                "x=-{x} e={e}"
            );
        }
    }
    assert_eq!(rounding_divide_by_pot(i32::MIN, 31), -1);
    assert_eq!(rounding_divide_by_pot(i32::MAX, 31), 1);
    assert_eq!(rounding_divide_by_pot(i32::MIN, 32), -1);
    assert_eq!(rounding_divide_by_pot(i32::MAX, 32), 0);
    assert_eq!(rounding_divide_by_pot(i32::MIN, 33), 0);
    assert_eq!(rounding_divide_by_pot(-5, -3), -5);
    for e in 0..=31_u32 {
        for &x in &edge_accumulators() {
            assert_eq!(
                rounding_divide_by_pot(x, e as i32),
                reference::divide_pot(x, e),
                "x={x} e={e}"
            );
        }
        for x in -3000..=3000 {
            assert_eq!(
                rounding_divide_by_pot(x, e as i32),
                reference::divide_pot(x, e),
                "x={x} e={e}"
            );
        }
    }
}

#[test]
fn requantization_edges_match_model() {
    let mut checked = 0_u64;
    for &acc in &edge_accumulators() {
        for &m in &EDGE_MULTIPLIERS {
            for shift in SHIFT_MIN..=SHIFT_MAX {
                let want_scaled = reference::scale(acc, m, shift);
                assert_eq!(
                    multiply_by_quantized_multiplier(acc, m, shift),
                    want_scaled,
                    "acc={acc} m={m} shift={shift}"
                );
                for &zp in &EDGE_ZERO_POINTS {
                    for &(lo, hi) in &EDGE_CLAMPS {
                        let got = requantize_to_i8(acc, m, shift, zp, lo, hi);
                        let want = reference::requantize(acc, m, shift, zp, lo, hi);
                        assert_eq!(
                            got, want,
                            "acc={acc} m={m} shift={shift} zp={zp} clamp={lo}..={hi}"
                        );
                        assert_eq!(requantize_valid(acc, m, shift, zp, lo, hi), want);
                        checked += 1;
                    }
                }
            }
        }
    }
    assert!(checked > 100_000);
    // Shifts outside the produced range are still defined (left saturates, right rounds to 0).
    for shift in [-100, -40, -32, 31, 32, 60, i32::MIN, i32::MAX] {
        for &acc in &edge_accumulators() {
            assert_eq!(
                multiply_by_quantized_multiplier(acc, Q31_MAX, shift),
                reference::scale(acc, Q31_MAX, shift),
                "acc={acc} shift={shift}"
            );
        }
    }
}

/// The branch-free path `requantize_to_i8` takes for right shifts equals the general formula for
/// every accumulator edge, multiplier (negative ones too, all but `i32::MIN`) and exponent.
#[test]
fn scale_down_equals_general_path() {
    let multipliers = [
        0,
        1,
        -1,
        Q31_MANTISSA_MIN,
        1_518_500_250,
        -1_518_500_250,
        Q31_MAX,
        i32::MIN + 1,
    ];
    let mut rng = SplitMix64::new(0xD0);
    let random = (0..2000).map(|_| rng.next_u64() as i32);
    for acc in edge_accumulators().into_iter().chain(random) {
        for &m in &multipliers {
            for exponent in 0..=31_u32 {
                assert_eq!(
                    fixed_point::scale_down(acc, m, exponent),
                    multiply_by_quantized_multiplier(acc, m, -(exponent as i32)),
                    "acc={acc} m={m} exponent={exponent}"
                );
            }
        }
    }
}

/// Ties of the final division: choose acc so that acc * M / 2^31 is an exact integer h and h is an
/// odd multiple of 2^(r-1).
#[test]
fn requantization_ties_round_half_away_from_zero() {
    // M = 2^30 makes the high multiply an exact halving for even acc.
    for r in 1..=20_u32 {
        for k in [0_i64, 1, 3, 10] {
            let h = (2 * k + 1) << (r - 1); // h / 2^r = k + 1/2
            let acc = 2 * h;
            for sign in [1_i64, -1] {
                let acc = (sign * acc) as i32;
                let want = sign * (k + 1);
                assert_eq!(
                    multiply_by_quantized_multiplier(acc, Q31_MANTISSA_MIN, -(r as i32)),
                    want as i32,
                    "acc={acc} r={r}"
                );
            }
        }
    }
}

#[test]
fn requantization_one_million_random_inputs_match_model() {
    let start = std::time::Instant::now();
    let mut rng = SplitMix64::new(0x5EED);
    let samples = 1_000_000_u32;
    let mut in_range = 0_u32;
    for _ in 0..samples {
        let bits = rng.next_u64();
        let raw = rng.next_u64();
        // Accumulator: full range, 20-bit, or 12-bit magnitudes.
        let acc = match bits & 3 {
            0 => raw as i32,
            1 | 2 => (raw as i32) >> 12,
            _ => (raw as i32) >> 20,
        };
        let multiplier = match (bits >> 2) & 15 {
            0 => Q31_MANTISSA_MIN,
            1 => Q31_MAX,
            _ => Q31_MANTISSA_MIN + ((raw >> 32) as u32 % (1 << 30)) as i32,
        };
        // Shift: half over the full produced range, half over typical FC values.
        let shift = if (bits >> 6) & 1 == 0 {
            SHIFT_MIN + ((bits >> 8) % 62) as i32
        } else {
            -(((bits >> 8) % 24) as i32)
        };
        let zero_point = match (bits >> 16) & 7 {
            0 => -128,
            1 => 127,
            _ => ((bits >> 24) as u8 as i8) as i32,
        };
        let (lo, hi) = if (bits >> 32) & 3 == 0 {
            let a = (bits >> 40) as u8 as i8;
            let b = (bits >> 48) as u8 as i8;
            (a.min(b), a.max(b))
        } else {
            (-128, 127)
        };
        let got = requantize_to_i8(acc, multiplier, shift, zero_point, lo, hi);
        let want = reference::requantize(acc, multiplier, shift, zero_point, lo, hi);
        assert_eq!(
            requantize_valid(acc, multiplier, shift, zero_point, lo, hi),
            want
        );
        assert_eq!(
            got, want,
            "acc={acc} m={multiplier} shift={shift} zp={zero_point} {lo}..={hi}"
        );
        if got != lo && got != hi {
            in_range += 1;
        }
    }
    let elapsed = start.elapsed();
    std::eprintln!("1M requantization samples vs wide model: {elapsed:?}, {in_range} unclamped");
    // The inputs must exercise the rounding, not only the clamps.
    assert!(in_range > samples / 10, "only {in_range} unclamped results");
}

#[test]
fn double_rounding_stays_within_one_of_exact() {
    let mut rng = SplitMix64::new(99);
    for _ in 0..100_000 {
        let acc = (rng.next_u64() as i32) >> 8;
        let m = Q31_MANTISSA_MIN + (rng.next_u64() % (1 << 30)) as i32;
        let shift = -((rng.next_u64() % 20) as i32);
        let exact = i128::from(acc) * i128::from(m);
        let denominator = 1_i128 << (31 - shift);
        let got = i128::from(multiply_by_quantized_multiplier(acc, m, shift));
        // |got - exact / denominator| <= 1  <=>  |got * d - exact| <= d
        assert!(
            (got * denominator - exact).abs() <= denominator,
            "acc={acc} m={m} shift={shift}"
        );
    }
}

#[test]
fn quantize_multiplier_reproduces_real_within_q31() {
    assert_eq!(quantize_multiplier(1.0), Ok((Q31_MANTISSA_MIN, 1)));
    assert_eq!(quantize_multiplier(0.5), Ok((Q31_MANTISSA_MIN, 0)));
    assert_eq!(quantize_multiplier(0.1), Ok((1_717_986_918, -3)));
    // Rounds up to 2^31 and is renormalized: 1 - 2^-33 -> (2^30, 1).
    assert_eq!(
        quantize_multiplier(1.0 - 2f64.powi(-33)),
        Ok((Q31_MANTISSA_MIN, 1))
    );
    // Largest and smallest representable.
    assert_eq!(
        quantize_multiplier(2f64.powi(-32)),
        Ok((Q31_MANTISSA_MIN, SHIFT_MIN))
    );
    assert_eq!(
        quantize_multiplier(2f64.powi(30) - 0.5),
        Ok((Q31_MAX, SHIFT_MAX))
    );
    // Just below 2^30 the mantissa rounds up to 2^31 and renormalizes to shift 31: overflow.
    assert_eq!(
        quantize_multiplier(2f64.powi(30) - 0.25),
        Err(QuantError::MultiplierOverflow)
    );

    let mut rng = SplitMix64::new(3);
    for _ in 0..100_000 {
        // log-uniform over [2^-32, 2^29.99] (just below 2^30 the mantissa rounds up to overflow)
        let u = (rng.next_u64() >> 11) as f64 / (1_u64 << 53) as f64;
        let real = 2f64.powf(-32.0 + 61.99 * u);
        let (m, s) = quantize_multiplier(real).unwrap();
        assert!(
            (Q31_MANTISSA_MIN..=Q31_MAX).contains(&m),
            "real={real} m={m}"
        );
        assert!((SHIFT_MIN..=SHIFT_MAX).contains(&s), "real={real} s={s}");
        let represented = f64::from(m) * 2f64.powi(s - 31);
        assert!(
            (represented - real).abs() <= real * 2f64.powi(-31),
            "real={real} represented={represented}"
        );
    }
}

#[test]
fn quantize_multiplier_rejects_unrepresentable() {
    assert_eq!(
        quantize_multiplier(0.0),
        Err(QuantError::NonPositiveMultiplier)
    );
    assert_eq!(
        quantize_multiplier(-0.0),
        Err(QuantError::NonPositiveMultiplier)
    );
    assert_eq!(
        quantize_multiplier(-0.25),
        Err(QuantError::NonPositiveMultiplier)
    );
    assert_eq!(
        quantize_multiplier(f64::NAN),
        Err(QuantError::NonFiniteMultiplier)
    );
    assert_eq!(
        quantize_multiplier(f64::INFINITY),
        Err(QuantError::NonFiniteMultiplier)
    );
    assert_eq!(
        quantize_multiplier(f64::NEG_INFINITY),
        Err(QuantError::NonFiniteMultiplier)
    );
    assert_eq!(
        quantize_multiplier(2f64.powi(-33)),
        Err(QuantError::MultiplierUnderflow)
    );
    assert_eq!(
        quantize_multiplier(1e-20),
        Err(QuantError::MultiplierUnderflow)
    );
    assert_eq!(
        quantize_multiplier(f64::MIN_POSITIVE),
        Err(QuantError::MultiplierUnderflow)
    );
    assert_eq!(
        quantize_multiplier(5e-324),
        Err(QuantError::MultiplierUnderflow)
    );
    assert_eq!(
        quantize_multiplier(2f64.powi(30)),
        Err(QuantError::MultiplierOverflow)
    );
    assert_eq!(
        quantize_multiplier(1e30),
        Err(QuantError::MultiplierOverflow)
    );
    assert_eq!(
        quantize_multiplier(f64::MAX),
        Err(QuantError::MultiplierOverflow)
    );
}

#[test]
fn activation_params_from_range() {
    let p = QuantParams::from_range(-1.0, 1.0).unwrap();
    assert_eq!(p.scale, (2.0_f64 / 255.0) as f32);
    assert_eq!(p.zero_point, -1);
    assert_eq!(QuantParams::from_range(0.0, 6.0).unwrap().zero_point, -128);
    assert_eq!(QuantParams::from_range(-6.0, 0.0).unwrap().zero_point, 127);
    // Ranges excluding 0 are widened to include it.
    let p = QuantParams::from_range(2.0, 5.0).unwrap();
    assert_eq!((p.scale, p.zero_point), ((5.0_f64 / 255.0) as f32, -128));
    let p = QuantParams::from_range(-5.0, -2.0).unwrap();
    assert_eq!((p.scale, p.zero_point), ((5.0_f64 / 255.0) as f32, 127));
    assert_eq!(
        QuantParams::from_range(0.0, 0.0),
        Ok(QuantParams {
            scale: 1.0,
            zero_point: 0
        })
    );
    assert_eq!(
        QuantParams::from_range(f32::NAN, 1.0),
        Err(QuantError::NonFiniteRange)
    );
    assert_eq!(
        QuantParams::from_range(0.0, f32::INFINITY),
        Err(QuantError::NonFiniteRange)
    );
    assert_eq!(
        QuantParams::from_range(1.0, -1.0),
        Err(QuantError::InvertedRange)
    );
    // Extreme but finite ranges still give valid parameters.
    assert!(QuantParams::from_range(-f32::MAX, f32::MAX).is_ok());
    assert_eq!(QuantParams::new(0.0, 0), Err(QuantError::InvalidScale));
    assert_eq!(
        QuantParams::new(1.0, 128),
        Err(QuantError::InvalidZeroPoint)
    );

    let mut rng = SplitMix64::new(17);
    for _ in 0..20_000 {
        let a = ((rng.next_u64() >> 11) as f64 / (1_u64 << 53) as f64 * 40.0 - 20.0) as f32;
        let b = ((rng.next_u64() >> 11) as f64 / (1_u64 << 53) as f64 * 40.0 - 20.0) as f32;
        let (min, max) = (a.min(b), a.max(b));
        let p = QuantParams::from_range(min, max).unwrap();
        assert!((-128..=127).contains(&p.zero_point));
        // Zero is exactly representable.
        assert_eq!(p.dequantize(p.zero_point as i8), 0.0);
        assert_eq!(p.quantize(0.0), p.zero_point as i8);
        // Every value of the calibrated range round-trips within one step.
        for t in 0..=16 {
            let x = min + (max - min) * t as f32 / 16.0;
            let back = p.dequantize(p.quantize(x));
            assert!(
                (back - x).abs() <= p.scale * 1.0001,
                "x={x} back={back} {p:?}"
            );
        }
    }
}

#[test]
fn quantize_and_dequantize_values() {
    let unit = QuantParams::new(1.0, 0).unwrap();
    assert_eq!(quantize(2.5, unit), 3);
    assert_eq!(quantize(-2.5, unit), -3);
    assert_eq!(quantize(2.4999, unit), 2);
    assert_eq!(quantize(1000.0, unit), 127);
    assert_eq!(quantize(-1000.0, unit), -128);
    assert_eq!(quantize(f32::INFINITY, unit), 127);
    assert_eq!(quantize(f32::NEG_INFINITY, unit), -128);
    let shifted = QuantParams::new(0.5, 10).unwrap();
    assert_eq!(quantize(f32::NAN, shifted), 10);
    assert_eq!(quantize(1.25, shifted), 13); // 2.5 steps -> 3, + 10
    assert_eq!(dequantize(13, shifted), 1.5);
    assert_eq!(dequantize(-128, shifted), -69.0);
    for q in i8::MIN..=i8::MAX {
        assert_eq!(quantize(dequantize(q, shifted), shifted), q);
    }
    assert_eq!(dequantize_accumulator(-3, 0.25), -0.75);
}

#[test]
fn per_channel_weights() {
    let mut rng = SplitMix64::new(23);
    let (out, inp) = (6_usize, 9_usize);
    let mut weights: Vec<f32> = (0..out * inp)
        .map(|_| ((rng.next_u64() >> 40) as f32 / (1 << 24) as f32 - 0.5) * 3.0)
        .collect();
    for w in &mut weights[2 * inp..3 * inp] {
        *w = 0.0; // an all-zero channel
    }
    let mut q = std::vec![0_i8; out * inp];
    let mut scales = std::vec![0.0_f32; out];
    quantize_weights_per_channel(&weights, inp, &mut q, &mut scales).unwrap();
    for c in 0..out {
        let row = &weights[c * inp..(c + 1) * inp];
        let row_q = &q[c * inp..(c + 1) * inp];
        let max_abs = row.iter().fold(0.0_f32, |m, w| m.max(w.abs()));
        if max_abs == 0.0 {
            assert_eq!(scales[c], 1.0);
            assert!(row_q.iter().all(|v| *v == 0));
            continue;
        }
        assert_eq!(scales[c], max_abs / 127.0);
        assert_eq!(row_q.iter().map(|v| v.unsigned_abs()).max(), Some(127));
        assert!(row_q.iter().all(|v| *v >= WEIGHT_MIN));
        for (w, v) in row.iter().zip(row_q) {
            assert!((f32::from(*v) * scales[c] - w).abs() <= scales[c] * 0.5001);
        }
    }
    let mut short = std::vec![0_i8; out * inp - 1];
    assert_eq!(
        quantize_weights_per_channel(&weights, inp, &mut short, &mut scales),
        Err(QuantError::LengthMismatch)
    );
    assert_eq!(
        quantize_weights_per_channel(&weights, 0, &mut q, &mut scales),
        Err(QuantError::LengthMismatch)
    );
    weights[5] = f32::NAN;
    assert_eq!(
        quantize_weights_per_channel(&weights, inp, &mut q, &mut scales),
        Err(QuantError::NonFiniteValue)
    );
    assert_eq!(quantize_weight(1.0, 2.0), 1); // 0.5 -> 1, half away from zero
    assert_eq!(quantize_weight(-1.0, 2.0), -1);
    assert_eq!(quantize_weight(-1000.0, 1.0), -127);
    assert_eq!(
        symmetric_weight_scale(f32::NAN),
        Err(QuantError::NonFiniteValue)
    );
    assert_eq!(symmetric_weight_scale(1e-45), Err(QuantError::InvalidScale));
}

#[test]
fn bias_and_zero_point_folding() {
    assert_eq!(quantize_bias(1.0, 0.5, 0.25), Ok(8));
    assert_eq!(quantize_bias(0.625, 0.5, 0.5), Ok(3)); // 2.5 -> 3
    assert_eq!(quantize_bias(-0.625, 0.5, 0.5), Ok(-3));
    assert_eq!(
        quantize_bias(1e10, 1e-3, 1e-3),
        Err(QuantError::BiasOverflow)
    );
    assert_eq!(
        quantize_bias(f32::NAN, 1.0, 1.0),
        Err(QuantError::NonFiniteValue)
    );
    assert_eq!(quantize_bias(1.0, 0.0, 1.0), Err(QuantError::InvalidScale));
    assert_eq!(fold_input_zero_point(10, &[1, 2, 3], -5), Ok(40));
    assert_eq!(fold_input_zero_point(10, &[1, 2, 3], 5), Ok(-20));
    assert_eq!(
        fold_input_zero_point(i32::MIN, &[1], 1),
        Err(QuantError::BiasOverflow)
    );
    // The folded bias makes sum(w * x) equal sum(w * (x - zp)) + bias.
    let w = [3_i8, -7, 127, -127];
    let x = [-128_i8, 5, 17, 100];
    let zp = -9;
    let folded = fold_input_zero_point(1234, &w, zp).unwrap();
    let direct: i32 = 1234
        + w.iter()
            .zip(&x)
            .map(|(w, x)| i32::from(*w) * (i32::from(*x) - zp))
            .sum::<i32>();
    let kernel: i32 = folded
        + w.iter()
            .zip(&x)
            .map(|(w, x)| i32::from(*w) * i32::from(*x))
            .sum::<i32>();
    assert_eq!(direct, kernel);
    assert_eq!(
        requantization_multiplier(0.02, 0.003, 0.05),
        quantize_multiplier(f64::from(0.02_f32) * f64::from(0.003_f32) / f64::from(0.05_f32))
    );
    assert_eq!(
        requantization_multiplier(0.02, -1.0, 0.05),
        Err(QuantError::InvalidScale)
    );
}

mod properties {
    use super::super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn requantization_is_monotone_in_the_accumulator(
            a in any::<i32>(),
            b in any::<i32>(),
            multiplier in Q31_MANTISSA_MIN..=i32::MAX,
            shift in SHIFT_MIN..=SHIFT_MAX,
            zero_point in -128_i32..=127,
        ) {
            let (lo, hi) = (a.min(b), a.max(b));
            let q_lo = requantize_to_i8(lo, multiplier, shift, zero_point, -128, 127);
            let q_hi = requantize_to_i8(hi, multiplier, shift, zero_point, -128, 127);
            prop_assert!(q_lo <= q_hi);
        }

        #[test]
        fn high_mul_is_symmetric(a in any::<i32>(), b in any::<i32>()) {
            prop_assert_eq!(
                saturating_rounding_doubling_high_mul(a, b),
                saturating_rounding_doubling_high_mul(b, a)
            );
        }

        #[test]
        fn divide_by_pot_is_odd(x in (i32::MIN + 1)..=i32::MAX, e in 0_i32..=31) {
            prop_assert_eq!(rounding_divide_by_pot(-x, e), -rounding_divide_by_pot(x, e));
        }

        #[test]
        fn quantize_dequantize_round_trip(code in any::<i8>(), scale in 1e-4_f32..10.0, zp in -128_i32..=127) {
            let params = QuantParams::new(scale, zp).unwrap();
            prop_assert_eq!(params.quantize(params.dequantize(code)), code);
        }
    }
}
