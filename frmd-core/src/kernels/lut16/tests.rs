//! Tests of the interpolated int16 tables: the lookup against the wide-integer model's slope form
//! (every code, random and extreme tables), against TFLite's int16 arithmetic, and the builder's
//! accuracy for frmd's activations.

extern crate std;

use super::*;
use crate::kernels::activation::{gelu, gelu_sigmoid, gelu_tanh, mish, silu};
use crate::quant::{reference, symmetric_i16_scale};
use crate::rng::SplitMix64;
use std::vec::Vec;

/// Random tables: uniform codes, maximal jumps between -32768 and 32767, monotone ramps, and
/// tables that sit at the int16 ends.
fn tables() -> Vec<Lut16Table> {
    let mut rng = SplitMix64::new(0x1616_7AB1E);
    let mut tables = Vec::new();
    for kind in 0..12 {
        let mut table = [0_i16; LUT16_LEN];
        for (j, t) in table.iter_mut().enumerate() {
            let bits = rng.next_u64();
            *t = match kind % 4 {
                0 => bits as i16,
                1 => {
                    if (j + kind) % 2 == 0 {
                        i16::MIN
                    } else {
                        i16::MAX
                    }
                }
                2 => (128 * (j as i32 - 256)).clamp(-32768, 32767) as i16,
                _ => [i16::MIN, i16::MIN + 1, i16::MAX - 1, i16::MAX][(bits % 4) as usize],
            };
        }
        tables.push(table);
    }
    tables
}

#[test]
fn lookup_matches_the_slope_form_on_every_code() {
    for table in tables() {
        for x in i16::MIN..=i16::MAX {
            let got = lookup(&table, x);
            assert_eq!(Some(got), reference::lookup16(&table, x), "x {x}");
        }
    }
}

/// TFLite's int16 `LUTLookup`: `base + ((slope * offset + 64) >> 7)` with an int16 slope. frmd
/// gives the same value wherever that slope fits in int16 (everywhere for smooth functions).
#[test]
fn lookup_matches_tflite_where_its_slope_fits() {
    let tflite = |table: &Lut16Table, value: i16| -> Option<i16> {
        let index = (256 + (i32::from(value) >> 7)) as usize;
        let offset = i32::from(value & 0x7f);
        let base = i32::from(*table.get(index)?);
        let slope = i16::try_from(i32::from(*table.get(index + 1)?) - base).ok()?;
        let delta = (i32::from(slope) * offset + 64) >> 7;
        Some((base + delta) as i16)
    };
    let mut compared = 0_usize;
    for table in tables() {
        for x in i16::MIN..=i16::MAX {
            if let Some(want) = tflite(&table, x) {
                assert_eq!(lookup(&table, x), want, "x {x}");
                compared += 1;
            }
        }
    }
    assert!(compared > 400_000, "{compared}");
}

#[test]
fn lookup_stays_between_the_segment_knots() {
    for table in tables() {
        for x in i16::MIN..=i16::MAX {
            let i = ((i32::from(x) >> 7) + 256) as usize;
            let (a, b) = (table[i], table[i + 1]);
            let y = lookup(&table, x);
            assert!(a.min(b) <= y && y <= a.max(b));
            if x & 127 == 0 {
                assert_eq!(y, a, "a knot's own code returns the knot");
            }
        }
        let mut data: Vec<i16> = (i16::MIN..=i16::MAX).step_by(7).collect();
        let want: Vec<i16> = data.iter().map(|x| lookup(&table, *x)).collect();
        apply_in_place(&table, &mut data);
        assert_eq!(data, want);
    }
}

type Function = fn(f32) -> f32;

const FUNCTIONS: [(&str, Function, f64); 5] = [
    // (name, function, max |f''| over the reals)
    ("silu", silu, 0.5),
    ("mish", mish, 0.645),
    ("gelu", gelu, 0.798),
    ("gelu_tanh", gelu_tanh, 0.798),
    ("gelu_sigmoid", gelu_sigmoid, 0.851),
];

/// Calibrated pre-activation ranges; the table covers them widened 1.5x (the design's headroom).
const RANGES: [(f32, f32); 5] = [
    (-1.0, 1.0),
    (-8.0, 8.0),
    (-0.5, 12.0),
    (-20.0, 1.0),
    (-60.0, 60.0),
];

/// `(input_scale, output_scale)` of a table for `f` over `range` x 1.5, the output scale from the
/// largest `|f|` on the input codes and the last knot (code 32768), so the table does not clamp.
fn scales(f: Function, (lo, hi): (f32, f32)) -> (f32, f32) {
    let input = symmetric_i16_scale(1.5 * lo.abs().max(hi)).unwrap();
    let largest = (-32768..=32768)
        .map(|q: i32| f(input * q as f32).abs())
        .fold(0.0_f32, f32::max);
    (input, symmetric_i16_scale(largest).unwrap())
}

/// The exact output code of every input code.
fn exact(f: Function, input: f32, output: f32, x: i16) -> i32 {
    crate::quant::round_to_i32(f(input * f32::from(x)) / output).clamp(-32768, 32767)
}

#[test]
fn built_tables_are_within_the_interpolation_bound() {
    for (name, f, curvature) in FUNCTIONS {
        for range in RANGES {
            let (input, output) = scales(f, range);
            let lut = Lut16::build(f, input, output).unwrap();
            // Linear interpolation over knots h = 128 input steps apart, lowered by half the
            // midpoint error: about h^2 max|f''| / 16, in output codes.
            let interpolation = 1024.0 * f64::from(input).powi(2) * curvature / f64::from(output);
            let bound = 1 + interpolation.ceil() as i32;
            let mut worst = 0;
            for x in i16::MIN..=i16::MAX {
                let error = (i32::from(lut.lookup(x)) - exact(f, input, output, x)).abs();
                worst = worst.max(error);
            }
            std::eprintln!(
                "{name} {range:?}: worst error {worst} codes (interpolation term {interpolation:.3}, bound {bound})"
            );
            assert!(worst <= bound, "{name} {range:?}: {worst} > {bound}");
            // int8 tables are within half of 1/255 of the output range; these within a few of
            // 65,535 steps.
            assert!(worst <= 8, "{name} {range:?}: {worst}");
        }
    }
}

#[test]
fn midpoint_correction_does_not_increase_the_error() {
    for (name, f, _) in FUNCTIONS {
        for range in RANGES {
            let (input, output) = scales(f, range);
            let lut = Lut16::build(f, input, output).unwrap();
            let mut plain = [0_i16; LUT16_LEN];
            for (j, t) in plain.iter_mut().enumerate() {
                let code = 128 * (j as i32 - 256);
                let y = f(input * code as f32) / output;
                *t = crate::quant::round_to_i32(y).clamp(-32768, 32767) as i16;
            }
            // The design's first version: the correction from rounded values.
            let mut rounded = plain;
            for (j, t) in rounded.iter_mut().take(LUT16_LEN - 1).enumerate() {
                let code = 128 * (j as i32 - 256) + 64;
                let mid = crate::quant::round_to_i32(f(input * code as f32) / output)
                    .clamp(-32768, 32767);
                let lin = (i32::from(plain[j]) + i32::from(plain[j + 1]) + 1) >> 1;
                let error = lin - mid;
                *t = (i32::from(plain[j]) - (error + error.signum()) / 2).clamp(-32768, 32767)
                    as i16;
            }
            let (mut corrected, mut uncorrected, mut first) = (0_i64, 0_i64, 0_i64);
            let (mut worst, mut worst_plain) = (0, 0);
            for x in i16::MIN..=i16::MAX {
                let want = exact(f, input, output, x);
                let error = (i32::from(lut.lookup(x)) - want).abs();
                let error_plain = (i32::from(lookup(&plain, x)) - want).abs();
                corrected += i64::from(error);
                uncorrected += i64::from(error_plain);
                first += i64::from((i32::from(lookup(&rounded, x)) - want).abs());
                worst = worst.max(error);
                worst_plain = worst_plain.max(error_plain);
            }
            std::eprintln!(
                "{name} {range:?}: total |error| {corrected} (worst {worst}), uncorrected {uncorrected} (worst {worst_plain}), corrected from rounded values {first}"
            );
            assert!(
                corrected <= uncorrected && worst <= worst_plain,
                "{name} {range:?}: total error {corrected} vs {uncorrected} uncorrected"
            );
        }
    }
}

#[test]
fn build_is_deterministic_and_reproduces_linear_functions() {
    let a = Lut16::build(silu, 1e-3, 2e-3).unwrap();
    assert_eq!(a, Lut16::build(silu, 1e-3, 2e-3).unwrap());
    // f(x) = x with equal scales: every code maps to itself, except the last segment, whose
    // right end (code 32768) saturates to 32767.
    let identity = Lut16::build(|v| v, 0.01, 0.01).unwrap();
    for x in i16::MIN..=i16::MAX {
        let y = identity.lookup(x);
        if x < 32_640 {
            assert_eq!(y, x);
        } else {
            assert!((i32::from(y) - i32::from(x)).abs() <= 1, "{x} -> {y}");
        }
    }
    // A function that saturates: the table clamps, the lookup stays inside.
    let steep = Lut16::build(|v| 1e6 * v, 1.0, 1.0).unwrap();
    assert_eq!(steep.lookup(i16::MAX), i16::MAX);
    assert_eq!(steep.lookup(i16::MIN), i16::MIN);
}

#[test]
fn build_rejects_bad_inputs() {
    assert_eq!(Lut16::build(silu, 0.0, 1.0), Err(QuantError::InvalidScale));
    assert_eq!(
        Lut16::build(silu, 1.0, f32::NAN),
        Err(QuantError::InvalidScale)
    );
    assert_eq!(Lut16::build(silu, -1.0, 1.0), Err(QuantError::InvalidScale));
    assert_eq!(
        Lut16::build(|v| v.ln(), 1.0, 1.0),
        Err(QuantError::NonFiniteValue)
    );
}

/// The case proptest found where a tanh table steps one code down: never more than one.
#[test]
fn flat_tanh_table_steps_down_at_most_one_code() {
    let lut = Lut16::build(libm::tanhf, 0.000_250_038_98, 0.000_792_079_1).unwrap();
    let (mut highest, mut deepest) = (i16::MIN, 0);
    for x in i16::MIN..=i16::MAX {
        let y = lut.lookup(x);
        deepest = deepest.max(i32::from(highest) - i32::from(y));
        highest = highest.max(y);
    }
    assert_eq!(deepest, 1);
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn lookup_of_random_tables_equals_the_model(
            seed in any::<u64>(),
            x in any::<i16>(),
        ) {
            let mut rng = SplitMix64::new(seed);
            let table: Lut16Table = core::array::from_fn(|_| rng.next_u64() as i16);
            prop_assert_eq!(Some(lookup(&table, x)), reference::lookup16(&table, x));
        }

        #[test]
        fn built_tables_are_within_the_bound_for_any_scales(
            input in 1e-5_f32..3e-3,
            headroom in 1.0_f32..2.0,
        ) {
            // SiLU with an output scale that covers its values on the codes (x headroom).
            let largest = (-32768..=32768_i32)
                .step_by(64)
                .map(|q| silu(input * q as f32).abs())
                .fold(0.0_f32, f32::max);
            let output = symmetric_i16_scale(headroom * largest).unwrap();
            let lut = Lut16::build(silu, input, output).unwrap();
            let interpolation = 1024.0 * f64::from(input).powi(2) * 0.5 / f64::from(output);
            let bound = 1 + interpolation.ceil() as i32;
            for x in (i16::MIN..=i16::MAX).step_by(5) {
                let error = (i32::from(lut.lookup(x)) - exact(silu, input, output, x)).abs();
                prop_assert!(error <= bound, "x {} error {} bound {}", x, error, bound);
            }
        }

        #[test]
        fn built_tables_are_monotone_for_monotone_functions(
            input in 1e-5_f32..1e-3,
            output in 1e-5_f32..1e-2,
        ) {
            // tanh is monotone: so is every lookup of its table, within one output code, while
            // the knots are fine enough (here at most 0.128 apart; with knots over a unit apart
            // the midpoint correction of two strongly curved neighbouring segments can cross, as
            // TFLite's does). Each knot's correction is rounded on its own, so where tanh is flat
            // in the output codes a knot can sit one code under its left neighbour (input
            // 2.5e-4, output 7.9e-4: 127 such codes).
            let lut = Lut16::build(libm::tanhf, input, output).unwrap();
            let mut highest = i16::MIN;
            for x in (i16::MIN..=i16::MAX).step_by(3) {
                let y = lut.lookup(x);
                prop_assert!(i32::from(y) + 1 >= i32::from(highest), "x {} y {} highest so far {}", x, y, highest);
                highest = highest.max(y);
            }
        }
    }
}
