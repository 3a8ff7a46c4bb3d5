//! The AVX2 row kernels against the portable ones and a wide-integer model.
extern crate std;
use super::*;
use crate::kernels::dot::tests::{random_cases, wide_row_sums};
use crate::quant::requantize_to_i8;
use crate::rng::SplitMix64;
use std::vec::Vec;

/// Row sums of `weights` through the eight-row kernel (zero bias), the last `rows % 8` rows
/// padded with zero rows.
fn kernel_row_sums(avx2: Avx2, weights: &[i8], input: &[i8]) -> Vec<i32> {
    let rows = weights.len() / input.len();
    let mut padded = weights.to_vec();
    padded.resize(rows.div_ceil(BLOCK_ROWS) * BLOCK_ROWS * input.len(), 0);
    let mut sums = Vec::new();
    for block in padded.chunks_exact(BLOCK_ROWS * input.len()) {
        sums.extend(avx2.accumulate_rows(block, input, &[0; BLOCK_ROWS]));
    }
    sums.truncate(rows);
    sums
}

/// The tokens to test: AVX2 alone, and with AVX-VNNI when the CPU has it.
fn tokens() -> Vec<Avx2> {
    let Some(detected) = Avx2::get() else {
        std::eprintln!("no AVX2 on this CPU: only the portable kernel is exercised");
        return Vec::new();
    };
    let mut tokens = std::vec![Avx2 { vnni: false }];
    if detected.vnni() {
        tokens.push(detected);
    } else {
        std::eprintln!("no AVX-VNNI on this CPU: its kernel is not exercised");
    }
    tokens
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
    let got = avx2.accumulate_rows(&weights, &COLUMN, &[1; BLOCK_ROWS]);
    assert_eq!(got, [wide.wrapping_add(1); BLOCK_ROWS]);
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
        let columns = 1 + (rng.next_u64() % 70) as usize;
        let weights: Vec<i8> = (0..BLOCK_ROWS * columns)
            .map(|_| rng.next_u64() as i8)
            .collect();
        let input: Vec<i8> = (0..columns).map(|_| rng.next_u64() as i8).collect();
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
        let requant = RequantBlock {
            multipliers: &multipliers,
            shifts: &shifts,
            zero_point,
            bounds,
        };
        let got = avx2.requantize_rows(&weights, &input, &bias, requant);
        let acc = avx2.accumulate_rows(&weights, &input, &bias);
        let want: [i8; BLOCK_ROWS] = core::array::from_fn(|r| {
            let dot =
                crate::kernels::dot_i8(&weights[r * columns..(r + 1) * columns], &input).unwrap();
            assert_eq!(acc[r], bias[r].wrapping_add(dot));
            requantize_to_i8(
                acc[r],
                multipliers[r],
                shifts[r],
                zero_point,
                bounds.0,
                bounds.1,
            )
        });
        assert_eq!(got, want, "case {case}");
    }
}
