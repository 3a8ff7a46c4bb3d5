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
//! loop branch adds 2 per four steps, see [`super::dsp_asm::row_pairs`]). Wider int8 inputs are
//! unpacked in the loop instead (24 per 16). The accumulators start at the rows' biases; the last
//! `in_features % 8` columns are added in Rust.
//!
//! Bit-exactness: every product of an int8 weight and an int8 or int16 input fits a halfword
//! product, the pair sum fits in 32 bits, and `SMLAD` adds it to the accumulator modulo 2^32 (on
//! signed overflow it only sets the sticky Q flag). Wrapping int32 addition is associative and
//! commutative, so the sums equal the portable kernel's for every input.

use super::dot::RowInput;
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

/// `sums[r] = bias[r] + dot(row_r, input)` for the first `sums.len()` (at most [`BLOCK_ROWS`])
/// rows of `rows` (row-major, `input.len()` columns; missing bias entries count as 0). Rows go
/// two at a time through the assembly kernels when they start on word boundaries (4-aligned
/// weights, width a multiple of 4); otherwise, and for an odd last row, the portable dot
/// products are used.
#[inline(always)]
pub(crate) fn block_sums<T: RowInput>(
    prepared: &Prepared,
    input: &[T],
    rows: &[i8],
    bias: &[i32],
    sums: &mut [i32],
) {
    let width = input.len();
    let blocks = width / BLOCK;
    let head = blocks * BLOCK;
    // The rows' biases as pairs: the caller's own when it has one per row, else a padded copy.
    let mut padded = [[0_i32; 2]; BLOCK_ROWS / 2];
    let start: &[[i32; 2]] = match bias.get(..sums.len()) {
        Some(own) => own.as_chunks::<2>().0,
        None => {
            for (slot, b) in padded.as_flattened_mut().iter_mut().zip(bias) {
                *slot = *b;
            }
            &padded
        }
    };
    let (sum_pairs, _) = sums.as_chunks_mut::<2>();
    let source = match (prepared.expanded, T::as_i8(input)) {
        (true, _) => Some(Input::Pairs(&prepared.pairs)),
        (false, Some(bytes)) => Some(Input::Bytes(bytes)),
        (false, None) => None,
    };
    let paired =
        source.is_some_and(|source| row_pairs(rows, width, source, blocks, start, sum_pairs));
    let done = if paired { 2 * sum_pairs.len() } else { 0 };
    let (paired, rest) = sums.split_at_mut(done);
    if head < width {
        let input_tail = input.get(head..).unwrap_or(&[]);
        for (sum, row) in paired.iter_mut().zip(rows.chunks_exact(width)) {
            *sum = sum.wrapping_add(T::dot(row.get(head..).unwrap_or(&[]), input_tail));
        }
    }
    let rest_rows = rows.get(done * width..).unwrap_or(&[]).chunks_exact(width);
    for (r, (sum, row)) in rest.iter_mut().zip(rest_rows).enumerate() {
        let b = bias.get(done + r).copied().unwrap_or(0);
        *sum = b.wrapping_add(T::dot(row, input));
    }
}
