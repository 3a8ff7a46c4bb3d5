//! Two rows of an int8 matrix-vector product on Arm cores with the DSP extension
//! (Cortex-M4/M7/M33), for `super::rows::for_each_block`.
//!
//! Compiled only with `cfg(frmd_arm_dsp)` (set by `build.rs`); every other target uses the
//! portable dot products. The `asm!` inner loops are in [`super::dsp_asm`], the only module of
//! frmd-core with `unsafe` on Arm.
//!
//! The input is first rewritten as sign-extended halfword pairs, once per layer call, into a
//! buffer on the stack ([`Prepared`], inputs up to [`EXPANDED_COLUMNS`] wide): per 4 columns
//! `xe = (x0, x2)` and `xo = (x1, x3)`, the order in which `SXTB16` / `SXTB16 ROR #8` split a
//! weight word. int8 inputs are sign-extended; int16 inputs (the first layer's 16-bit input
//! plane) are only reordered. Two output rows then go through the assembly loop eight columns per
//! step: one `LDM` of four input words, one `LDRD` of eight weights per row, and per weight word
//! two `SXTB16` and two `SMLAD`: 19 instructions per 16 multiply-accumulates (1.19 per MAC; the
//! loop branch adds 2 per four steps, see [`super::dsp_asm::row_pairs`]). Wider inputs are
//! unpacked in the loop instead (24 per 16: int8 by `SXTB16`, int16 by `PKHBT`/`PKHTB`). The
//! accumulators start at the rows' biases (int32 accumulators) or at 0 (each 512-column chunk of
//! an int64 accumulator, see `kernels::Accumulator`); the last `in_features % 8` columns are added
//! in Rust. The int16-activation layers run the same loop: the pair buffer then holds their int16
//! codes as they are.
//!
//! Bit-exactness: every product of an int8 weight and an int8 or int16 input fits a halfword
//! product, the pair sum fits in 32 bits, and `SMLAD` adds it to the accumulator modulo 2^32 (on
//! signed overflow it only sets the sticky Q flag). Wrapping int32 addition is associative and
//! commutative, so the sums equal the portable kernel's for every input.

use super::dot::RowInput;
use core::ops::Range;

use super::dsp_asm::{row_pairs, Input, BLOCK};
use super::BLOCK_ROWS;

/// Widest input that is rewritten to halfword pairs on the stack (2 bytes per column: 512 bytes).
pub(crate) const EXPANDED_COLUMNS: usize = 256;

/// The input as halfword pairs: words `2k, 2k+1` hold columns `(4k, 4k+2)`, `(4k+1, 4k+3)` (low
/// half first), for every complete 4-column block; not `expanded` for inputs wider than
/// [`EXPANDED_COLUMNS`].
pub(crate) struct Prepared {
    pairs: [u32; EXPANDED_COLUMNS / 2],
    expanded: bool,
}

impl Prepared {
    /// An empty buffer (fill it in place: it is 512 bytes).
    #[inline(always)]
    pub(crate) const fn new() -> Self {
        Self {
            pairs: [0; EXPANDED_COLUMNS / 2],
            expanded: false,
        }
    }

    /// The pairs of `input`, if it is at most [`EXPANDED_COLUMNS`] wide.
    #[inline(always)]
    pub(crate) fn fill<T: RowInput>(&mut self, input: &[T]) {
        self.expanded = input.len() <= EXPANDED_COLUMNS;
        if !self.expanded {
            return;
        }
        let (quads, _) = input.as_chunks::<4>();
        let (slots, _) = self.pairs.as_chunks_mut::<2>();
        for (&[x0, x1, x2, x3], slot) in quads.iter().zip(slots) {
            *slot = [x0.half() | x2.half() << 16, x1.half() | x3.half() << 16];
        }
    }
}

/// `sums[r] = start[r] + dot(row_r[columns], input[columns])` (int32, wrapping) for the first
/// `sums.len()` (at most [`BLOCK_ROWS`]) rows of `rows` (row-major, `input.len()` columns; missing
/// `start` entries count as 0): the whole row for int32 accumulators, one 512-column chunk of it
/// for int64 ones. Rows go two at a time through the assembly kernels when they start on word
/// boundaries (4-aligned weights, width a multiple of 4); otherwise, and for an odd last row, the
/// portable dot products are used. Inputs wider than the pair buffer are unpacked in the loop:
/// int8 codes by `SXTB16`, int16 codes (word-aligned) by `PKHBT`/`PKHTB`.
#[inline(always)]
pub(crate) fn block_sums<T: RowInput>(
    prepared: &Prepared,
    input: &[T],
    rows: &[i8],
    columns: Range<usize>,
    start: &[i32],
    sums: &mut [i32],
) {
    let width = input.len();
    let first = columns.start;
    let chunk = input.get(columns.clone()).unwrap_or(&[]);
    let count = chunk.len();
    let blocks = count / BLOCK;
    let head = blocks * BLOCK;
    // The rows' start values as pairs: the caller's own when it has one per row, else a padded
    // copy.
    let mut padded = [[0_i32; 2]; BLOCK_ROWS / 2];
    let start_pairs: &[[i32; 2]] = match start.get(..sums.len()) {
        Some(own) => own.as_chunks::<2>().0,
        None => {
            for (slot, b) in padded.as_flattened_mut().iter_mut().zip(start) {
                *slot = *b;
            }
            &padded
        }
    };
    let (sum_pairs, _) = sums.as_chunks_mut::<2>();
    // The pair buffer holds the input from column 0 (only inputs up to 256 columns, one chunk).
    let source = match (
        prepared.expanded && first == 0,
        T::as_i8(chunk),
        T::as_i16(chunk),
    ) {
        (true, _, _) => Some(Input::Pairs(&prepared.pairs)),
        (false, Some(bytes), _) => Some(Input::Bytes(bytes)),
        (false, None, Some(halves)) => Some(Input::Halves(halves)),
        (false, None, None) => None,
    };
    let chunk_rows = rows.get(first..).unwrap_or(&[]);
    let paired = source
        .is_some_and(|source| row_pairs(chunk_rows, width, source, blocks, start_pairs, sum_pairs));
    let done = if paired { 2 * sum_pairs.len() } else { 0 };
    let (paired, rest) = sums.split_at_mut(done);
    if head < count {
        let input_tail = chunk.get(head..).unwrap_or(&[]);
        let tail_columns = first + head..columns.end;
        for (sum, row) in paired.iter_mut().zip(rows.chunks_exact(width)) {
            let row_tail = row.get(tail_columns.clone()).unwrap_or(&[]);
            *sum = sum.wrapping_add(T::dot(row_tail, input_tail));
        }
    }
    let rest_rows = rows.get(done * width..).unwrap_or(&[]).chunks_exact(width);
    for (r, (sum, row)) in rest.iter_mut().zip(rest_rows).enumerate() {
        let b = start.get(done + r).copied().unwrap_or(0);
        *sum = b.wrapping_add(T::dot(row.get(columns.clone()).unwrap_or(&[]), chunk));
    }
}

/// `FullyConnected::forward_validated` for int16 outputs of a layer up to 512 columns wide (one
/// int64 chunk; wider layers return `false` and take the generic rows): per block of
/// [`BLOCK_ROWS`] rows the int32 sums from 0 ([`block_sums`]), then in one loop per row
/// `acc = bias + sext(sum)` (two instructions), the requantization (`dsp_asm::scale_s64`), the
/// clamp and the table, so no int64 accumulator goes through memory. The same values as the
/// generic path (the `kernels` firmware image's digest compares both with the host).
#[inline(always)]
pub(crate) fn requantize_rows_wide<T: RowInput>(
    fc: &super::FullyConnected<'_, i64>,
    requant: &super::FcRequant<'_, i16>,
    table: Option<&super::Lut16Table>,
    input: &[T],
    output: &mut [i16],
) -> bool {
    const ZERO: [i32; BLOCK_ROWS] = [0; BLOCK_ROWS];
    let width = input.len();
    if width == 0 || width > crate::quant::CHUNK16 {
        return false;
    }
    let mut prepared = Prepared::new();
    prepared.fill(input);
    let mut sums = [0_i32; BLOCK_ROWS];
    let mut first = 0;
    for rows in fc.weights.chunks(BLOCK_ROWS * width) {
        let count = rows.len() / width;
        let end = first + count;
        let Some(out_sums) = sums.get_mut(..count) else {
            break;
        };
        block_sums(&prepared, input, rows, 0..width, &ZERO, out_sums);
        if let (Some(out), Some(bias), Some(m), Some(s)) = (
            output.get_mut(first..end),
            fc.bias.get(first..end),
            requant.multipliers.get(first..end),
            requant.shifts.get(first..end),
        ) {
            let bounds = (requant.activation_min, requant.activation_max);
            match table {
                Some(table) => requantize_sums(out_sums, bias, m, s, bounds, out, &|y| {
                    super::dsp_asm::lookup16(table, y)
                }),
                None => requantize_sums(out_sums, bias, m, s, bounds, out, &|y| y),
            }
        }
        first = end;
    }
    true
}

/// `out[r] = map(clamp(scale_s64(bias[r] + sext(sums[r]), m[r], s[r])))` for one block of rows.
/// Not inlined (the loop has the registers to itself); the full int16 range takes a loop
/// whose clamp is one `SSAT`.
#[inline(never)]
fn requantize_sums(
    sums: &[i32],
    bias: &[i64],
    multipliers: &[i32],
    shifts: &[i32],
    (lo, hi): (i16, i16),
    out: &mut [i16],
    map: &impl Fn(i16) -> i16,
) {
    let channels = out
        .iter_mut()
        .zip(sums.iter().zip(bias))
        .zip(multipliers.iter().zip(shifts));
    if (lo, hi) == (i16::MIN, i16::MAX) {
        for ((out, (sum, b)), (m, s)) in channels {
            let r = super::dsp_asm::scale_s64(b.wrapping_add(i64::from(*sum)), *m, *s);
            *out = map(r.clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16);
        }
    } else {
        for ((out, (sum, b)), (m, s)) in channels {
            let r = super::dsp_asm::scale_s64(b.wrapping_add(i64::from(*sum)), *m, *s);
            *out = map(r.max(i32::from(lo)).min(i32::from(hi)) as i16);
        }
    }
}
