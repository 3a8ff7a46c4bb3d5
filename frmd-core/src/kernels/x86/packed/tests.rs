//! The packed-weight layers of every VNNI level against the wide-integer definition: random
//! shapes (every column remainder of both group sizes, partial row blocks), extreme codes and
//! int32 wrap-around.
extern crate std;
use crate::kernels::dot::tests::wide_dot;
use crate::kernels::packed::{pack, PackedKind, PackedWeights};
use crate::kernels::x86::{test_tokens, Avx2};
use crate::kernels::{FcRequant, FullyConnected, LayerInput};
use crate::quant::{quantize_multiplier, requantize_to_i8};
use crate::rng::SplitMix64;
use std::vec::Vec;

/// The tokens with a packed level.
fn tokens() -> Vec<Avx2> {
    let tokens: Vec<Avx2> = test_tokens()
        .into_iter()
        .filter(|t| t.runs_packed())
        .collect();
    if tokens.is_empty() {
        std::eprintln!("no VNNI level on this CPU: the packed kernels are not exercised");
    }
    tokens
}

/// `bias[o] + sum w x` (wrapping int32) of every row.
fn wide_sums(weights: &[i8], bias: &[i32], input: LayerInput<'_>) -> Vec<i32> {
    weights
        .chunks_exact(input.len())
        .zip(bias)
        .map(|(row, b)| b.wrapping_add(wide_dot(row, input) as i32))
        .collect()
}

/// Runs `check` with `layer` carrying its packed copy for `input`'s type.
fn with_packed(
    weights: &[i8],
    bias: &[i32],
    input: LayerInput<'_>,
    check: impl FnOnce(&FullyConnected<'_, i32>, &PackedWeights<'_>),
) {
    let layer = FullyConnected::new(input.len(), bias.len(), weights, bias);
    let kind = PackedKind::of(input);
    let mut bytes =
        std::vec![0_u8; kind.packed_len(layer.in_features, layer.out_features).unwrap()];
    pack(&layer, kind, &mut bytes).unwrap();
    let packed = PackedWeights::new(&layer, kind, &bytes).unwrap();
    assert!(packed.serves(&layer, input));
    let layer = FullyConnected {
        packed: Some(packed),
        ..layer
    };
    check(&layer, &packed);
}

#[test]
fn packed_layers_match_the_wide_sums_and_scalar_requantization() {
    let tokens = tokens();
    let mut rng = SplitMix64::new(0x9AC4);
    for case in 0..600 {
        let columns = 1 + (rng.next_u64() % 300) as usize;
        let rows = 1 + (rng.next_u64() % 70) as usize;
        let extreme = case % 7 == 0;
        let mut code = || {
            if extreme {
                [-128, 127][(rng.next_u64() % 2) as usize]
            } else {
                rng.next_u64() as i8
            }
        };
        let weights: Vec<i8> = (0..rows * columns).map(|_| code()).collect();
        let input: Vec<i8> = (0..columns).map(|_| code()).collect();
        let wide_input: Vec<i16> = (0..columns)
            .map(|_| {
                if extreme {
                    i16::MIN
                } else {
                    rng.next_u64() as i16
                }
            })
            .collect();
        let bias: Vec<i32> = (0..rows).map(|_| rng.next_u64() as i32).collect();
        let scales: Vec<(i32, i32)> = (0..rows)
            .map(|_| {
                let u = (rng.next_u64() >> 11) as f64 / (1_u64 << 53) as f64;
                quantize_multiplier(1e-6 * 1e4_f64.powf(u)).unwrap_or((1 << 30, 0))
            })
            .collect();
        let multipliers: Vec<i32> = scales.iter().map(|s| s.0).collect();
        let shifts: Vec<i32> = scales.iter().map(|s| s.1).collect();
        let zero_point = (rng.next_u64() % 256) as i32 - 128;
        let requant = FcRequant {
            multipliers: &multipliers,
            shifts: &shifts,
            output_zero_point: zero_point,
            activation_min: if case % 2 == 0 {
                zero_point as i8
            } else {
                -128
            },
            activation_max: 127,
        };
        for input in [LayerInput::Int8(&input), LayerInput::Int16(&wide_input)] {
            let want = wide_sums(&weights, &bias, input);
            let want_codes: Vec<i8> = want
                .iter()
                .zip(&scales)
                .map(|(acc, (m, s))| {
                    requantize_to_i8(*acc, *m, *s, zero_point, requant.activation_min, 127)
                })
                .collect();
            with_packed(&weights, &bias, input, |layer, packed| {
                for token in &tokens {
                    let mut acc = std::vec![0; rows];
                    assert!(token.accumulate_packed(packed, layer, input, &mut acc));
                    assert_eq!(acc, want, "{token:?} case {case} {rows}x{columns}");
                    let mut codes = std::vec![0; rows];
                    assert!(token.requantize_packed(packed, layer, &requant, input, &mut codes));
                    assert_eq!(codes, want_codes, "{token:?} case {case} {rows}x{columns}");
                }
                // Through the public layer calls too (whichever level this CPU runs).
                let mut acc = std::vec![0; rows];
                layer.accumulate(input, &mut acc).unwrap();
                assert_eq!(acc, want, "accumulate, case {case}");
                let mut codes = std::vec![0; rows];
                layer
                    .forward_activated(&requant, None, input, &mut codes)
                    .unwrap();
                assert_eq!(codes, want_codes, "forward, case {case}");
            });
        }
    }
}

#[test]
fn packed_sums_wrap_like_the_portable_kernel() {
    // The widest packed layer: 1,024 products of 2^22 (int16 inputs) leave int32, and a bias at
    // the int32 limits wraps with int8 inputs.
    let columns = crate::kernels::packed::MAX_PACKED_COLUMNS;
    let weights = std::vec![-128_i8; 17 * columns];
    let bias = [i32::MAX - 3; 17];
    let x8 = std::vec![-128_i8; columns];
    let x16 = std::vec![i16::MIN; columns];
    for input in [LayerInput::Int8(&x8), LayerInput::Int16(&x16)] {
        let want = wide_sums(&weights, &bias, input);
        with_packed(&weights, &bias, input, |layer, packed| {
            for token in tokens() {
                let mut acc = [0; 17];
                assert!(token.accumulate_packed(packed, layer, input, &mut acc));
                assert_eq!(acc.as_slice(), want.as_slice(), "{token:?}");
            }
        });
    }
}

/// int16-activation layers (int64 accumulators) of one column chunk: the packed accumulators
/// are the exact sums, and the requantized, tabled outputs equal the row-major kernels'.
#[test]
fn packed_wide_layers_match_the_exact_sums_and_the_row_major_kernels() {
    use crate::kernels::lut16::Lut16Table;
    use crate::quant::{CHUNK16, SHIFT16_MAX, SHIFT16_MIN};
    let tokens = tokens();
    let mut rng = SplitMix64::new(0x16A7);
    let table: Lut16Table = core::array::from_fn(|_| rng.next_u64() as i16);
    for case in 0..300 {
        let columns = 1 + (rng.next_u64() % CHUNK16 as u64) as usize;
        let rows = 1 + (rng.next_u64() % 40) as usize;
        let weights: Vec<i8> = (0..rows * columns)
            .map(|_| ((rng.next_u64() % 255) as i32 - 127) as i8)
            .collect();
        let x16: Vec<i16> = (0..columns).map(|_| rng.next_u64() as i16).collect();
        let bias: Vec<i64> = (0..rows).map(|_| (rng.next_u64() as i64) >> 20).collect();
        let multipliers: Vec<i32> = (0..rows)
            .map(|_| (1 << 30) + (rng.next_u64() % (1 << 30)) as i32)
            .collect();
        let span = (SHIFT16_MAX - SHIFT16_MIN + 1) as u64;
        let shifts: Vec<i32> = (0..rows)
            .map(|_| SHIFT16_MIN + (rng.next_u64() % span) as i32)
            .collect();
        let requant = FcRequant {
            multipliers: &multipliers,
            shifts: &shifts,
            output_zero_point: 0,
            activation_min: if case % 2 == 0 { 0 } else { i16::MIN },
            activation_max: i16::MAX,
        };
        let plain = FullyConnected::new(columns, rows, &weights, &bias);
        plain.validate_exact().unwrap();
        let input = LayerInput::Int16(&x16);
        let exact: Vec<i64> = weights
            .chunks_exact(columns)
            .zip(&bias)
            .map(|(row, b)| b + wide_dot(row, LayerInput::Int16(&x16)))
            .collect();
        let table = (case % 3 != 0).then_some(&table);
        let mut want_codes = std::vec![0_i16; rows];
        plain
            .forward_activated(&requant, table, input, &mut want_codes)
            .unwrap();
        let kind = PackedKind::of(input);
        let mut bytes = std::vec![0_u8; kind.packed_len(columns, rows).unwrap()];
        pack(&plain, kind, &mut bytes).unwrap();
        let packed = PackedWeights::new(&plain, kind, &bytes).unwrap();
        let layer = FullyConnected {
            packed: Some(packed),
            ..plain
        };
        for token in &tokens {
            let mut acc = std::vec![0_i64; rows];
            assert!(token.accumulate_packed_wide(&packed, &layer, input, &mut acc));
            assert_eq!(acc, exact, "{token:?} case {case} {rows}x{columns}");
            let mut codes = std::vec![0_i16; rows];
            assert!(
                token.requantize_packed_wide(&packed, &layer, &requant, table, input, &mut codes)
            );
            assert_eq!(codes, want_codes, "{token:?} case {case} {rows}x{columns}");
        }
        let mut acc = std::vec![0_i64; rows];
        layer.accumulate(input, &mut acc).unwrap();
        assert_eq!(acc, exact, "accumulate, case {case}");
        let mut codes = std::vec![0_i16; rows];
        layer
            .forward_activated(&requant, table, input, &mut codes)
            .unwrap();
        assert_eq!(codes, want_codes, "forward, case {case}");
    }
}
