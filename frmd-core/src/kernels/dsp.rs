//! int8 matrix-vector product for Arm cores with the DSP extension (Cortex-M4/M7, Armv7E-M).
//!
//! Compiled only with `cfg(frmd_arm_dsp)` (set by `build.rs`); every other target uses the
//! portable [`super::dot::dot_i8_prefix`] per row. This is the only module of frmd-core with
//! `unsafe`: two `asm!` blocks that read the weight rows and the input, and touch nothing else.
//!
//! Output rows go in groups of four, columns in blocks of eight. Per 4 columns, the input is
//! needed as two halfword pairs, `xe = (x0, x2)` and `xo = (x1, x3)`; for each of the 4 rows the
//! loop loads one weight word, sign-extends it the same way (`SXTB16`, `SXTB16 ROR #8`) and
//! accumulates both pairs with `SMLAD` (`acc += w0*x0 + w2*x2`, `acc += w1*x1 + w3*x3`): 20
//! instructions per 16 multiply-accumulates. The input pairs come from
//! - a halfword copy of the input made once per layer call on the stack (inputs up to
//!   [`EXPANDED_COLUMNS`] wide): one `LDRD` per 4 columns, 42 + 2 loop instructions per 32 MACs
//!   (1.375 per MAC);
//! - or, for wider inputs, the int8 input itself: `LDR` + 2 `SXTB16` per 4 columns, 46 + 2 per 32
//!   MACs (1.5 per MAC).
//!
//! The last `in_features % 8` columns and `out_features % 4` rows use plain Rust.
//!
//! Bit-exactness: every product of two int8 values fits a halfword product, the pair sum fits in
//! 32 bits, and `SMLAD` adds it to the accumulator modulo 2^32 (on signed overflow it only sets
//! the sticky Q flag). Wrapping int32 addition is associative and commutative, so the sums equal
//! the portable kernel's for every input.

#![allow(unsafe_code)]

use super::dot::dot_i8_prefix;

/// Columns per loop iteration of the assembly blocks.
const BLOCK: usize = 8;

/// Widest input that is copied to halfword pairs on the stack (2 bytes per column: 512 bytes).
pub(crate) const EXPANDED_COLUMNS: usize = 256;

/// Assembly for 4 columns of 4 rows once `xe`/`xo` hold the input pairs: rows 0 and 1 through
/// `row_0` (`[row_0]`, `[row_0, stride]`), rows 2 and 3 through `row_2`; both pointers advance 4.
macro_rules! four_rows_four_columns {
    () => {
        concat!(
            "ldr {w}, [{row_0}, {stride}]\n",
            "sxtb16 {t}, {w}\n",
            "smlad {acc1}, {t}, {xe}, {acc1}\n",
            "sxtb16 {w}, {w}, ror #8\n",
            "smlad {acc1}, {w}, {xo}, {acc1}\n",
            "ldr {w}, [{row_0}], #4\n",
            "sxtb16 {t}, {w}\n",
            "smlad {acc0}, {t}, {xe}, {acc0}\n",
            "sxtb16 {w}, {w}, ror #8\n",
            "smlad {acc0}, {w}, {xo}, {acc0}\n",
            "ldr {w}, [{row_2}, {stride}]\n",
            "sxtb16 {t}, {w}\n",
            "smlad {acc3}, {t}, {xe}, {acc3}\n",
            "sxtb16 {w}, {w}, ror #8\n",
            "smlad {acc3}, {w}, {xo}, {acc3}\n",
            "ldr {w}, [{row_2}], #4\n",
            "sxtb16 {t}, {w}\n",
            "smlad {acc2}, {t}, {xe}, {acc2}\n",
            "sxtb16 {w}, {w}, ror #8\n",
            "smlad {acc2}, {w}, {xo}, {acc2}\n",
        )
    };
}

/// Calls `emit(sum_i weights[o][i] * input[i])` (int32, wrapping) for every row `o` of the
/// row-major `weights` (`input.len()` columns) in order; a partial last row is ignored.
pub(crate) fn for_each_row_dot(weights: &[i8], input: &[i8], mut emit: impl FnMut(i32)) {
    let width = input.len();
    if width == 0 {
        return;
    }
    let blocks = width / BLOCK;
    let head = blocks * BLOCK;
    let input_tail = input.get(head..).unwrap_or(&[]);
    let mut pairs = [0_u32; EXPANDED_COLUMNS / 2];
    let expanded = width <= EXPANDED_COLUMNS;
    if expanded {
        expand_to_pairs(input, &mut pairs);
    }
    let groups = weights.chunks_exact(width.saturating_mul(4));
    let last_rows = groups.remainder();
    for group in groups {
        let dots = if expanded {
            rows4_pairs(group, width, &pairs, blocks)
        } else {
            rows4_bytes(group, input, blocks)
        };
        let Some(mut dots) = dots else {
            // Unreachable: `group.len() == 4 * width` by construction; stay correct anyway.
            group.chunks_exact(width).for_each(|row| emit(dot_i8_prefix(row, input)));
            continue;
        };
        for (sum, row) in dots.iter_mut().zip(group.chunks_exact(width)) {
            let row_tail = row.get(head..).unwrap_or(&[]);
            // Fewer than 8 columns: a plain loop.
            for (weight, x) in row_tail.iter().zip(input_tail) {
                *sum = sum.wrapping_add(i32::from(*weight) * i32::from(*x));
            }
        }
        dots.into_iter().for_each(&mut emit);
    }
    for row in last_rows.chunks_exact(width) {
        emit(dot_i8_prefix(row, input));
    }
}

/// Writes `(x[4k], x[4k+2])` and `(x[4k+1], x[4k+3])` as sign-extended halfword pairs (low half
/// first) to `pairs[2k]` and `pairs[2k + 1]`, for every complete 4-column block of `input` that
/// fits `pairs`.
fn expand_to_pairs(input: &[i8], pairs: &mut [u32]) {
    let half = |value: i8| u32::from(i16::from(value) as u16);
    let (quads, _) = input.as_chunks::<4>();
    let (pair_slots, _) = pairs.as_chunks_mut::<2>();
    for (&[x0, x1, x2, x3], slot) in quads.iter().zip(pair_slots) {
        *slot = [half(x0) | half(x2) << 16, half(x1) | half(x3) << 16];
    }
}

/// The first `8 * blocks` columns of the 4 rows in `group` times the halfword-pair input `pairs`
/// (see [`expand_to_pairs`]). `None` unless `group.len() == 4 * width`, `1 <= blocks` and
/// `8 * blocks <= min(width, 2 * pairs.len())`.
fn rows4_pairs(group: &[i8], width: usize, pairs: &[u32], blocks: usize) -> Option<[i32; 4]> {
    let columns = blocks.checked_mul(BLOCK)?;
    let in_bounds = blocks >= 1
        && width.checked_mul(4) == Some(group.len())
        && columns <= width
        && columns <= pairs.len().saturating_mul(2);
    if !in_bounds {
        return None;
    }
    let rows_2_3 = group.get(2 * width..)?;
    let [mut acc0, mut acc1, mut acc2, mut acc3] = [0_i32; 4];
    // SAFETY: the block only reads memory, and only inside the borrowed slices (checked above):
    // - `pairs` (a `u32` slice, so 4-byte aligned as `LDRD` requires) at byte offsets
    //   `[0, 2 * columns)`, i.e. `columns / 2 <= pairs.len()` words;
    // - row r of `group` at `r * width + [0, columns)` with `columns <= width`: rows 0 and 1
    //   through `row_0` and `row_0 + stride`, rows 2 and 3 through `row_2 = row_0 + 2 * width`
    //   (`rows_2_3` starts there) and `row_2 + stride`.
    // `blocks >= 1`, so `end > input_ptr` and the bottom-tested loop runs exactly `blocks` times
    // (`input_ptr` advances 16 bytes per iteration). The weight `LDR`s may be unaligned, which
    // Armv7-M supports (CCR.UNALIGN_TRP is 0 at reset; LLVM emits unaligned `LDR` for this target
    // too). Only declared registers and the flags (NZCV by `CMP`, sticky Q by `SMLAD`) change.
    unsafe {
        core::arch::asm!(
            "add {end}, {input_ptr}, {end}, lsl #4",
            "2:",
            "ldrd {xe}, {xo}, [{input_ptr}], #8",
            four_rows_four_columns!(),
            "ldrd {xe}, {xo}, [{input_ptr}], #8",
            four_rows_four_columns!(),
            "cmp {input_ptr}, {end}",
            "bne 2b",
            input_ptr = inout(reg) pairs.as_ptr() => _,
            row_0 = inout(reg) group.as_ptr() => _,
            row_2 = inout(reg) rows_2_3.as_ptr() => _,
            stride = in(reg) width,
            end = inout(reg) blocks => _,
            w = out(reg) _,
            t = out(reg) _,
            xe = out(reg) _,
            xo = out(reg) _,
            acc0 = inout(reg) acc0,
            acc1 = inout(reg) acc1,
            acc2 = inout(reg) acc2,
            acc3 = inout(reg) acc3,
            options(nostack, readonly),
        );
    }
    Some([acc0, acc1, acc2, acc3])
}

/// The first `8 * blocks` columns of the 4 rows in `group` times the int8 `input`. `None` unless
/// `group.len() == 4 * input.len()` and `1 <= blocks <= input.len() / 8`.
fn rows4_bytes(group: &[i8], input: &[i8], blocks: usize) -> Option<[i32; 4]> {
    let width = input.len();
    let columns = blocks.checked_mul(BLOCK)?;
    let in_bounds = blocks >= 1 && width.checked_mul(4) == Some(group.len()) && columns <= width;
    if !in_bounds {
        return None;
    }
    let rows_2_3 = group.get(2 * width..)?;
    let [mut acc0, mut acc1, mut acc2, mut acc3] = [0_i32; 4];
    // SAFETY: as in `rows4_pairs`, reads stay inside the borrowed slices (checked above): `input`
    // at `[0, columns)` with `columns <= width = input.len()` (unaligned `LDR`s are fine on
    // Armv7-M), and row r of `group` at `r * width + [0, columns)`. `blocks >= 1`, so the
    // bottom-tested loop runs exactly `blocks` times (`input_ptr` advances 8 bytes per
    // iteration). Only declared registers and the flags (NZCV, Q) change.
    unsafe {
        core::arch::asm!(
            "add {end}, {input_ptr}, {end}, lsl #3",
            "2:",
            "ldr {w}, [{input_ptr}], #4",
            "sxtb16 {xe}, {w}",
            "sxtb16 {xo}, {w}, ror #8",
            four_rows_four_columns!(),
            "ldr {w}, [{input_ptr}], #4",
            "sxtb16 {xe}, {w}",
            "sxtb16 {xo}, {w}, ror #8",
            four_rows_four_columns!(),
            "cmp {input_ptr}, {end}",
            "bne 2b",
            input_ptr = inout(reg) input.as_ptr() => _,
            row_0 = inout(reg) group.as_ptr() => _,
            row_2 = inout(reg) rows_2_3.as_ptr() => _,
            stride = in(reg) width,
            end = inout(reg) blocks => _,
            w = out(reg) _,
            t = out(reg) _,
            xe = out(reg) _,
            xo = out(reg) _,
            acc0 = inout(reg) acc0,
            acc1 = inout(reg) acc1,
            acc2 = inout(reg) acc2,
            acc3 = inout(reg) acc3,
            options(nostack, readonly),
        );
    }
    Some([acc0, acc1, acc2, acc3])
}
