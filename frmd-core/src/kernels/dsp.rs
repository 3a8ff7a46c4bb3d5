//! int8 matrix-vector inner loop for Arm cores with the DSP extension (Cortex-M4/M7, Armv7E-M).
//!
//! Compiled only with `cfg(frmd_arm_dsp)` (set by `build.rs`); every other target uses the
//! portable [`super::dot::dot_i8_prefix`]. This is the only module of frmd-core with `unsafe`: one
//! `asm!` block that reads the weight rows and the input, and touches nothing else.
//!
//! Per 4 columns the loop loads one input word and sign-extends it into two halfword pairs,
//! `xe = (x0, x2)` and `xo = (x1, x3)` (`SXTB16`, `SXTB16 ROR #8`); then for each of 4 rows it
//! loads one weight word, extends it the same way and accumulates both pairs with `SMLAD`
//! (`acc += w0*x0 + w2*x2`, `acc += w1*x1 + w3*x3`). That is 23 instructions per 16
//! multiply-accumulates, plus `CMP`/`BNE` per 8 columns: 48 per 32, 1.5 per MAC.
//!
//! Bit-exactness: every product of two int8 values fits a halfword product, the pair sum fits in
//! 32 bits, and `SMLAD` adds it to the accumulator modulo 2^32 (on signed overflow it only sets
//! the sticky Q flag). Wrapping int32 addition is associative and commutative, so the sums equal
//! the portable kernel's for every input.

#![allow(unsafe_code)]

use super::dot::dot_i8_rows4_portable;

/// Columns per loop iteration of the assembly block.
const BLOCK: usize = 8;

/// `[dot(row_r, input) for r in 0..4]` for the four consecutive rows stored row-major in `rows`
/// (each `input.len()` long), int32 wrapping sums.
///
/// Falls back to the portable kernel when `rows` is shorter than `4 * input.len()` (the caller
/// never does that) so the function has no failure mode.
pub(crate) fn dot_i8_rows4(rows: &[i8], input: &[i8]) -> [i32; 4] {
    let width = input.len();
    if width == 0 {
        return [0; 4];
    }
    let group = width.checked_mul(4).and_then(|len| rows.get(..len));
    let (Some(group), Some(rows_2_3)) = (group, rows.get(width.saturating_mul(2)..)) else {
        return fallback(rows, input);
    };
    let blocks = width / BLOCK;
    let mut acc = [0_i32; 4];
    if blocks > 0 {
        let [mut acc0, mut acc1, mut acc2, mut acc3] = acc;
        // SAFETY: the block only reads memory, and only inside the borrowed slices:
        // - `input` at `input_ptr + [0, 8 * blocks)`, and `8 * blocks <= width = input.len()`;
        // - row r of `group` (`group.len() == 4 * width`) at `row_0 + r * width + [0, 8 * blocks)`:
        //   rows 0 and 1 through `row_0` (`[row_0]`, `[row_0, stride]`), rows 2 and 3 through
        //   `row_2 = row_0 + 2 * width` (`rows_2_3` starts there); each row read stays below
        //   `r * width + width <= group.len()`.
        // `blocks >= 1`, so `end > input_ptr` and the loop (which tests at the bottom) stops after
        // exactly `blocks` iterations, when `input_ptr` has advanced by `8 * blocks`.
        // The word loads may be unaligned: Armv7-M `LDR` supports that (CCR.UNALIGN_TRP is 0 at
        // reset, and LLVM itself emits unaligned `LDR` for this target). Only declared registers
        // and the flags (NZCV by `CMP`, sticky Q by `SMLAD`) are written; no stack is used.
        unsafe {
            core::arch::asm!(
                "add {end}, {input_ptr}, {end}, lsl #3",
                "2:",
                // Columns 0..4 of the block.
                "ldr {w}, [{input_ptr}], #4",
                "sxtb16 {xe}, {w}",
                "sxtb16 {xo}, {w}, ror #8",
                "ldr {w}, [{row_0}, {stride}]",
                "sxtb16 {t}, {w}",
                "smlad {acc1}, {t}, {xe}, {acc1}",
                "sxtb16 {w}, {w}, ror #8",
                "smlad {acc1}, {w}, {xo}, {acc1}",
                "ldr {w}, [{row_0}], #4",
                "sxtb16 {t}, {w}",
                "smlad {acc0}, {t}, {xe}, {acc0}",
                "sxtb16 {w}, {w}, ror #8",
                "smlad {acc0}, {w}, {xo}, {acc0}",
                "ldr {w}, [{row_2}, {stride}]",
                "sxtb16 {t}, {w}",
                "smlad {acc3}, {t}, {xe}, {acc3}",
                "sxtb16 {w}, {w}, ror #8",
                "smlad {acc3}, {w}, {xo}, {acc3}",
                "ldr {w}, [{row_2}], #4",
                "sxtb16 {t}, {w}",
                "smlad {acc2}, {t}, {xe}, {acc2}",
                "sxtb16 {w}, {w}, ror #8",
                "smlad {acc2}, {w}, {xo}, {acc2}",
                // Columns 4..8 of the block (the pointers have advanced by 4).
                "ldr {w}, [{input_ptr}], #4",
                "sxtb16 {xe}, {w}",
                "sxtb16 {xo}, {w}, ror #8",
                "ldr {w}, [{row_0}, {stride}]",
                "sxtb16 {t}, {w}",
                "smlad {acc1}, {t}, {xe}, {acc1}",
                "sxtb16 {w}, {w}, ror #8",
                "smlad {acc1}, {w}, {xo}, {acc1}",
                "ldr {w}, [{row_0}], #4",
                "sxtb16 {t}, {w}",
                "smlad {acc0}, {t}, {xe}, {acc0}",
                "sxtb16 {w}, {w}, ror #8",
                "smlad {acc0}, {w}, {xo}, {acc0}",
                "ldr {w}, [{row_2}, {stride}]",
                "sxtb16 {t}, {w}",
                "smlad {acc3}, {t}, {xe}, {acc3}",
                "sxtb16 {w}, {w}, ror #8",
                "smlad {acc3}, {w}, {xo}, {acc3}",
                "ldr {w}, [{row_2}], #4",
                "sxtb16 {t}, {w}",
                "smlad {acc2}, {t}, {xe}, {acc2}",
                "sxtb16 {w}, {w}, ror #8",
                "smlad {acc2}, {w}, {xo}, {acc2}",
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
        acc = [acc0, acc1, acc2, acc3];
    }
    let head = blocks * BLOCK;
    let input_tail = input.get(head..).unwrap_or(&[]);
    // The last `width % 8` columns (fewer than 8, so a plain loop).
    for (sum, row) in acc.iter_mut().zip(group.chunks_exact(width)) {
        let row_tail = row.get(head..).unwrap_or(&[]);
        for (weight, x) in row_tail.iter().zip(input_tail) {
            *sum = sum.wrapping_add(i32::from(*weight) * i32::from(*x));
        }
    }
    acc
}

/// Out-of-line portable path for malformed arguments (keeps the hot function small).
#[cold]
#[inline(never)]
fn fallback(rows: &[i8], input: &[i8]) -> [i32; 4] {
    dot_i8_rows4_portable(rows, input)
}
