//! The int16-activation (16x8) fully connected kernels against the wide-integer model
//! (`quant::reference`: chunk residues by `rem_euclid`, i128 requantization, the slope-form
//! table lookup), on random shapes that reach every loop remainder (widths mod 4, 8, 16, 32, the
//! DSP loop's steps mod 4, the 256-column pair buffer, the 512-column chunks), every saturation
//! case (weights at +-127 and -128, inputs at -32768 / 32767, biases up to 2^46, outputs at every
//! clamp), and every host path (portable, AVX2) against each other. The Cortex-M DSP kernels meet
//! the same cases through the `kernels` firmware image's digest (frmd-core/tests/cortex_m_qemu.rs).

extern crate std;

use super::*;
use crate::kernels::lut16::{self, Lut16Table};
use crate::quant::{quantize_multiplier, reference, BIAS16_MAX, CHUNK16, SHIFT16_MAX};
use crate::rng::SplitMix64;
use std::{vec, vec::Vec};

/// Widths that sit on and around every boundary of the kernels, then random ones.
fn widths(rng: &mut SplitMix64) -> Vec<usize> {
    let mut widths: Vec<usize> = (1..=40).collect();
    widths.extend([
        47, 63, 64, 65, 95, 127, 128, 129, 200, 255, 256, 257, 260, 300, 384, 511, 512, 513, 516,
        520, 767, 768, 1023, 1024, 1025, 1032, 1100, 1536, 1537, 1792,
    ]);
    widths.extend((0..60).map(|_| 1 + (rng.next_u64() % 1100) as usize));
    widths
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Weights {
    /// Uniform in [-127, 127].
    Random,
    /// Only -127 and 127 (the largest exact chunk sums).
    Extreme,
    /// Uniform in [-128, 127]: chunk sums may wrap; every kernel gives the same residues.
    WithMinus128,
}

struct Case {
    width: usize,
    rows: usize,
    weights: Vec<i8>,
    bias: Vec<i64>,
    multipliers: Vec<i32>,
    shifts: Vec<i32>,
    clamp: (i16, i16),
    input: Vec<i16>,
    bytes: Vec<i8>,
    table: Option<Lut16Table>,
    kind: Weights,
}

fn random_case(rng: &mut SplitMix64, width: usize, index: usize) -> Case {
    let rows = 1 + (rng.next_u64() % 23) as usize;
    let kind = match index % 5 {
        0 => Weights::Extreme,
        1 => Weights::WithMinus128,
        _ => Weights::Random,
    };
    let weights: Vec<i8> = (0..rows * width)
        .map(|_| {
            let bits = rng.next_u64();
            match kind {
                Weights::Extreme if bits.is_multiple_of(2) => -127,
                Weights::Extreme => 127,
                Weights::WithMinus128 => (bits >> 8) as i8,
                Weights::Random => ((bits >> 8) as i8).max(-127),
            }
        })
        .collect();
    let input: Vec<i16> = (0..width)
        .map(|_| {
            let bits = rng.next_u64();
            match (index % 3, bits % 3) {
                (0, 0) => i16::MIN,
                (0, 1) => i16::MAX,
                (1, _) => (bits >> 16) as i16 >> (bits % 12),
                _ => (bits >> 16) as i16,
            }
        })
        .collect();
    let bytes: Vec<i8> = input.iter().map(|x| (*x >> 8) as i8).collect();
    // The accumulators' typical spread (random weights and inputs).
    let typical = (width as f64).sqrt() * 127.0 * 16384.0 + 1.0;
    let bias: Vec<i64> = (0..rows)
        .map(|r| {
            let bits = rng.next_u64();
            match (index + r) % 9 {
                0 => BIAS16_MAX,
                1 => -BIAS16_MAX,
                2 => 0,
                3 => ((bits >> 17) as i64 - (1 << 46)) >> (bits % 40),
                _ => (((bits >> 11) as f64 / (1_u64 << 53) as f64 * 4.0 - 2.0) * typical) as i64,
            }
        })
        .collect();
    // Output scales around the accumulators' spread, so that outputs cover the int16 range and
    // a share saturates: real multiplier ~ 32767 / (typical |acc|) x [1/8, 8].
    let (mut multipliers, mut shifts) = (Vec::new(), Vec::new());
    for _ in 0..rows {
        let u = (rng.next_u64() >> 11) as f64 / (1_u64 << 53) as f64;
        let real = 32767.0 / typical * 64_f64.powf(u) / 8.0;
        let (m, s) = quantize_multiplier(real).unwrap();
        assert!(s <= SHIFT16_MAX);
        multipliers.push(m);
        shifts.push(s);
    }
    let clamp = match index % 6 {
        0 => (0, i16::MAX),
        1 => (-1000, 5000),
        2 => (7, 7),
        _ => (i16::MIN, i16::MAX),
    };
    let table = (index % 4 < 2).then(|| {
        let mut table = [0_i16; lut16::LUT16_LEN];
        for t in table.iter_mut() {
            *t = rng.next_u64() as i16;
        }
        table
    });
    Case {
        width,
        rows,
        weights,
        bias,
        multipliers,
        shifts,
        clamp,
        input,
        bytes,
        table,
        kind,
    }
}

impl Case {
    fn layer(&self) -> FullyConnected<'_, i64> {
        FullyConnected::new(self.width, self.rows, &self.weights, &self.bias)
    }

    fn requant(&self) -> FcRequant<'_, i16> {
        FcRequant {
            multipliers: &self.multipliers,
            shifts: &self.shifts,
            output_zero_point: 0,
            activation_min: self.clamp.0,
            activation_max: self.clamp.1,
        }
    }

    /// The wide model's accumulators for `input`.
    fn model_accumulators<T: Copy + Into<i128>>(&self, input: &[T]) -> Vec<i64> {
        self.weights
            .chunks_exact(self.width)
            .zip(&self.bias)
            .map(|(row, b)| {
                let acc = reference::accumulate_chunked(*b, row, input, CHUNK16);
                i64::try_from(acc).expect("accumulators of valid biases fit i64")
            })
            .collect()
    }

    /// The wide model's outputs for given accumulators.
    fn model_outputs(&self, acc: &[i64]) -> Vec<i16> {
        acc.iter()
            .zip(self.multipliers.iter().zip(&self.shifts))
            .map(|(a, (m, s))| {
                let q = reference::requantize16(i128::from(*a), *m, *s, self.clamp.0, self.clamp.1);
                match &self.table {
                    Some(table) => reference::lookup16(table, q).unwrap(),
                    None => q,
                }
            })
            .collect()
    }
}

/// Every path's accumulators and outputs for one input; returns the outputs.
fn check_paths(case: &Case, input: LayerInput<'_>, want_acc: &[i64]) -> Vec<i16> {
    let layer = case.layer();
    let requant = case.requant();
    let table = case.table.as_ref();
    let rows = case.rows;
    let want = case.model_outputs(want_acc);
    let what = || std::format!("width {} rows {} {:?}", case.width, rows, case.kind);

    // Portable (on Cortex-M: the DSP kernels; here the portable loop).
    let mut acc = vec![0_i64; rows];
    layer.copy_sums(input, &mut acc);
    assert_eq!(acc, want_acc, "portable accumulators, {}", what());
    let mut out = vec![0_i16; rows];
    layer.requantize_activated(&requant, table, input, &mut out);
    assert_eq!(out, want, "portable outputs, {}", what());

    // The public entry points (AVX2 where the CPU has it).
    let mut acc = vec![0_i64; rows];
    layer.accumulate(input, &mut acc).unwrap();
    assert_eq!(acc, want_acc, "accumulate, {}", what());
    let mut out = vec![0_i16; rows];
    layer
        .forward_activated(&requant, table, input, &mut out)
        .unwrap();
    assert_eq!(out, want, "forward_activated, {}", what());

    #[cfg(target_arch = "x86_64")]
    if let Some(avx2) = crate::kernels::x86::Avx2::get() {
        let mut acc = vec![0_i64; rows];
        layer.accumulate_avx2(avx2, input, &mut acc);
        assert_eq!(acc, want_acc, "AVX2 accumulators, {}", what());
        let mut out = vec![0_i16; rows];
        layer.forward_avx2_wide(avx2, &requant, table, input, &mut out);
        assert_eq!(out, want, "AVX2 outputs, {}", what());
    }
    want
}

#[test]
fn int16_layers_match_the_wide_model_on_random_shapes() {
    #[cfg(target_arch = "x86_64")]
    if crate::kernels::x86::Avx2::get().is_none() {
        std::eprintln!("no AVX2 on this CPU: only the portable int16 kernels are exercised");
    }
    let mut rng = SplitMix64::new(0x1608);
    let (mut total, mut unclamped, mut saturated) = (0_usize, 0_usize, 0_usize);
    let mut wrapped = 0_usize;
    for (index, width) in widths(&mut rng).into_iter().enumerate() {
        let case = random_case(&mut rng, width, index);
        // Residue semantics: with -128 weights some chunk sums wrap.
        let exact: Vec<i128> = case
            .weights
            .chunks_exact(width)
            .zip(&case.bias)
            .map(|(row, b)| reference::accumulate_chunked(*b, row, &case.input, usize::MAX))
            .collect();
        let want_acc = case.model_accumulators(&case.input);
        wrapped += exact
            .iter()
            .zip(&want_acc)
            .filter(|(e, w)| **e != i128::from(**w))
            .count();
        if case.kind != Weights::WithMinus128 {
            let exact: Vec<i64> = exact.iter().map(|e| *e as i64).collect();
            assert_eq!(want_acc, exact, "valid weights accumulate exactly");
            assert_eq!(case.layer().validate_exact(), Ok(()));
        } else if case.weights.contains(&-128) {
            assert_eq!(case.layer().validate_exact(), Err(KernelError::WeightRange));
        }
        let out = check_paths(&case, LayerInput::Int16(&case.input), &want_acc);
        // int8 codes into the int64 kernel (an int8 first-layer input of an int16 network).
        let want_bytes = case.model_accumulators(&case.bytes);
        check_paths(&case, LayerInput::Int8(&case.bytes), &want_bytes);
        // Misaligned int16 input (the DSP kernel's word-aligned loads fall back).
        let mut shifted = vec![0_i16; width + 1];
        shifted[1..].copy_from_slice(&case.input);
        check_paths(&case, LayerInput::Int16(&shifted[1..]), &want_acc);

        total += out.len();
        if case.table.is_none() {
            unclamped += out
                .iter()
                .filter(|v| **v != case.clamp.0 && **v != case.clamp.1)
                .count();
            saturated += out
                .iter()
                .filter(|v| **v == i16::MIN || **v == i16::MAX)
                .count();
        }
    }
    std::eprintln!(
        "{total} outputs, {unclamped} unclamped / {saturated} saturated (untabled), {wrapped} wrapped accumulators"
    );
    assert!(unclamped > 150, "{unclamped} unclamped outputs");
    assert!(saturated > 20, "{saturated} saturated outputs");
    std::eprintln!("{wrapped} random accumulators wrapped a chunk sum");
}

/// Weights of -128 times inputs of -32768 over a whole chunk: the chunk's sum is exactly 2^31,
/// which wraps to -2^31 in every kernel's int32 partial sum, and every path (and the model's
/// residue definition) gives the same accumulator, not the exact one.
#[test]
fn chunk_sums_that_wrap_do_so_identically_on_every_path() {
    for width in [512_usize, 513, 1024, 1100, 1536] {
        let rows = 3;
        let weights = vec![-128_i8; rows * width];
        let input = vec![i16::MIN; width];
        let bias = vec![5_i64, -BIAS16_MAX, BIAS16_MAX];
        let full_chunks = (width / CHUNK16) as i64;
        let rest = (width % CHUNK16) as i64;
        let want: Vec<i64> = bias
            .iter()
            .map(|b| b + full_chunks * i64::from(i32::MIN) + rest * (1 << 22))
            .collect();
        let exact: Vec<i64> = bias.iter().map(|b| b + width as i64 * (1 << 22)).collect();
        assert_ne!(want, exact);
        let case = Case {
            width,
            rows,
            weights,
            bias,
            multipliers: vec![1 << 30; rows],
            shifts: vec![-20; rows],
            clamp: (i16::MIN, i16::MAX),
            input,
            bytes: vec![i8::MIN; width],
            table: None,
            kind: Weights::WithMinus128,
        };
        assert_eq!(case.model_accumulators(&case.input), want);
        check_paths(&case, LayerInput::Int16(&case.input), &want);
    }
}

/// Rows that start off word boundaries (`in_features` not a multiple of 4, or a weight slice
/// that starts inside a word) take the portable rows on DSP cores; on every target they give the
/// same bits.
#[test]
fn int16_layers_on_unaligned_weights_match_the_model() {
    let mut rng = SplitMix64::new(0xA116);
    for (index, width) in [8_usize, 12, 257, 512, 520, 1030].into_iter().enumerate() {
        let case = random_case(&mut rng, width, index);
        let want_acc = case.model_accumulators(&case.input);
        let want = case.model_outputs(&want_acc);
        for offset in 1..4 {
            let mut storage = vec![0_i8; case.weights.len() + offset];
            storage[offset..].copy_from_slice(&case.weights);
            let layer = FullyConnected::new(width, case.rows, &storage[offset..], &case.bias);
            let mut out = vec![0_i16; case.rows];
            layer
                .forward_activated(
                    &case.requant(),
                    case.table.as_ref(),
                    LayerInput::Int16(&case.input),
                    &mut out,
                )
                .unwrap();
            assert_eq!(out, want, "width {width} offset {offset}");
            let mut acc = vec![0_i64; case.rows];
            layer.copy_sums(LayerInput::Int16(&case.input), &mut acc);
            assert_eq!(acc, want_acc);
        }
    }
}

/// The int8 network's first layer on the 16-bit input plane (int32 accumulators, int8 outputs):
/// the new AVX2 int16-input kernel, the portable loop and the wide model agree.
#[test]
fn int8_layers_with_int16_inputs_match_on_every_path() {
    let mut rng = SplitMix64::new(0x0816);
    for width in widths(&mut rng).into_iter().filter(|w| *w <= 600) {
        let rows = 1 + (rng.next_u64() % 19) as usize;
        let weights: Vec<i8> = (0..rows * width)
            .map(|_| ((rng.next_u64() >> 8) as i8).max(-127))
            .collect();
        let input: Vec<i16> = (0..width).map(|_| (rng.next_u64() >> 40) as i16).collect();
        let bias: Vec<i32> = (0..rows).map(|_| (rng.next_u64() as i32) >> 8).collect();
        let mut multipliers = Vec::new();
        let mut shifts = Vec::new();
        for _ in 0..rows {
            let u = (rng.next_u64() >> 11) as f64 / (1_u64 << 53) as f64;
            let (m, s) = quantize_multiplier(1e-7 * 1000f64.powf(u)).unwrap();
            multipliers.push(m);
            shifts.push(s);
        }
        let zero_point = (rng.next_u64() % 256) as i32 - 128;
        let requant = FcRequant {
            multipliers: &multipliers,
            shifts: &shifts,
            output_zero_point: zero_point,
            activation_min: -128,
            activation_max: 127,
        };
        let layer = FullyConnected::new(width, rows, &weights, &bias);
        let wide: Vec<i32> = weights
            .chunks_exact(width)
            .zip(&bias)
            .map(|(row, b)| {
                let dot: i64 = row
                    .iter()
                    .zip(&input)
                    .map(|(w, x)| i64::from(*w) * i64::from(*x))
                    .sum();
                (i64::from(*b) + dot) as i32
            })
            .collect();
        let want: Vec<i8> = wide
            .iter()
            .enumerate()
            .map(|(o, acc)| {
                reference::requantize(*acc, multipliers[o], shifts[o], zero_point, -128, 127)
            })
            .collect();
        let mut out = vec![0_i8; rows];
        layer.requantize_activated(&requant, None, LayerInput::Int16(&input), &mut out);
        assert_eq!(out, want, "portable, width {width}");
        let mut out = vec![0_i8; rows];
        layer
            .forward_activated(&requant, None, LayerInput::Int16(&input), &mut out)
            .unwrap();
        assert_eq!(out, want, "forward_activated, width {width}");
        let mut acc = vec![0_i32; rows];
        layer
            .accumulate(LayerInput::Int16(&input), &mut acc)
            .unwrap();
        assert_eq!(acc, wide, "accumulate, width {width}");
        // int8 inputs: the generic accumulate equals forward_accumulators.
        let bytes: Vec<i8> = input.iter().map(|x| *x as i8).collect();
        let (mut generic, mut int8) = (vec![0_i32; rows], vec![0_i32; rows]);
        layer
            .accumulate(LayerInput::Int8(&bytes), &mut generic)
            .unwrap();
        layer.forward_accumulators(&bytes, &mut int8).unwrap();
        assert_eq!(generic, int8, "width {width}");
    }
}

#[test]
fn int16_parameters_are_validated() {
    let weights = [1_i8, -127, 3, 4, 5, 6];
    let bias = [0_i64, BIAS16_MAX];
    let layer = FullyConnected::new(3, 2, &weights, &bias);
    assert_eq!(layer.validate_exact(), Ok(()));
    let m = [1 << 30; 2];
    let s = [-3, SHIFT16_MAX];
    let good = FcRequant {
        multipliers: &m,
        shifts: &s,
        output_zero_point: 0,
        activation_min: i16::MIN,
        activation_max: i16::MAX,
    };
    let mut out = [0_i16; 2];
    let input = LayerInput::Int16(&[1, 2, 3]);
    assert!(layer
        .forward_activated(&good, None, input, &mut out)
        .is_ok());
    let zp = FcRequant {
        output_zero_point: 1,
        ..good
    };
    assert_eq!(
        layer.forward_activated(&zp, None, input, &mut out),
        Err(KernelError::ZeroPoint)
    );
    let wide_shift = [-3, SHIFT16_MAX + 1];
    let shift = FcRequant {
        shifts: &wide_shift,
        ..good
    };
    assert_eq!(
        layer.forward_activated(&shift, None, input, &mut out),
        Err(KernelError::Multiplier)
    );
    let low_shift = [-32, 0];
    let shift = FcRequant {
        shifts: &low_shift,
        ..good
    };
    assert_eq!(shift.validate(2), Err(KernelError::Multiplier));
    let negative = [1 << 30, -1];
    let multiplier = FcRequant {
        multipliers: &negative,
        ..good
    };
    assert_eq!(multiplier.validate(2), Err(KernelError::Multiplier));
    let range = FcRequant {
        activation_min: 5,
        activation_max: 4,
        ..good
    };
    assert_eq!(range.validate(2), Err(KernelError::ActivationRange));
    assert_eq!(
        layer.forward_activated(&good, None, LayerInput::Int16(&[1, 2]), &mut out),
        Err(KernelError::InputLength)
    );
    assert_eq!(
        layer.forward_activated(&good, None, input, &mut out[..1]),
        Err(KernelError::OutputLength)
    );
    let mut acc = [0_i64; 2];
    assert_eq!(
        layer.accumulate(input, &mut acc[..1]),
        Err(KernelError::OutputLength)
    );
    // The int8 zero point rule is unchanged.
    let int8 = FcRequant::<i8> {
        multipliers: &m,
        shifts: &s,
        output_zero_point: 127,
        activation_min: -128,
        activation_max: 127,
    };
    assert_eq!(int8.validate(2), Ok(()));

    let minus128 = [1_i8, -128, 3, 4, 5, 6];
    assert_eq!(
        FullyConnected::new(3, 2, &minus128, &bias).validate_exact(),
        Err(KernelError::WeightRange)
    );
    let big = [0_i64, BIAS16_MAX + 1];
    assert_eq!(
        FullyConnected::new(3, 2, &weights, &big).validate_exact(),
        Err(KernelError::BiasRange)
    );
    let int32_bias = [i32::MAX, i32::MIN];
    assert_eq!(
        FullyConnected::new(3, 2, &minus128, &int32_bias).validate_exact(),
        Ok(()),
        "int32 accumulators wrap by definition: nothing to check"
    );
}

#[test]
fn int64_accumulators_dequantize_per_channel() {
    let mut out = [0.0_f32; 3];
    dequantize_accumulators(&[4_i64, -8, 1 << 40], &[0.5, 0.25, 2.0], &mut out).unwrap();
    assert_eq!(out, [2.0, -2.0, 2.0 * (1_u64 << 40) as f32]);
    assert_eq!(
        dequantize_accumulators(&[1_i64, 2], &[1.0], &mut out[..2]),
        Err(KernelError::ScaleLength)
    );
}

/// Garbage parameters (unvalidated, through the crate-private entry) never panic and every path
/// still agrees.
#[test]
fn unvalidated_int16_parameters_agree_across_paths() {
    let mut rng = SplitMix64::new(0xBAD0_0016);
    for _ in 0..200 {
        let width = 1 + (rng.next_u64() % 700) as usize;
        let rows = 1 + (rng.next_u64() % 17) as usize;
        let weights: Vec<i8> = (0..rows * width).map(|_| rng.next_u64() as i8).collect();
        let bias: Vec<i64> = (0..rows).map(|_| rng.next_u64() as i64).collect();
        let multipliers: Vec<i32> = (0..rows).map(|_| rng.next_u64() as i32).collect();
        let shifts: Vec<i32> = (0..rows).map(|_| rng.next_u64() as i32).collect();
        let input: Vec<i16> = (0..width).map(|_| rng.next_u64() as i16).collect();
        let (a, b) = (rng.next_u64() as i16, rng.next_u64() as i16);
        let requant = FcRequant {
            multipliers: &multipliers,
            shifts: &shifts,
            output_zero_point: rng.next_u64() as i32,
            activation_min: a,
            activation_max: b,
        };
        let table: Lut16Table = core::array::from_fn(|_| rng.next_u64() as i16);
        let layer = FullyConnected::new(width, rows, &weights, &bias);
        let mut portable = vec![0_i16; rows];
        layer.requantize_activated(
            &requant,
            Some(&table),
            LayerInput::Int16(&input),
            &mut portable,
        );
        let mut public = vec![0_i16; rows];
        layer
            .forward_validated(
                &requant,
                Some(&table),
                LayerInput::Int16(&input),
                &mut public,
            )
            .unwrap();
        assert_eq!(portable, public);
    }
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn int16_layer_equals_the_wide_model(
            seed in any::<u64>(),
            width in 1_usize..1200,
            index in 0_usize..60,
        ) {
            let mut rng = SplitMix64::new(seed);
            let case = random_case(&mut rng, width, index);
            let want_acc = case.model_accumulators(&case.input);
            let want = case.model_outputs(&want_acc);
            let mut out = vec![0_i16; case.rows];
            case.layer()
                .forward_activated(&case.requant(), case.table.as_ref(), LayerInput::Int16(&case.input), &mut out)
                .unwrap();
            prop_assert_eq!(out, want);
        }

        #[test]
        fn int16_outputs_are_monotone_in_the_bias(
            seed in any::<u64>(),
            width in 1_usize..600,
            delta in 0_i64..(1 << 40),
        ) {
            // Without a table the layer is monotone in each bias (the requantization is).
            let mut rng = SplitMix64::new(seed);
            let mut case = random_case(&mut rng, width, 3);
            case.table = None;
            let mut low = vec![0_i16; case.rows];
            case.layer()
                .forward_activated(&case.requant(), None, LayerInput::Int16(&case.input), &mut low)
                .unwrap();
            for b in case.bias.iter_mut() {
                *b = (*b + delta).min(BIAS16_MAX);
            }
            let mut high = vec![0_i16; case.rows];
            case.layer()
                .forward_activated(&case.requant(), None, LayerInput::Int16(&case.input), &mut high)
                .unwrap();
            prop_assert!(low.iter().zip(&high).all(|(l, h)| l <= h));
        }
    }
}
