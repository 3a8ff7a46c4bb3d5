//! The row kernels of every level (through the whole-layer loops of `x86::layer`) against the
//! portable definitions and a wide-integer model, on random shapes (every column remainder).
extern crate std;
use crate::kernels::dot::tests::{random_cases, wide_dot, wide_row_sums};
use crate::kernels::x86::test_tokens as tokens;
use crate::kernels::x86::{Avx2, BLOCK_ROWS};
use crate::kernels::{FcRequant, FullyConnected, LayerInput};
use crate::quant::requantize_to_i8;
use crate::rng::SplitMix64;
use std::vec::Vec;

/// Row sums of `weights` through the block kernels (zero bias), the last `rows % 8` rows padded
/// with zero rows.
fn kernel_row_sums(avx2: Avx2, weights: &[i8], input: &[i8]) -> Vec<i32> {
    let rows = weights.len() / input.len();
    let blocks = rows.div_ceil(BLOCK_ROWS) * BLOCK_ROWS;
    let mut padded = weights.to_vec();
    padded.resize(blocks * input.len(), 0);
    let bias = std::vec![0; blocks];
    let layer = FullyConnected::new(input.len(), blocks, &padded, &bias);
    let mut sums = std::vec![0; blocks];
    avx2.accumulate_blocks(&layer, LayerInput::Int8(input), false, &mut sums);
    sums.truncate(rows);
    sums
}

#[test]
fn eight_row_sums_match_wide_sums() {
    for avx2 in tokens() {
        random_cases(0xA7, |weights, input| {
            let got: Vec<i64> = kernel_row_sums(avx2, weights, input)
                .into_iter()
                .map(i64::from)
                .collect();
            let want = wide_row_sums(weights, input);
            assert_eq!(got, want, "{avx2:?} columns {}", input.len());
        });
    }
}

#[test]
fn sums_wrap_like_the_portable_kernel() {
    for avx2 in tokens() {
        sums_wrap(avx2);
    }
}

fn sums_wrap(avx2: Avx2) {
    // 131 074 products of 16384 exceed i32::MAX: the sums wrap like `dot_i8`.
    static COLUMN: [i8; 131_074] = [-128; 131_074];
    let weights: Vec<i8> = (0..BLOCK_ROWS).flat_map(|_| COLUMN).collect();
    let wide = (131_074_i64 * 16384) as i32;
    let bias = [1; BLOCK_ROWS];
    let layer = FullyConnected::new(COLUMN.len(), BLOCK_ROWS, &weights, &bias);
    let mut got = [0; BLOCK_ROWS];
    avx2.accumulate_blocks(&layer, LayerInput::Int8(&COLUMN), true, &mut got);
    assert_eq!(got, [wide.wrapping_add(1); BLOCK_ROWS], "{avx2:?}");
    assert_eq!(crate::kernels::dot_i8(&COLUMN, &COLUMN), Ok(wide));
}

#[test]
fn requantized_rows_match_scalar_requantization() {
    for avx2 in tokens() {
        requantized_rows_match(avx2);
    }
}

fn requantized_rows_match(avx2: Avx2) {
    let mut rng = SplitMix64::new(0xB10C);
    for case in 0..2_000 {
        let columns = 1 + (rng.next_u64() % 300) as usize;
        let weights: Vec<i8> = (0..BLOCK_ROWS * columns)
            .map(|_| rng.next_u64() as i8)
            .collect();
        let input: Vec<i8> = (0..columns).map(|_| rng.next_u64() as i8).collect();
        let wide_input: Vec<i16> = (0..columns).map(|_| rng.next_u64() as i16).collect();
        let bias: [i32; BLOCK_ROWS] = core::array::from_fn(|_| (rng.next_u64() as i32) >> 12);
        let scales: [(i32, i32); BLOCK_ROWS] = core::array::from_fn(|_| {
            let u = (rng.next_u64() >> 11) as f64 / (1_u64 << 53) as f64;
            crate::quant::quantize_multiplier(1e-4 * 1e3_f64.powf(u)).unwrap_or((1 << 30, 0))
        });
        let multipliers = scales.map(|(m, _)| m);
        let shifts = scales.map(|(_, s)| s);
        let zero_point = (rng.next_u64() % 256) as i32 - 128;
        let bounds = if case % 2 == 0 {
            (zero_point as i8, 127)
        } else {
            (-128, 127)
        };
        let requant = FcRequant {
            multipliers: &multipliers,
            shifts: &shifts,
            output_zero_point: zero_point,
            activation_min: bounds.0,
            activation_max: bounds.1,
        };
        let layer = FullyConnected::new(columns, BLOCK_ROWS, &weights, &bias);
        for input in [LayerInput::Int8(&input), LayerInput::Int16(&wide_input)] {
            let mut got = [0_i8; BLOCK_ROWS];
            avx2.requantize_blocks(&layer, &requant, input, &mut got);
            let mut acc = [0_i32; BLOCK_ROWS];
            avx2.accumulate_blocks(&layer, input, true, &mut acc);
            let want: [i8; BLOCK_ROWS] = core::array::from_fn(|r| {
                let row = &weights[r * columns..(r + 1) * columns];
                let dot = wide_dot(row, input);
                assert_eq!(
                    acc[r],
                    bias[r].wrapping_add(dot as i32),
                    "{avx2:?} case {case}"
                );
                requantize_to_i8(
                    acc[r],
                    multipliers[r],
                    shifts[r],
                    zero_point,
                    bounds.0,
                    bounds.1,
                )
            });
            assert_eq!(got, want, "{avx2:?} case {case}");
        }
    }
}
