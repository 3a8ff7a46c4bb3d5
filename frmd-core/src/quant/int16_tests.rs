//! Tests of the 16x8 arithmetic (`quant::int16`) against the wide-integer model
//! ([`super::reference`]) and against CMSIS-NN's formulation.

extern crate std;

use super::reference;
use super::*;
use crate::rng::SplitMix64;
use std::vec::Vec;

/// The multipliers around the Q15 reduction's rounding and cap.
const MULTIPLIERS: [i32; 12] = [
    0,
    1,
    0x7FFF,
    0x8000,
    1 << 30,
    (1 << 30) + 1,
    0x7FFE_FFFF,
    0x7FFF_0000,
    0x7FFF_7FFF,
    0x7FFF_8000,
    i32::MAX - 1,
    i32::MAX,
];

/// Accumulators of the exact domain `|acc| <= 2^47`: 0, +-1, +-2^k +- 1, +-(2^47 - 1), +-2^47,
/// +-2^46 +- n 2^22.
fn edge_accumulators() -> Vec<i64> {
    let mut values = std::vec![
        0_i64,
        1,
        -1,
        (1 << 47) - 1,
        -(1 << 47) + 1,
        1 << 47,
        -(1 << 47)
    ];
    for k in 0..47 {
        let p = 1_i64 << k;
        values.extend([p, p - 1, p + 1, -p, -p + 1, -p - 1]);
    }
    for n in -3..=3_i64 {
        values.extend([(1 << 46) + n * (1 << 22), -(1 << 46) + n * (1 << 22)]);
    }
    values
}

const BOUNDS: [(i16, i16); 5] = [
    (i16::MIN, i16::MAX),
    (0, i16::MAX),
    (-20, 35),
    (5, 5),
    (-32768, -32000),
];

/// Asserts that [`requantize_s64`] equals the wide model on one case; returns whether the result
/// is inside `(lo, hi)` (not clamped).
fn matches_the_wide_model(acc: i64, multiplier: i32, shift: i32, lo: i16, hi: i16) -> bool {
    let got = requantize_s64(acc, multiplier, shift, lo, hi);
    let want = reference::requantize16(i128::from(acc), multiplier, shift, lo, hi);
    assert_eq!(
        got, want,
        "acc {acc} m {multiplier:#x} shift {shift} [{lo}, {hi}]"
    );
    got != lo && got != hi
}

#[test]
fn requantize_s64_edges_match_the_wide_model() {
    let accumulators = edge_accumulators();
    let mut unclamped = 0_usize;
    for shift in SHIFT16_MIN..=SHIFT16_MAX {
        for &multiplier in &MULTIPLIERS {
            for &acc in &accumulators {
                for (lo, hi) in BOUNDS {
                    unclamped +=
                        usize::from(matches_the_wide_model(acc, multiplier, shift, lo, hi));
                }
            }
        }
    }
    assert!(unclamped > 10_000, "{unclamped} unclamped outputs");
}

#[test]
fn requantize_s64_rounds_exact_ties_half_up() {
    // acc * m15 = (2k + 1) 2^(T - 1): the quotient is k + 1/2, rounded up to k + 1; the
    // negative tie -(k + 1/2) rounds up to -k.
    let multiplier = 1 << 16; // m15 = 1
    assert_eq!(reduce_multiplier(multiplier), 1);
    for shift in SHIFT16_MIN..=SHIFT16_MAX {
        let t = 15 - shift;
        for k in [0_i64, 1, 2, 7, 1000, 16_000] {
            let acc = (2 * k + 1) << (t - 1);
            let full = (i16::MIN, i16::MAX);
            assert_eq!(
                requantize_s64(acc, multiplier, shift, full.0, full.1),
                (k + 1) as i16
            );
            assert_eq!(
                requantize_s64(-acc, multiplier, shift, full.0, full.1),
                -k as i16
            );
            // One below / above the tie rounds to the nearer value.
            assert_eq!(
                requantize_s64(acc - 1, multiplier, shift, full.0, full.1),
                k as i16
            );
            assert_eq!(
                requantize_s64(-acc - 1, multiplier, shift, full.0, full.1),
                -(k + 1) as i16
            );
        }
    }
}

#[test]
fn reduce_multiplier_equals_cmsis_definition() {
    // CMSIS-NN REDUCE_MULTIPLIER: ((x < 0x7FFF0000) ? ((x + (1 << 15)) >> 16) : 0x7FFF), for the
    // non-negative mantissas it is applied to.
    let cmsis = |x: i32| -> i32 {
        if x < 0x7FFF_0000 {
            ((i64::from(x) + (1 << 15)) >> 16) as i32
        } else {
            0x7FFF
        }
    };
    for x in (0x7FFE_0000..=i32::MAX).chain(0..=0x3_0000) {
        assert_eq!(reduce_multiplier(x), cmsis(x), "{x:#x}");
        assert_eq!(
            reduce_multiplier(x),
            reference::reduce_multiplier16(x),
            "{x:#x}"
        );
    }
    let mut rng = SplitMix64::new(0x0151);
    for _ in 0..1_000_000 {
        let x = rng.next_u64() as i32;
        assert_eq!(
            reduce_multiplier(x),
            reference::reduce_multiplier16(x),
            "{x:#x}"
        );
        if x >= 0 {
            assert_eq!(reduce_multiplier(x), cmsis(x), "{x:#x}");
        }
    }
    assert_eq!(reduce_multiplier(-1), 0);
    assert_eq!(reduce_multiplier(i32::MIN), 0);
}

/// A random accumulator of the exact domain with a random magnitude.
fn random_accumulator(rng: &mut SplitMix64) -> i64 {
    let bits = rng.next_u64();
    let magnitude = (bits >> 16) & ((1 << 47) - 1);
    let value = (magnitude >> (bits % 48)) as i64;
    if bits & (1 << 8) == 0 {
        value
    } else {
        -value
    }
}

/// A random shift of the int16 requantization's range.
fn random_shift(rng: &mut SplitMix64) -> i32 {
    let span = (SHIFT16_MAX - SHIFT16_MIN + 1) as u64;
    SHIFT16_MIN + (rng.next_u64() % span) as i32
}

#[test]
fn requantize_s64_one_million_random_inputs_match_the_wide_model() {
    let mut rng = SplitMix64::new(0x1616);
    let mut unclamped = 0_usize;
    for case in 0..1_000_000 {
        let acc = random_accumulator(&mut rng);
        let multiplier = match case % 4 {
            // Mantissas as quantize_multiplier makes them.
            0 | 1 => (1 << 30) + (rng.next_u64() % (1 << 30)) as i32,
            2 => MULTIPLIERS[(rng.next_u64() % MULTIPLIERS.len() as u64) as usize],
            _ => rng.next_u64() as i32,
        };
        let shift = random_shift(&mut rng);
        let (lo, hi) = if case % 3 == 0 {
            (i16::MIN, i16::MAX)
        } else {
            let (a, b) = (rng.next_u64() as i16, rng.next_u64() as i16);
            (a.min(b), a.max(b))
        };
        unclamped += usize::from(matches_the_wide_model(acc, multiplier, shift, lo, hi));
    }
    assert!(unclamped > 300_000, "{unclamped} unclamped outputs");
}

/// CMSIS-NN `arm_nn_requantize_s64`: `result = (int32_t)(val * m15 >> (14 - shift));
/// (result + 1) >> 1`. frmd gives the same value wherever that int32 truncation is exact.
#[test]
fn requantize_s64_matches_cmsis_where_its_intermediate_fits() {
    let mut rng = SplitMix64::new(0xC515);
    let mut compared = 0_usize;
    for _ in 0..500_000 {
        let acc = random_accumulator(&mut rng);
        let multiplier = (1 << 30) + (rng.next_u64() % (1 << 30)) as i32;
        let shift = random_shift(&mut rng);
        let m15 = i64::from(reduce_multiplier(multiplier));
        let wide = (acc * m15) >> (14 - shift);
        let Ok(truncated) = i32::try_from(wide) else {
            continue;
        };
        let cmsis = (i64::from(truncated) + 1) >> 1;
        let cmsis = cmsis.clamp(i64::from(i16::MIN), i64::from(i16::MAX)) as i16;
        assert_eq!(
            requantize_s64(acc, multiplier, shift, i16::MIN, i16::MAX),
            cmsis
        );
        compared += 1;
    }
    assert!(compared > 100_000, "{compared}");
}

#[test]
fn requantize_s64_is_total_outside_the_domain() {
    // Any accumulator, multiplier, shift and bound order: defined, never a panic; inverted bounds
    // give the upper one.
    let mut rng = SplitMix64::new(0x707A1);
    for _ in 0..200_000 {
        let acc = rng.next_u64() as i64;
        let multiplier = rng.next_u64() as i32;
        let shift = rng.next_u64() as i32;
        let (lo, hi) = (rng.next_u64() as i16, rng.next_u64() as i16);
        let got = requantize_s64(acc, multiplier, shift, lo, hi);
        if lo <= hi {
            assert!((lo..=hi).contains(&got));
        } else {
            assert_eq!(got, hi);
        }
    }
    for acc in [i64::MIN, i64::MAX, -1, 0] {
        for shift in [i32::MIN, -64, -32, 14, 15, 16, 63, 64, i32::MAX] {
            let _ = requantize_s64(acc, i32::MAX, shift, i16::MIN, i16::MAX);
        }
    }
}

#[test]
fn requantize_s64_is_within_half_a_step_of_the_real_product() {
    // One rounding: |out - acc * M 2^(shift - 31)| <= 1/2 + the Q15 reduction's error.
    let mut rng = SplitMix64::new(0xAB5);
    for _ in 0..200_000 {
        let real = 1e-6 * 1e7_f64.powf((rng.next_u64() >> 11) as f64 / (1_u64 << 53) as f64);
        let Ok((multiplier, shift)) = quantize_multiplier(real) else {
            continue;
        };
        if shift > SHIFT16_MAX {
            continue;
        }
        let acc = random_accumulator(&mut rng) >> 10;
        let exact = acc as f64 * real;
        if exact.abs() > 32_000.0 {
            continue;
        }
        let got = f64::from(requantize_s64(acc, multiplier, shift, i16::MIN, i16::MAX));
        // m15 differs from the real multiplier's mantissa by at most 2^-15 relative.
        let bound = 0.5 + exact.abs() * 2f64.powi(-14) + 1e-9;
        assert!(
            (got - exact).abs() <= bound,
            "{got} vs {exact} (real {real})"
        );
    }
}

#[test]
fn dequantize_wide_matches_the_model_and_the_real_value() {
    let mut rng = SplitMix64::new(0xDE0);
    let scales = [1.0_f32, 3.7e-9, 2.5e-5, 0.013, 0.37, 7.0];
    let mut values = edge_accumulators();
    values.extend((0..100_000).map(|_| random_accumulator(&mut rng)));
    values.extend((0..100_000).map(|_| random_accumulator(&mut rng) >> 24));
    values.extend([
        i64::from(i32::MAX),
        i64::from(i32::MIN),
        -3,
        -(1 << 23),
        (1 << 23) - 1,
    ]);
    let mut worst = 0.0_f64;
    for &acc in &values {
        for scale in scales {
            let got = dequantize_wide(acc, scale);
            assert_eq!(
                got.to_bits(),
                reference::dequantize_wide(acc, scale).to_bits()
            );
            let exact = acc as f64 * f64::from(scale);
            let ulp = f64::from(f32::EPSILON) * exact.abs().max(f64::from(f32::MIN_POSITIVE));
            let error = (f64::from(got) - exact).abs() / ulp;
            worst = worst.max(error);
            assert!(error <= 2.0, "acc {acc} scale {scale}: {got} vs {exact}");
            if acc.unsigned_abs() < 1 << 23 {
                // The int32 path's value, bit for bit.
                assert_eq!(got.to_bits(), (acc as f32 * scale).to_bits(), "acc {acc}");
            }
        }
    }
    std::eprintln!("dequantize_wide: worst error {worst:.3} ulp of f32::EPSILON |exact|");
    // Beyond the exact domain: defined, never a panic.
    for acc in [i64::MIN, i64::MAX, -1, 1 << 60] {
        let _ = dequantize_wide(acc, 0.5);
    }
}

#[test]
fn symmetric_int16_parameters() {
    assert_eq!(symmetric_i16_scale(0.0), Ok(1.0));
    assert_eq!(symmetric_i16_scale(-32767.0), Ok(1.0));
    assert_eq!(
        symmetric_i16_scale(f32::NAN),
        Err(QuantError::NonFiniteRange)
    );
    assert_eq!(symmetric_i16_scale(1e-45), Err(QuantError::InvalidScale));
    let scale = symmetric_i16_scale(6.0).unwrap();
    assert_eq!(scale, (6.0_f64 / 32767.0) as f32);
    assert_eq!(quantize_sym16(6.0, scale), 32767);
    assert_eq!(quantize_sym16(-6.0, scale), -32767);
    assert_eq!(quantize_sym16(100.0, scale), i16::MAX);
    assert_eq!(quantize_sym16(-100.0, scale), i16::MIN);
    assert_eq!(quantize_sym16(f32::NAN, scale), 0);
    assert_eq!(quantize_sym16(f32::INFINITY, scale), i16::MAX);
    // Ties away from zero.
    assert_eq!(quantize_sym16(2.5, 1.0), 3);
    assert_eq!(quantize_sym16(-2.5, 1.0), -3);
    for code in [i16::MIN, -1, 0, 1, 12_345, i16::MAX] {
        assert_eq!(quantize_sym16(dequantize_sym16(code, scale), scale), code);
    }
}

#[test]
fn int64_bias_and_zero_point_folding() {
    assert_eq!(quantize_bias_i64(1.0, 0.5, 0.25), Ok(8));
    assert_eq!(quantize_bias_i64(-1.25, 0.5, 1.0), Ok(-3));
    // Far beyond i32: the 16-bit input plane's fine scale times small weight scales.
    let wide = quantize_bias_i64(2.0, 1e-6, 1e-4).unwrap();
    assert!((wide as f64 / 2e10 - 1.0).abs() < 1e-6, "{wide}");
    assert_eq!(
        quantize_bias_i64(1.0, 1e-10, 1e-5),
        Err(QuantError::BiasOverflow)
    );
    assert_eq!(
        quantize_bias_i64(f32::NAN, 1.0, 1.0),
        Err(QuantError::NonFiniteValue)
    );
    assert_eq!(
        quantize_bias_i64(1.0, 0.0, 1.0),
        Err(QuantError::InvalidScale)
    );
    let limit = BIAS16_MAX as f32;
    assert_eq!(quantize_bias_i64(limit, 1.0, 1.0), Ok(BIAS16_MAX));
    assert_eq!(quantize_bias_i64(-limit, 1.0, 1.0), Ok(-BIAS16_MAX));
    assert_eq!(
        fold_input_zero_point_i64(100, &[1, -2, 3], 4),
        Ok(100 - 4 * 2)
    );
    assert_eq!(
        fold_input_zero_point_i64(BIAS16_MAX, &[1], -1),
        Err(QuantError::BiasOverflow)
    );
    assert_eq!(
        fold_input_zero_point_i64(BIAS16_MAX, &[1], 1),
        Ok(BIAS16_MAX - 1)
    );
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn requantize_s64_is_monotone_in_the_accumulator(
            a in -(1_i64 << 47)..=(1_i64 << 47),
            b in -(1_i64 << 47)..=(1_i64 << 47),
            multiplier in Q31_MANTISSA_MIN..=i32::MAX,
            shift in SHIFT16_MIN..=SHIFT16_MAX,
        ) {
            let (lo, hi) = (a.min(b), a.max(b));
            let q_lo = requantize_s64(lo, multiplier, shift, i16::MIN, i16::MAX);
            let q_hi = requantize_s64(hi, multiplier, shift, i16::MIN, i16::MAX);
            prop_assert!(q_lo <= q_hi);
        }

        #[test]
        fn requantize_s64_equals_the_wide_model(
            acc in -(1_i64 << 47)..=(1_i64 << 47),
            multiplier in any::<i32>(),
            shift in SHIFT16_MIN..=SHIFT16_MAX,
            a in any::<i16>(),
            b in any::<i16>(),
        ) {
            let (lo, hi) = (a.min(b), a.max(b));
            prop_assert_eq!(
                requantize_s64(acc, multiplier, shift, lo, hi),
                reference::requantize16(i128::from(acc), multiplier, shift, lo, hi)
            );
        }

        #[test]
        fn requantize_s64_is_odd_up_to_the_tie_direction(
            acc in -(1_i64 << 47)..=(1_i64 << 47),
            multiplier in Q31_MANTISSA_MIN..=i32::MAX,
            shift in SHIFT16_MIN..=SHIFT16_MAX,
        ) {
            let full = (i16::MIN + 1, i16::MAX);
            let plus = i32::from(requantize_s64(acc, multiplier, shift, full.0, full.1));
            let minus = i32::from(requantize_s64(-acc, multiplier, shift, full.0, full.1));
            // Round half up: r(-x) = -r(x), or -r(x) + 1 at an exact tie.
            prop_assert!(plus + minus == 0 || plus + minus == 1);
        }

        #[test]
        fn sym16_round_trip(code in any::<i16>(), scale in 1e-6_f32..10.0) {
            prop_assert_eq!(quantize_sym16(dequantize_sym16(code, scale), scale), code);
        }
    }
}
