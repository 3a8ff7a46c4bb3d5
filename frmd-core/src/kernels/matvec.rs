//! Portable int8 matrix-vector product (every target except Arm cores with the DSP extension,
//! which use the `SMLAD` kernel of `kernels::dsp`).
//!
//! Off Arm, rows go in groups of [`ROWS`]: each block of [`LANES`] input columns is loaded (and
//! sign-extended) once and multiplied into four weight rows with sixteen int32 partial sums per
//! row, which LLVM compiles to SSE2 `pmaddwd` (36 instructions per 64 multiply-accumulates, against
//! 16 per 16 one row at a time). On x86-64 CPUs with AVX2, `FullyConnected` uses the eight-row
//! kernels of `kernels::x86` instead (LLVM does not find `vpmaddwd` for this loop with AVX2).
//! On Arm without DSP the loop stays one row at a time ([`dot_i8_prefix`]), which is what
//! Cortex-M0/M3 register files favour.
//!
//! Bit-exactness: each row's sum is a wrapping int32 sum of the same products as
//! [`dot_i8_prefix`]; wrapping addition is associative and commutative, so every path returns
//! identical sums for every input.

use super::dot::dot_i8_prefix;

/// Weight rows per pass over the input on hosts.
#[cfg(not(target_arch = "arm"))]
const ROWS: usize = 4;

/// Calls `emit(dot(row, input))` for every row of the row-major `weights` (`input.len()` columns
/// per row) in order; a partial last row is ignored (callers check the shapes).
#[inline]
pub(crate) fn for_each_row_dot(weights: &[i8], input: &[i8], mut emit: impl FnMut(i32)) {
    #[cfg(target_arch = "arm")]
    {
        if input.is_empty() {
            return;
        }
        for row in weights.chunks_exact(input.len()) {
            emit(dot_i8_prefix(row, input));
        }
    }
    #[cfg(not(target_arch = "arm"))]
    for_each_row_block(weights, input, &mut emit);
}

/// Input columns per inner-loop step of the portable kernel (int32 partial sums per row).
#[cfg(not(target_arch = "arm"))]
const LANES: usize = 16;

/// Splits `weights` into blocks of [`ROWS`] rows of `input.len()` columns, emits the sums of
/// [`dot_four_rows`] for each block, then [`dot_i8_prefix`] for the last `rows % ROWS` rows, all
/// in row order.
#[cfg(not(target_arch = "arm"))]
#[inline(always)]
fn for_each_row_block(weights: &[i8], input: &[i8], emit: &mut impl FnMut(i32)) {
    let columns = input.len();
    let Some(block_len) = columns.checked_mul(ROWS).filter(|len| *len > 0) else {
        return;
    };
    let mut blocks = weights.chunks_exact(block_len);
    for block in &mut blocks {
        let Some((first, second)) = block.split_at_checked(2 * columns) else {
            return;
        };
        let (Some((row_0, row_1)), Some((row_2, row_3))) = (
            first.split_at_checked(columns),
            second.split_at_checked(columns),
        ) else {
            return;
        };
        for sum in dot_four_rows([row_0, row_1, row_2, row_3], input) {
            emit(sum);
        }
    }
    for row in blocks.remainder().chunks_exact(columns) {
        emit(dot_i8_prefix(row, input));
    }
}

/// `[dot(rows[r], input) for r in 0..4]` (all rows as long as `input`), wrapping int32 sums.
///
/// Written and attributed so that LLVM vectorizes it (checked in the disassembly): not inlined,
/// and the tails in a separate non-inlined function. Inlined into `FullyConnected::forward`, or
/// with the tail dot products inlined here, LLVM kept the 64 partial sums in general-purpose
/// registers and memory without `pmaddwd` (385k to 650k instead of about 220k instructions per
/// chunk).
#[cfg(not(target_arch = "arm"))]
#[inline(never)]
fn dot_four_rows(rows: [&[i8]; ROWS], input: &[i8]) -> [i32; ROWS] {
    let (x_blocks, x_tail) = input.as_chunks::<LANES>();
    let [(w0, t0), (w1, t1), (w2, t2), (w3, t3)] = rows.map(|row| row.as_chunks::<LANES>());
    let mut sums = [[0_i32; LANES]; ROWS];
    let blocks = x_blocks.iter().zip(w0).zip(w1).zip(w2).zip(w3);
    for ((((x, w0), w1), w2), w3) in blocks {
        let [s0, s1, s2, s3] = &mut sums;
        multiply_accumulate(s0, w0, x);
        multiply_accumulate(s1, w1, x);
        multiply_accumulate(s2, w2, x);
        multiply_accumulate(s3, w3, x);
    }
    let mut out = sums.map(|lanes| lanes.iter().fold(0_i32, |acc, s| acc.wrapping_add(*s)));
    if !x_tail.is_empty() {
        for (total, tail) in out.iter_mut().zip([t0, t1, t2, t3]) {
            *total = total.wrapping_add(dot_tail(tail, x_tail));
        }
    }
    out
}

/// [`dot_i8_prefix`] of the last `columns % LANES` columns, kept out of [`dot_four_rows`].
#[cfg(not(target_arch = "arm"))]
#[inline(never)]
fn dot_tail(row_tail: &[i8], input_tail: &[i8]) -> i32 {
    dot_i8_prefix(row_tail, input_tail)
}

/// `sums[i] += w[i] * x[i]` (wrapping) for every lane.
#[cfg(not(target_arch = "arm"))]
#[inline(always)]
fn multiply_accumulate(sums: &mut [i32; LANES], w: &[i8; LANES], x: &[i8; LANES]) {
    for ((sum, w), x) in sums.iter_mut().zip(w).zip(x) {
        *sum = sum.wrapping_add(i32::from(*w) * i32::from(*x));
    }
}

#[cfg(test)]
pub(crate) mod tests {
    extern crate std;
    use super::*;
    use crate::rng::SplitMix64;
    use std::vec::Vec;

    /// Row sums in i64 (no wrapping possible at these sizes).
    pub(crate) fn wide_row_sums(weights: &[i8], input: &[i8]) -> Vec<i64> {
        weights
            .chunks_exact(input.len())
            .map(|row| {
                row.iter()
                    .zip(input)
                    .map(|(w, x)| i64::from(*w) * i64::from(*x))
                    .sum()
            })
            .collect()
    }

    /// Random shapes (row counts not multiples of 4, column counts not multiples of 16), one
    /// case in five with only -128/127 entries.
    pub(crate) fn random_cases(seed: u64, mut check: impl FnMut(&[i8], &[i8])) {
        let mut rng = SplitMix64::new(seed);
        for case in 0..300 {
            let columns = 1 + (rng.next_u64() % 300) as usize;
            let rows = 1 + (rng.next_u64() % 11) as usize;
            let extreme = case % 5 == 0;
            let mut byte = || {
                let bits = rng.next_u64();
                match (extreme, bits % 2) {
                    (true, 0) => -128,
                    (true, _) => 127,
                    (false, _) => (bits >> 8) as i8,
                }
            };
            let weights: Vec<i8> = (0..rows * columns).map(|_| byte()).collect();
            let input: Vec<i8> = (0..columns).map(|_| byte()).collect();
            check(&weights, &input);
        }
    }

    #[test]
    fn portable_kernel_matches_wide_sums() {
        random_cases(0x3A7, |weights, input| {
            let mut got = Vec::new();
            for_each_row_dot(weights, input, |sum| got.push(i64::from(sum)));
            assert_eq!(
                got,
                wide_row_sums(weights, input),
                "columns {}",
                input.len()
            );
        });
    }

    #[test]
    fn partial_rows_and_empty_input_emit_nothing_extra() {
        let mut got = Vec::new();
        for_each_row_dot(&[1, 2, 3, 4, 5], &[1, 1], |sum| got.push(sum));
        assert_eq!(got, [3, 7]);
        got.clear();
        for_each_row_dot(&[1, 2, 3], &[], |sum| got.push(sum));
        assert!(got.is_empty());
    }
}
