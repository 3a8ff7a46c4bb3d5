//! The `asm!` inner loops of [`super::dsp`] (Armv7E-M / Armv8-M Mainline DSP extension), and the
//! int16-activation layers' requantization ([`scale_s64`]) and table lookup ([`lookup16`]).
//!
//! Each function checks its slice bounds before the assembly block and returns plain sums; the
//! blocks only read memory inside the borrowed slices and change only declared registers and
//! the flags (NZCV by `CMP`, the sticky Q flag by `SMLAD`). Unaligned `LDR` is fine on
//! Armv7-M/Armv8-M Mainline (CCR.UNALIGN_TRP is 0 at reset; LLVM emits unaligned loads for these
//! targets too), `LDRD` and `LDM` need word alignment: the functions refuse rows that do not start
//! on a word boundary (their callers use the portable loop there), and the pair buffer is a `u32`
//! array.

#![allow(unsafe_code)]

use super::lut16::Lut16Table;

/// Columns per step of the assembly loops.
pub(crate) const BLOCK: usize = 8;

/// Input words of eight columns into `r0..r3` as halfword pairs: `pairs` loads them (one `LDM`,
/// which needs the registers in ascending order, hence explicit `r0..r3`); `bytes` loads eight
/// int8 values with two `LDR`s and unpacks them with four `SXTB16`; `halves` loads eight int16
/// values with two `LDRD`s and reorders them with `PKHBT`/`PKHTB`.
macro_rules! input_words {
    (pairs) => {
        "ldm {xp}!, {{r0, r1, r2, r3}}\n"
    };
    (bytes) => {
        concat!(
            "ldr {wa}, [{xp}], #4\n",
            "ldr {wb}, [{xp}], #4\n",
            "sxtb16 r0, {wa}\n",
            "sxtb16 r1, {wa}, ror #8\n",
            "sxtb16 r2, {wb}\n",
            "sxtb16 r3, {wb}, ror #8\n",
        )
    };
    // Eight int16 codes (x0, x1) .. (x6, x7) by two `LDRD`s (word-aligned input), reordered to
    // (x0, x2) (x1, x3) (x4, x6) (x5, x7) with `PKHBT` / `PKHTB`; `wa`, `wb` are free here (the
    // row loads overwrite them next).
    (halves) => {
        concat!(
            "ldrd {wa}, {wb}, [{xp}], #8\n",
            "pkhbt r0, {wa}, {wb}, lsl #16\n",
            "pkhtb r1, {wb}, {wa}, asr #16\n",
            "ldrd {wa}, {wb}, [{xp}], #8\n",
            "pkhbt r2, {wa}, {wb}, lsl #16\n",
            "pkhtb r3, {wb}, {wa}, asr #16\n",
        )
    };
}

/// Eight weights of one row into `wa`, `wb` (one `LDRD`: the row must be word-aligned).
macro_rules! row_words {
    ($row:literal) => {
        concat!("ldrd {wa}, {wb}, [{", $row, "}], #8\n")
    };
}

/// `acc += wa . (r0, r1) + wb . (r2, r3)`: each weight word split by `SXTB16` /
/// `SXTB16 ROR #8` and accumulated with two `SMLAD`s.
macro_rules! accumulate {
    ($acc:literal) => {
        concat!(
            "sxtb16 {t}, {wa}\n",
            "smlad {",
            $acc,
            "}, {t}, r0, {",
            $acc,
            "}\n",
            "sxtb16 {wa}, {wa}, ror #8\n",
            "smlad {",
            $acc,
            "}, {wa}, r1, {",
            $acc,
            "}\n",
            "sxtb16 {t}, {wb}\n",
            "smlad {",
            $acc,
            "}, {t}, r2, {",
            $acc,
            "}\n",
            "sxtb16 {wb}, {wb}, ror #8\n",
            "smlad {",
            $acc,
            "}, {wb}, r3, {",
            $acc,
            "}\n",
        )
    };
}

/// Eight columns of two rows; the row pointers advance 8 bytes, the input pointer 16 (pairs,
/// halves) or 8 (bytes).
macro_rules! two_rows_eight_columns {
    ($input:ident) => {
        concat!(
            input_words!($input),
            row_words!("row_0"),
            accumulate!("acc0"),
            row_words!("row_1"),
            accumulate!("acc1"),
        )
    };
}

/// The whole two-row product as one `asm!` block: a loop of four steps per iteration, entered
/// through a `TBB` jump table at the step that leaves a multiple of four (`blocks % 4` steps in
/// the first pass), so that the loop branch runs once per four steps; `xp` advances
/// `1 << $shift` bytes per step up to the end computed first. The jump depends on the width only.
macro_rules! two_row_asm {
    ($input:ident, $shift:literal, $blocks:expr, $xp:expr, $r0:expr, $r1:expr, $acc0:ident, $acc1:ident) => {
        core::arch::asm!(
            // The Armv8-M Mainline and Armv8.1-M targets leave the (optional) DSP extension off;
            // every instruction here is Armv7E-M, encoded alike on those cores.
            ".arch armv7e-m",
            "and {t}, {n}, #3",
            concat!("add {n}, {xp}, {n}, lsl #", $shift),
            "tbb [pc, {t}]",
            "0:",
            ".byte (4f - 0b) / 2",
            ".byte (7f - 0b) / 2",
            ".byte (6f - 0b) / 2",
            ".byte (5f - 0b) / 2",
            "4:",
            two_rows_eight_columns!($input),
            "5:",
            two_rows_eight_columns!($input),
            "6:",
            two_rows_eight_columns!($input),
            "7:",
            two_rows_eight_columns!($input),
            "cmp {xp}, {n}",
            "bne 4b",
            n = inout(reg) $blocks => _,
            xp = inout(reg) $xp => _,
            row_0 = inout(reg) $r0 => _,
            row_1 = inout(reg) $r1 => _,
            wa = out(reg) _,
            wb = out(reg) _,
            t = out(reg) _,
            acc0 = inout(reg) $acc0,
            acc1 = inout(reg) $acc1,
            out("r0") _,
            out("r1") _,
            out("r2") _,
            out("r3") _,
            options(nostack, readonly),
        )
    };
}

/// Where the input comes from for [`row_pairs`].
#[derive(Clone, Copy)]
pub(crate) enum Input<'a> {
    /// Halfword pairs (see `dsp::Prepared`), at least `4 * blocks` words.
    Pairs(&'a [u32]),
    /// int8 codes unpacked in the loop, at least `8 * blocks` of them.
    Bytes(&'a [i8]),
    /// int16 codes reordered in the loop, at least `8 * blocks` of them, word-aligned (`LDRD`).
    Halves(&'a [i16]),
}

/// `out[k] = start[k] + (rows 2k and 2k+1 of `rows`) . x` over the first `8 * blocks` columns, for
/// every `k < out.len()`; `rows` is row-major with `width` columns (row `r` starts at `r * width`;
/// the last row only needs its first `8 * blocks` bytes, so `rows` may start inside a row, at a
/// chunk of columns). Returns `false` (and leaves `out` alone) unless `1 <= blocks`,
/// `8 * blocks <= width`, `width` is a multiple of 4, `rows` starts on a word boundary (`LDRD`
/// faults otherwise), `rows` holds the `2 * out.len()` rows so far, `start` has `out.len()`
/// entries and the input is long enough (and word-aligned, for `Halves`). Not inlined: its loop
/// keeps few values live around the assembly block, which needs 13 registers.
#[inline(never)]
pub(crate) fn row_pairs(
    rows: &[i8],
    width: usize,
    input: Input<'_>,
    blocks: usize,
    start: &[[i32; 2]],
    out: &mut [[i32; 2]],
) -> bool {
    let columns = blocks.saturating_mul(BLOCK);
    let (input_len, input_aligned) = match input {
        Input::Pairs(pairs) => (pairs.len().saturating_mul(2), true),
        Input::Bytes(bytes) => (bytes.len(), true),
        Input::Halves(halves) => (halves.len(), (halves.as_ptr() as usize).is_multiple_of(4)),
    };
    // The last row's last byte read is at (2 out.len() - 1) width + columns.
    let rows_fit = match (out.len().checked_mul(2)).and_then(|n| n.checked_sub(1)) {
        None => true,
        Some(last_row) => last_row
            .checked_mul(width)
            .and_then(|offset| offset.checked_add(columns))
            .is_some_and(|len| len <= rows.len()),
    };
    let ok = blocks >= 1
        && columns <= width
        && columns <= input_len
        && input_aligned
        && width.is_multiple_of(4)
        && (rows.as_ptr() as usize).is_multiple_of(4)
        && start.len() >= out.len()
        && rows_fit;
    if !ok {
        return false;
    }
    let mut row_0 = rows.as_ptr();
    for (sums, bias) in out.iter_mut().zip(start) {
        let row_1 = row_0.wrapping_add(width);
        let [mut acc0, mut acc1] = *bias;
        // SAFETY: rows `2k` and `2k + 1` start at `row_0` and `row_1` (offsets `2k width` and
        // `(2k + 1) width`) on word boundaries (`rows` is word-aligned and `width` a multiple of
        // 4), as `LDRD` needs; the block reads bytes [0, 8 blocks) of each row, which end at most
        // at `(2 out.len() - 1) width + 8 blocks <= rows.len()` (checked above), and the input's
        // first `8 blocks` columns (`4 blocks` words of a `u32` slice, aligned for `LDM`;
        // `8 blocks` bytes by `LDR`, which may be unaligned; or `8 blocks` halfwords of a
        // word-aligned `i16` slice by `LDRD`), all inside the borrowed slices. It runs `blocks`
        // eight-column steps in all (`blocks % 4` in the first pass, then four per pass).
        unsafe {
            match input {
                Input::Pairs(pairs) => {
                    two_row_asm!(pairs, "4", blocks, pairs.as_ptr(), row_0, row_1, acc0, acc1)
                }
                Input::Bytes(bytes) => {
                    two_row_asm!(bytes, "3", blocks, bytes.as_ptr(), row_0, row_1, acc0, acc1)
                }
                Input::Halves(halves) => {
                    two_row_asm!(
                        halves,
                        "4",
                        blocks,
                        halves.as_ptr(),
                        row_0,
                        row_1,
                        acc0,
                        acc1
                    )
                }
            }
        }
        *sums = [acc0, acc1];
        row_0 = row_0.wrapping_add(2 * width);
    }
    true
}

/// `quant::requantize_s64` of one int64 accumulator up to its clamp: the Q15 multiplier
/// `usat15((M >> 16) + bit15(M))`, `p = acc * m15` (`UMULL` + `MLA`, modulo 2^64), the arithmetic
/// shift by `n = (14 - shift) mod 64` and the saturation to int32 (register-specified shifts give
/// 0 for `LSL`/`LSR` and the sign for `ASR` at 32 and more, so the only condition is `n >= 32`,
/// the channel's, not the data's), then `(s >> 1) + (s & 1)`. 22 instructions, no branch, no
/// memory access; LLVM's form of the same Rust took about 35 (64-bit compare chains for the
/// saturation).
#[inline(always)]
pub(crate) fn scale_s64(acc: i64, multiplier: i32, shift: i32) -> i32 {
    let low = acc as u32;
    let high = (acc >> 32) as u32;
    let out: i32;
    // SAFETY: register arithmetic only (no memory access, no stack); it changes only the declared
    // registers and the flags.
    unsafe {
        core::arch::asm!(
            ".arch armv7e-m",
            // m15 in `m` (the multiplier's register).
            "ubfx {t}, {m}, #15, #1",
            "asr {m}, {m}, #16",
            "add {m}, {m}, {t}",
            "usat {m}, #15, {m}",
            // (hi:lo) = acc * m15 modulo 2^64.
            "umull {lo}, {t}, {lo}, {m}",
            "mla {hi}, {hi}, {m}, {t}",
            // n = (14 - shift) mod 64 in `n` (the shift's register).
            "rsb {n}, {n}, #14",
            "and {n}, {n}, #63",
            // q = (hi:lo) >> n: its low word in a, its high word in t.
            "lsr {a}, {lo}, {n}",
            "rsb {t}, {n}, #32",
            "lsl {t}, {hi}, {t}",
            "orr {a}, {a}, {t}",
            "subs {t}, {n}, #32",
            "it pl",
            "asrpl {a}, {hi}, {t}",
            "asr {t}, {hi}, {n}",
            // sat32(q): keep a if the high word is its sign, else (sign ^ i32::MAX).
            "cmp {t}, {a}, asr #31",
            "itt ne",
            "mvnne {a}, #0x80000000",
            "eorne {a}, {a}, {t}, asr #31",
            // (s >> 1) + (s & 1).
            "and {t}, {a}, #1",
            "add {a}, {t}, {a}, asr #1",
            m = inout(reg) multiplier => _,
            n = inout(reg) shift => _,
            lo = inout(reg) low => _,
            hi = inout(reg) high => _,
            t = out(reg) _,
            a = out(reg) out,
            options(pure, nomem, nostack),
        );
    }
    out
}

/// `lut16::lookup(table, x)` with one unaligned `LDR` of the knot pair `(t[i], t[i+1])` and one
/// `SMLAD` against `(128 - f, f)` with 64 added: `(t[i] (128 - f) + t[i+1] f + 64) >> 7`, 8
/// instructions in 5 registers.
#[inline(always)]
pub(crate) fn lookup16(table: &Lut16Table, x: i16) -> i16 {
    let y: i32;
    // SAFETY: `x` is a sign-extended int16, so the index `(x >> 7) + 256` is in 0..=511 and the
    // word read at byte offset `2 index <= 1022` ends at byte 1026 at most, inside the 1026-byte
    // table; unaligned `LDR` is allowed on these cores (see the module documentation). Nothing
    // else is read or written.
    unsafe {
        core::arch::asm!(
            ".arch armv7e-m",
            "asr {i}, {x}, #7",
            "add {i}, {i}, #256",
            "ldr {p}, [{t}, {i}, lsl #1]",
            // f in x, (128 - f, f) in i.
            "and {x}, {x}, #127",
            "rsb {i}, {x}, #128",
            "orr {i}, {i}, {x}, lsl #16",
            "smlad {p}, {p}, {i}, {c}",
            "asr {p}, {p}, #7",
            x = inout(reg) i32::from(x) => _,
            t = in(reg) table.as_ptr(),
            c = in(reg) 64_i32,
            i = out(reg) _,
            p = out(reg) y,
            options(pure, readonly, nostack),
        );
    }
    y as i16
}
