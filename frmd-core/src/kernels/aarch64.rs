//! Row kernels for aarch64 (Linux Arm controllers: the Raspberry Pi 5's Cortex-A76, Jetson
//! CPUs), for `super::rows::for_each_block`.
//!
//! Four rows share each 16-column load of the input; each 16-column step is one `asm!` block, so
//! the instruction selection is fixed. int8 inputs: with the dot-product extension
//! (`FEAT_DotProd`, Armv8.2 and later cores) one `SDOT` adds 16 products into a row's four int32
//! lanes (9 instructions per 64 products); without it, every aarch64 core has `SMULL`/`SMULL2`
//! (exact int16 products of int8 codes, each in `[-16256, 16384]`) and `SADALP` (pairwise into
//! the int32 lanes; 21 per 64). int16 inputs (the 16-bit first-layer plane and the
//! int16-activation layers): the weights are sign-extended (`SXTL`/`SXTL2`) and
//! `SMLAL`/`SMLAL2` multiply-accumulate into int32 lanes (29 per 64). Each row's lanes are summed
//! at the end (`ADDV`) and the last `columns % 16` columns, and the last `rows % 4` rows, are
//! added in Rust.
//!
//! Bit-exactness: every lane adds exact products modulo 2^32, as the portable loop does, and
//! wrapping int32 addition is associative and commutative, so every path gives the portable sums
//! for every input (tested against the wide sums on random shapes at every level by
//! `tests/row_kernels.rs`, and by the digests that `scripts/aarch64.sh` compares with x86-64's;
//! both run under `qemu-aarch64`). The `SMMLA` of `FEAT_I8MM` is not used: its 2x2
//! output tile needs two input vectors, and at batch 1 half of its products would be wasted,
//! which leaves it at `SDOT`'s 16 useful products per instruction.
//!
//! Run-time choice: NEON is part of the aarch64 baseline; `SDOT` is used when the target enables
//! `dotprod` at compile time (`-C target-cpu=cortex-a76`) or, on Linux, when the kernel reports
//! it (`getauxval(AT_HWCAP) & HWCAP_ASIMDDP`, as std's feature detection reads it; frmd-core
//! stays `no_std` and links only that libc symbol). [`set_neon_enabled`] and
//! [`set_dotprod_enabled`] switch the paths process-wide for A/B measurements and the agreement
//! checks.
#![allow(unsafe_code)]

use super::dot::RowInput;
use core::arch::aarch64::{int32x4_t, vaddvq_s32, vdupq_n_s32};
use core::ops::Range;

use super::switch::KernelSwitch;

/// Rows per pass.
const ROWS: usize = 4;
/// Columns per vector step.
const LANES: usize = 16;

static NEON: KernelSwitch = KernelSwitch::baseline();
static DOTPROD: KernelSwitch = KernelSwitch::probed(detect_dotprod);

/// Whether the row kernels use NEON (otherwise the portable loops). On by default.
#[inline]
pub fn neon_active() -> bool {
    NEON.active()
}

/// Switches the NEON row kernels on or off, process-wide (off: the portable loops, which give
/// the same sums); returns whether they are active afterwards.
pub fn set_neon_enabled(enabled: bool) -> bool {
    NEON.set(enabled)
}

/// Whether this CPU has the dot-product instructions (`SDOT`).
pub fn dotprod_supported() -> bool {
    DOTPROD.supported()
}

/// Whether the int8 row kernels use `SDOT` (only while NEON is active).
#[inline]
pub fn dotprod_active() -> bool {
    DOTPROD.active()
}

/// Enables (if supported) or disables the `SDOT` path, process-wide; returns whether it is
/// active afterwards. Both int8 paths give identical sums.
pub fn set_dotprod_enabled(enabled: bool) -> bool {
    DOTPROD.set(enabled)
}

#[cfg(target_feature = "dotprod")]
fn detect_dotprod() -> bool {
    true
}

#[cfg(all(not(target_feature = "dotprod"), target_os = "linux"))]
fn detect_dotprod() -> bool {
    use core::ffi::c_ulong;
    const AT_HWCAP: c_ulong = 16;
    const HWCAP_ASIMDDP: c_ulong = 1 << 20;
    extern "C" {
        fn getauxval(kind: c_ulong) -> c_ulong;
    }
    // SAFETY: getauxval (glibc >= 2.16, musl, bionic) only reads the process's auxiliary vector;
    // for a type it does not know it returns 0.
    unsafe { getauxval(AT_HWCAP) & HWCAP_ASIMDDP != 0 }
}

#[cfg(all(not(target_feature = "dotprod"), not(target_os = "linux")))]
fn detect_dotprod() -> bool {
    false
}

/// `sums[r] = start[r] + dot(row_r[columns], input[columns])` (int32, wrapping; missing `start`
/// entries count as 0) for the first `sums.len()` rows of `rows` (`input.len()` columns each),
/// as `rows::portable_block_sums` computes them (which `rows` calls instead while
/// [`neon_active`] is false).
#[inline]
pub(crate) fn block_sums<T: RowInput>(
    input: &[T],
    rows: &[i8],
    columns: Range<usize>,
    start: &[i32],
    sums: &mut [i32],
) {
    let width = input.len();
    let chunk = input.get(columns.clone()).unwrap_or(&[]);
    let row_slices = rows
        .chunks_exact(width)
        .map(|row| row.get(columns.clone()).unwrap_or(&[]));
    let rest_dot = |row: &[i8]| T::dot(row, chunk);
    match (T::as_i8(chunk), T::as_i16(chunk)) {
        (Some(x), _) => {
            let dotprod = dotprod_active();
            by_four(x, row_slices, start, sums, rest_dot, |w| {
                if dotprod {
                    // SAFETY: the CPU has FEAT_DotProd (`dotprod_active`); `by_four` passes only
                    // rows of `x.len()` elements.
                    unsafe { dots_i8_sdot(w, x) }
                } else {
                    // SAFETY: NEON is part of the aarch64 baseline; rows as above.
                    unsafe { dots_i8_neon(w, x) }
                }
            });
        }
        (None, Some(x)) => {
            // SAFETY: NEON is part of the aarch64 baseline; `by_four` passes only rows of
            // `x.len()` elements.
            let dots = |w| unsafe { dots_i16_neon(w, x) };
            by_four(x, row_slices, start, sums, rest_dot, dots);
        }
        (None, None) => {}
    }
}

/// `sums[r] = start[r] + dot(row_r, x)`: whole groups of four rows by `dots` (called only with
/// rows as long as `x`; others by a scalar loop), the last `sums.len() % 4` rows by `rest_dot`.
#[inline(always)]
fn by_four<'a, X: Copy + Into<i32>>(
    x: &[X],
    mut row_slices: impl Iterator<Item = &'a [i8]>,
    start: &[i32],
    sums: &mut [i32],
    rest_dot: impl Fn(&[i8]) -> i32,
    dots: impl Fn([&'a [i8]; ROWS]) -> [i32; ROWS],
) {
    let mut starts = start.iter().copied().chain(core::iter::repeat(0));
    let (groups, rest) = sums.as_chunks_mut::<ROWS>();
    for group in groups {
        let w: [&[i8]; ROWS] = core::array::from_fn(|_| row_slices.next().unwrap_or(&[]));
        let sums = if w.iter().all(|row| row.len() == x.len()) {
            dots(w)
        } else {
            w.map(|row| row.iter().zip(x).fold(0_i32, wide_step))
        };
        for (sum, dot) in group.iter_mut().zip(sums) {
            *sum = starts.next().unwrap_or(0).wrapping_add(dot);
        }
    }
    for sum in rest {
        let row = row_slices.next().unwrap_or(&[]);
        *sum = starts.next().unwrap_or(0).wrapping_add(rest_dot(row));
    }
}

/// `sum + w * x` (int32, wrapping) for an int8 or int16 input code.
#[inline(always)]
fn wide_step<X: Copy + Into<i32>>(sum: i32, (w, x): (&i8, &X)) -> i32 {
    sum.wrapping_add(i32::from(*w) * (*x).into())
}

/// The four rows' sums of the last `x.len() % 16` columns added to their vector lanes.
#[target_feature(enable = "neon")]
fn finish<X: Copy + Into<i32>>(acc: [int32x4_t; ROWS], w: [&[i8]; ROWS], x: &[X]) -> [i32; ROWS] {
    let head = x.len() - x.len() % LANES;
    let x_tail = x.get(head..).unwrap_or(&[]);
    core::array::from_fn(|r| {
        let lanes = acc.get(r).map_or(0, |lanes| vaddvq_s32(*lanes));
        let row_tail = w.get(r).and_then(|row| row.get(head..)).unwrap_or(&[]);
        row_tail.iter().zip(x_tail).fold(lanes, wide_step)
    })
}

/// Four int8 rows times an int8 vector with `SMULL`/`SMULL2` + `SADALP`: per 16 columns one
/// input load, and per row one load, two multiplies and two pairwise accumulations.
///
/// # Safety
/// Every row must have `x.len()` elements.
#[target_feature(enable = "neon")]
unsafe fn dots_i8_neon(w: [&[i8]; ROWS], x: &[i8]) -> [i32; ROWS] {
    let [mut a0, mut a1, mut a2, mut a3] = [vdupq_n_s32(0); ROWS];
    let [w0, w1, w2, w3] = w.map(<[i8]>::as_ptr);
    let xp = x.as_ptr();
    for offset in (0..x.len() / LANES).map(|b| b * LANES) {
        // SAFETY: `offset + 16 <= x.len()` and every row is as long as `x` (the caller's
        // contract); the instructions are baseline NEON and touch no other memory.
        unsafe {
            core::arch::asm!(
                "ldr {x:q}, [{xp}, {o}]",
                "ldr {v0:q}, [{w0}, {o}]",
                "ldr {v1:q}, [{w1}, {o}]",
                "ldr {v2:q}, [{w2}, {o}]",
                "ldr {v3:q}, [{w3}, {o}]",
                "smull {p0:v}.8h, {v0:v}.8b, {x:v}.8b",
                "smull2 {v0:v}.8h, {v0:v}.16b, {x:v}.16b",
                "smull {p1:v}.8h, {v1:v}.8b, {x:v}.8b",
                "smull2 {v1:v}.8h, {v1:v}.16b, {x:v}.16b",
                "sadalp {a0:v}.4s, {p0:v}.8h",
                "sadalp {a1:v}.4s, {p1:v}.8h",
                "smull {p0:v}.8h, {v2:v}.8b, {x:v}.8b",
                "smull2 {v2:v}.8h, {v2:v}.16b, {x:v}.16b",
                "smull {p1:v}.8h, {v3:v}.8b, {x:v}.8b",
                "smull2 {v3:v}.8h, {v3:v}.16b, {x:v}.16b",
                "sadalp {a0:v}.4s, {v0:v}.8h",
                "sadalp {a1:v}.4s, {v1:v}.8h",
                "sadalp {a2:v}.4s, {p0:v}.8h",
                "sadalp {a3:v}.4s, {p1:v}.8h",
                "sadalp {a2:v}.4s, {v2:v}.8h",
                "sadalp {a3:v}.4s, {v3:v}.8h",
                xp = in(reg) xp,
                w0 = in(reg) w0,
                w1 = in(reg) w1,
                w2 = in(reg) w2,
                w3 = in(reg) w3,
                o = in(reg) offset,
                x = out(vreg) _,
                v0 = out(vreg) _,
                v1 = out(vreg) _,
                v2 = out(vreg) _,
                v3 = out(vreg) _,
                p0 = out(vreg) _,
                p1 = out(vreg) _,
                a0 = inout(vreg) a0,
                a1 = inout(vreg) a1,
                a2 = inout(vreg) a2,
                a3 = inout(vreg) a3,
                options(pure, readonly, nostack, preserves_flags),
            );
        }
    }
    finish([a0, a1, a2, a3], w, x)
}

/// [`dots_i8_neon`] with `SDOT` (16 products per instruction).
///
/// # Safety
/// The CPU must implement FEAT_DotProd; every row must have `x.len()` elements.
#[target_feature(enable = "neon,dotprod")]
unsafe fn dots_i8_sdot(w: [&[i8]; ROWS], x: &[i8]) -> [i32; ROWS] {
    let [mut a0, mut a1, mut a2, mut a3] = [vdupq_n_s32(0); ROWS];
    let [w0, w1, w2, w3] = w.map(<[i8]>::as_ptr);
    let xp = x.as_ptr();
    for offset in (0..x.len() / LANES).map(|b| b * LANES) {
        // SAFETY: `offset + 16 <= x.len()` and every row is as long as `x` (the caller's
        // contract); `sdot` needs FEAT_DotProd (the caller's contract) and touches no memory.
        unsafe {
            core::arch::asm!(
                "ldr {x:q}, [{xp}, {o}]",
                "ldr {v0:q}, [{w0}, {o}]",
                "ldr {v1:q}, [{w1}, {o}]",
                "ldr {v2:q}, [{w2}, {o}]",
                "ldr {v3:q}, [{w3}, {o}]",
                "sdot {a0:v}.4s, {v0:v}.16b, {x:v}.16b",
                "sdot {a1:v}.4s, {v1:v}.16b, {x:v}.16b",
                "sdot {a2:v}.4s, {v2:v}.16b, {x:v}.16b",
                "sdot {a3:v}.4s, {v3:v}.16b, {x:v}.16b",
                xp = in(reg) xp,
                w0 = in(reg) w0,
                w1 = in(reg) w1,
                w2 = in(reg) w2,
                w3 = in(reg) w3,
                o = in(reg) offset,
                x = out(vreg) _,
                v0 = out(vreg) _,
                v1 = out(vreg) _,
                v2 = out(vreg) _,
                v3 = out(vreg) _,
                a0 = inout(vreg) a0,
                a1 = inout(vreg) a1,
                a2 = inout(vreg) a2,
                a3 = inout(vreg) a3,
                options(pure, readonly, nostack, preserves_flags),
            );
        }
    }
    finish([a0, a1, a2, a3], w, x)
}

/// Four int8 rows times an int16 vector: per 16 columns two input loads, and per row one load,
/// two sign extensions (`SXTL`/`SXTL2`) and four `SMLAL`/`SMLAL2` into int32 lanes (modulo 2^32).
///
/// # Safety
/// Every row must have `x.len()` elements.
#[target_feature(enable = "neon")]
unsafe fn dots_i16_neon(w: [&[i8]; ROWS], x: &[i16]) -> [i32; ROWS] {
    let [mut a0, mut a1, mut a2, mut a3] = [vdupq_n_s32(0); ROWS];
    let [w0, w1, w2, w3] = w.map(<[i8]>::as_ptr);
    let xp = x.as_ptr();
    for offset in (0..x.len() / LANES).map(|b| b * LANES) {
        // SAFETY: `offset + 16 <= x.len()` (32 input bytes from `2 * offset`) and every row is
        // as long as `x` (the caller's contract); baseline NEON, no other memory.
        unsafe {
            core::arch::asm!(
                "ldp {x0:q}, {x1:q}, [{xp}]",
                "ldr {v0:q}, [{w0}, {o}]",
                "ldr {v1:q}, [{w1}, {o}]",
                "sxtl {l:v}.8h, {v0:v}.8b",
                "sxtl2 {h:v}.8h, {v0:v}.16b",
                "sxtl {v0:v}.8h, {v1:v}.8b",
                "sxtl2 {v1:v}.8h, {v1:v}.16b",
                "smlal {a0:v}.4s, {l:v}.4h, {x0:v}.4h",
                "smlal2 {a0:v}.4s, {l:v}.8h, {x0:v}.8h",
                "smlal {a0:v}.4s, {h:v}.4h, {x1:v}.4h",
                "smlal2 {a0:v}.4s, {h:v}.8h, {x1:v}.8h",
                "smlal {a1:v}.4s, {v0:v}.4h, {x0:v}.4h",
                "smlal2 {a1:v}.4s, {v0:v}.8h, {x0:v}.8h",
                "smlal {a1:v}.4s, {v1:v}.4h, {x1:v}.4h",
                "smlal2 {a1:v}.4s, {v1:v}.8h, {x1:v}.8h",
                "ldr {v0:q}, [{w2}, {o}]",
                "ldr {v1:q}, [{w3}, {o}]",
                "sxtl {l:v}.8h, {v0:v}.8b",
                "sxtl2 {h:v}.8h, {v0:v}.16b",
                "sxtl {v0:v}.8h, {v1:v}.8b",
                "sxtl2 {v1:v}.8h, {v1:v}.16b",
                "smlal {a2:v}.4s, {l:v}.4h, {x0:v}.4h",
                "smlal2 {a2:v}.4s, {l:v}.8h, {x0:v}.8h",
                "smlal {a2:v}.4s, {h:v}.4h, {x1:v}.4h",
                "smlal2 {a2:v}.4s, {h:v}.8h, {x1:v}.8h",
                "smlal {a3:v}.4s, {v0:v}.4h, {x0:v}.4h",
                "smlal2 {a3:v}.4s, {v0:v}.8h, {x0:v}.8h",
                "smlal {a3:v}.4s, {v1:v}.4h, {x1:v}.4h",
                "smlal2 {a3:v}.4s, {v1:v}.8h, {x1:v}.8h",
                xp = in(reg) xp.add(offset),
                w0 = in(reg) w0,
                w1 = in(reg) w1,
                w2 = in(reg) w2,
                w3 = in(reg) w3,
                o = in(reg) offset,
                x0 = out(vreg) _,
                x1 = out(vreg) _,
                v0 = out(vreg) _,
                v1 = out(vreg) _,
                l = out(vreg) _,
                h = out(vreg) _,
                a0 = inout(vreg) a0,
                a1 = inout(vreg) a1,
                a2 = inout(vreg) a2,
                a3 = inout(vreg) a3,
                options(pure, readonly, nostack, preserves_flags),
            );
        }
    }
    finish([a0, a1, a2, a3], w, x)
}
