//! The matrix-vector product of a fully connected layer, two output rows at a time:
//! `bias[o] + sum_i w[o][i] * x[i]` for int8 weights and an int8 or int16 input, accumulated as
//! the [`Accumulator`] type says (int32 wrapping, or int64 from 512-column int32 partial sums).
//!
//! [`for_each_block`] prepares the input once per layer call and hands the sums to its caller in
//! blocks of [`BLOCK_ROWS`] rows, which the caller requantizes before the next block. On Arm cores
//! with the DSP extension (`cfg(frmd_arm_dsp)`, module `kernels::dsp`) the input is unpacked to
//! halfword pairs once and two rows at a time go through an `SMLAD` kernel; on aarch64 four rows
//! at a time go through NEON (`SDOT` where the core has it; module `kernels::aarch64`); elsewhere
//! each row is [`dot_i8_prefix`] / [`dot_i8_i16_prefix`]. All give identical sums: wrapping int32
//! addition is associative and commutative. (On x86-64 CPUs with AVX2, `FullyConnected` uses the
//! eight-row kernels of `kernels::x86` for int8 inputs instead. A four-row SSE2 version of the
//! portable loop ran fewer instructions but was slower: LLVM's `punpcklbw` sign extension read a
//! stale register and chained the whole loop body.)

use super::dot::RowInput;
use super::precision::Accumulator;
use super::BLOCK_ROWS;

/// Calls `block(first, sums)` for consecutive blocks of up to [`BLOCK_ROWS`] rows of the
/// row-major `weights` (`input.len()` columns; a partial last row is ignored), in order, with
/// `sums[r] = bias[first + r] + dot(row_{first + r}, input)` accumulated as `A` defines (int32
/// wrapping; int64 from 512-column int32 partial sums); missing bias entries count as 0, so an
/// empty `bias` gives plain dot products. The input is prepared once (on DSP cores: unpacked to
/// halfword pairs, when at most `dsp::EXPANDED_COLUMNS` wide).
#[inline(always)]
pub(crate) fn for_each_block<T: RowInput, A: Accumulator>(
    input: &[T],
    weights: &[i8],
    bias: &[A],
    mut block: impl FnMut(usize, &[A]),
) {
    let width = input.len();
    if width == 0 {
        return;
    }
    #[cfg(frmd_arm_dsp)]
    let mut prepared = super::dsp::Prepared::new();
    #[cfg(frmd_arm_dsp)]
    prepared.fill(input);
    let mut sums = [A::default(); BLOCK_ROWS];
    let mut first = 0;
    for rows in weights.chunks(BLOCK_ROWS * width) {
        let count = rows.len() / width;
        let out = sums.get_mut(..count).unwrap_or(&mut []);
        let block_bias = bias.get(first..).unwrap_or(&[]);
        A::block(block_bias, out, width, |columns, start, residues| {
            #[cfg(frmd_arm_dsp)]
            super::dsp::block_sums(&prepared, input, rows, columns, start, residues);
            #[cfg(target_arch = "aarch64")]
            if super::aarch64::neon_active() {
                super::aarch64::block_sums(input, rows, columns, start, residues);
            } else {
                portable_block_sums(input, rows, columns, start, residues);
            }
            #[cfg(not(any(frmd_arm_dsp, target_arch = "aarch64")))]
            portable_block_sums(input, rows, columns, start, residues);
        });
        block(first, out);
        first += count;
    }
}

/// `sums[r] = start[r] + dot(row_r[columns], input[columns])` (int32, wrapping; missing `start`
/// entries count as 0) for the first `sums.len()` rows of `rows` (`input.len()` columns each).
#[cfg(not(frmd_arm_dsp))]
#[inline(always)]
pub(crate) fn portable_block_sums<T: RowInput>(
    input: &[T],
    rows: &[i8],
    columns: core::ops::Range<usize>,
    start: &[i32],
    sums: &mut [i32],
) {
    let width = input.len();
    let chunk = input.get(columns.clone()).unwrap_or(&[]);
    for ((sum, row), b) in sums
        .iter_mut()
        .zip(rows.chunks_exact(width))
        .zip(start.iter().chain(core::iter::repeat(&0)))
    {
        *sum = b.wrapping_add(T::dot(row.get(columns.clone()).unwrap_or(&[]), chunk));
    }
}

/// Calls `emit(bias[o] + dot(row_o, input))` for every row, in order (int32 accumulators; see
/// [`for_each_block`]).
#[inline(always)]
pub(crate) fn for_each_sum<T: RowInput>(
    input: &[T],
    weights: &[i8],
    bias: &[i32],
    emit: impl FnMut(i32),
) {
    for_each_accumulator(input, weights, bias, emit);
}

/// Calls `emit(acc_o)` with every row's accumulator `bias[o] + dot(row_o, input)` (as `A`
/// defines), in order (see [`for_each_block`]).
#[inline(always)]
pub(crate) fn for_each_accumulator<T: RowInput, A: Accumulator>(
    input: &[T],
    weights: &[i8],
    bias: &[A],
    mut emit: impl FnMut(A),
) {
    for_each_block(input, weights, bias, |_, sums| {
        sums.iter().copied().for_each(&mut emit)
    });
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::for_each_sum;
    use crate::kernels::dot::tests::{random_cases, wide_row_sums};
    use std::vec::Vec;

    #[test]
    fn row_dots_match_wide_sums() {
        random_cases(0x3A7, |weights, input| {
            let mut got = Vec::new();
            for_each_sum(input, weights, &[], |sum| got.push(i64::from(sum)));
            assert_eq!(
                got,
                wide_row_sums(weights, input),
                "columns {}",
                input.len()
            );
        });
    }
}
