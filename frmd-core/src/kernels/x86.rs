//! AVX2 int8 matrix-vector kernel for x86-64, chosen at run time; the portable kernel of
//! `kernels::matvec` (SSE2 `pmaddwd` through LLVM) is the fallback.
//!
//! Four weight rows per pass (the block splitting of `matvec::for_each_row_block`); per 16 input
//! columns the input is loaded and sign-extended to 16 halfwords once (`vpmovsxbw`), and for each
//! row one `vpmovsxbw` of 16 weights, one `vpmaddwd` (16 products summed in pairs into 8 int32
//! lanes) and one `vpaddd`: 13 instructions per 64 multiply-accumulates. The last `columns % 16`
//! columns use [`dot_i8_prefix`].
//!
//! Bit-exactness: an int8 x int8 product lies in `[-16256, 16384]`, so a `vpmaddwd` pair sum
//! (at most 32768 in magnitude) is exact in int32; `vpaddd` and `vphaddd` add modulo 2^32. Every
//! row sum is therefore the wrapping int32 sum of the same products as the portable kernel, and
//! wrapping addition does not depend on order. The tests compare both on random shapes.
//!
//! Detection is `no_std`: `CPUID` leaf 1 (AVX and OSXSAVE bits), `XGETBV` (the OS saves the
//! SSE and AVX register state: XCR0 bits 1 and 2) and `CPUID` leaf 7 (AVX2 bit), cached in an
//! atomic. [`set_avx2_enabled`] turns the AVX2 path off (or back on, if the CPU has it) for
//! A/B measurements.
//!
//! Safety audit (the only `unsafe` besides `kernels::dsp`), three kinds of `unsafe` expression:
//! - `_xgetbv(0)`: requires the `XGETBV` instruction, which exists when `CPUID.1:ECX.OSXSAVE`
//!   (bit 27) is set; it is called only after checking that bit.
//! - calls of the `#[target_feature(enable = "avx2")]` function [`dot_four_rows_avx2`]: sound when
//!   the CPU supports AVX2 and the OS enabled the AVX state, which is what [`avx2_active`]
//!   checked (the cached state only becomes "active" through [`detect_avx2`]).
//! - `_mm_loadu_si128` in [`widen`]: an unaligned 16-byte read through a pointer made from a
//!   `&[i8; 16]`, so all 16 bytes are in bounds and initialized.
//!
//! No other memory is touched: weights and input are walked with `as_chunks::<16>` iterators.
#![allow(unsafe_code)]

use super::dot::dot_i8_prefix;
use super::matvec::{for_each_row_block, for_each_row_dot_portable, ROWS};
use core::arch::x86_64::{
    __cpuid, __cpuid_count, __m128i, __m256i, _mm256_add_epi32, _mm256_castsi256_si128,
    _mm256_cvtepi8_epi16, _mm256_extracti128_si256, _mm256_hadd_epi32, _mm256_madd_epi16,
    _mm256_setzero_si256, _mm_add_epi32, _mm_cvtsi128_si32, _mm_extract_epi32, _mm_loadu_si128,
    _xgetbv,
};
use core::sync::atomic::{AtomicU8, Ordering};

/// Detection state: not yet probed.
const UNKNOWN: u8 = 0;
/// The CPU and OS support AVX2 and the path is enabled.
const ACTIVE: u8 = 1;
/// AVX2 is unsupported, or disabled by [`set_avx2_enabled`].
const INACTIVE: u8 = 2;

static AVX2_STATE: AtomicU8 = AtomicU8::new(UNKNOWN);

/// Whether the CPU and the OS support AVX2 (probed once with `CPUID`/`XGETBV`).
pub fn avx2_supported() -> bool {
    detect_avx2()
}

/// Whether the int8 kernels currently use the AVX2 build.
#[inline]
pub fn avx2_active() -> bool {
    match AVX2_STATE.load(Ordering::Relaxed) {
        ACTIVE => true,
        INACTIVE => false,
        _ => {
            let supported = detect_avx2();
            AVX2_STATE.store(if supported { ACTIVE } else { INACTIVE }, Ordering::Relaxed);
            supported
        }
    }
}

/// Enables (if the CPU supports it) or disables the AVX2 build of the int8 kernels, process-wide.
/// Returns whether AVX2 is active afterwards. Both builds give identical results; this only
/// exists to measure one against the other.
pub fn set_avx2_enabled(enabled: bool) -> bool {
    let active = enabled && detect_avx2();
    AVX2_STATE.store(if active { ACTIVE } else { INACTIVE }, Ordering::Relaxed);
    active
}

/// `CPUID`/`XGETBV` probe for AVX2 with OS support of the YMM state.
fn detect_avx2() -> bool {
    const OSXSAVE: u32 = 1 << 27;
    const AVX: u32 = 1 << 28;
    const XCR0_SSE_AVX: u64 = 0b110;
    const AVX2: u32 = 1 << 5;
    if __cpuid(0).eax < 7 {
        return false;
    }
    let features = __cpuid(1).ecx;
    if features & OSXSAVE == 0 || features & AVX == 0 {
        return false;
    }
    // SAFETY: CPUID.1:ECX.OSXSAVE is set (checked above), so XGETBV is available and XCR0 readable.
    let xcr0 = unsafe { _xgetbv(0) };
    if xcr0 & XCR0_SSE_AVX != XCR0_SSE_AVX {
        return false;
    }
    __cpuid_count(7, 0).ebx & AVX2 != 0
}

/// The matrix-vector product `emit(dot(row, input))` per row, in row order, with the AVX2
/// four-row kernel (callers checked [`avx2_active`]; without AVX2 this runs the portable kernel).
#[inline]
pub(crate) fn for_each_row_dot_avx2(weights: &[i8], input: &[i8], emit: &mut impl FnMut(i32)) {
    if !avx2_active() {
        for_each_row_dot_portable(weights, input, emit);
        return;
    }
    for_each_row_block(weights, input, emit, |rows, input| {
        // SAFETY: `avx2_active()` returned true, so the CPU supports AVX2 and the OS saves the
        // YMM registers (see `detect_avx2`).
        unsafe { dot_four_rows_avx2(rows, input) }
    });
}

/// Columns per `vpmaddwd` step.
const COLUMNS: usize = 16;

/// `[dot(rows[r], input) for r in 0..4]` (rows as long as `input`), wrapping int32 sums.
#[target_feature(enable = "avx2")]
fn dot_four_rows_avx2(rows: [&[i8]; ROWS], input: &[i8]) -> [i32; ROWS] {
    let (x_blocks, x_tail) = input.as_chunks::<COLUMNS>();
    let [(w0, t0), (w1, t1), (w2, t2), (w3, t3)] = rows.map(|row| row.as_chunks::<COLUMNS>());
    let mut acc = [_mm256_setzero_si256(); ROWS];
    let blocks = x_blocks.iter().zip(w0).zip(w1).zip(w2).zip(w3);
    for ((((x, w0), w1), w2), w3) in blocks {
        let x = widen(x);
        let [a0, a1, a2, a3] = &mut acc;
        *a0 = _mm256_add_epi32(*a0, _mm256_madd_epi16(widen(w0), x));
        *a1 = _mm256_add_epi32(*a1, _mm256_madd_epi16(widen(w1), x));
        *a2 = _mm256_add_epi32(*a2, _mm256_madd_epi16(widen(w2), x));
        *a3 = _mm256_add_epi32(*a3, _mm256_madd_epi16(widen(w3), x));
    }
    let [a0, a1, a2, a3] = acc;
    // Lanes of `quad`: per 128-bit half, [sum of a0's four lanes, a1's, a2's, a3's].
    let quad = _mm256_hadd_epi32(_mm256_hadd_epi32(a0, a1), _mm256_hadd_epi32(a2, a3));
    let sums = _mm_add_epi32(
        _mm256_castsi256_si128(quad),
        _mm256_extracti128_si256::<1>(quad),
    );
    let body = [
        _mm_cvtsi128_si32(sums),
        _mm_extract_epi32::<1>(sums),
        _mm_extract_epi32::<2>(sums),
        _mm_extract_epi32::<3>(sums),
    ];
    let mut out = [0_i32; ROWS];
    for ((total, body), tail) in out.iter_mut().zip(body).zip([t0, t1, t2, t3]) {
        let tail_sum = if x_tail.is_empty() {
            0
        } else {
            dot_i8_prefix(tail, x_tail)
        };
        *total = body.wrapping_add(tail_sum);
    }
    out
}

/// Loads 16 int8 values and sign-extends them to 16 int16 lanes.
#[inline]
#[target_feature(enable = "avx2")]
fn widen(block: &[i8; COLUMNS]) -> __m256i {
    // SAFETY: the pointer comes from a `&[i8; 16]`: 16 initialized, readable bytes; `loadu`
    // has no alignment requirement.
    let bytes = unsafe { _mm_loadu_si128(block.as_ptr().cast::<__m128i>()) };
    _mm256_cvtepi8_epi16(bytes)
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::kernels::matvec::tests::{random_cases, wide_row_sums};
    use std::vec::Vec;

    #[test]
    fn avx2_kernel_matches_portable_and_wide_sums() {
        if !avx2_supported() {
            std::eprintln!("no AVX2 on this CPU: only the portable kernel is exercised");
            return;
        }
        random_cases(0xA7, |weights, input| {
            let (mut avx2, mut portable) = (Vec::new(), Vec::new());
            for_each_row_dot_avx2(weights, input, &mut |sum| avx2.push(sum));
            for_each_row_dot_portable(weights, input, &mut |sum| portable.push(sum));
            assert_eq!(avx2, portable, "columns {}", input.len());
            let wide: Vec<i64> = avx2.iter().map(|s| i64::from(*s)).collect();
            assert_eq!(wide, wide_row_sums(weights, input));
        });
    }

    #[test]
    fn avx2_kernel_wraps_like_the_portable_one() {
        if !avx2_supported() {
            return;
        }
        // 65 537 * 2 products of 16384 exceed i32::MAX: both kernels wrap identically.
        static COLUMN: [i8; 131_074] = [-128; 131_074];
        let weights: Vec<i8> = COLUMN
            .iter()
            .chain(&COLUMN)
            .chain(&COLUMN)
            .chain(&COLUMN)
            .copied()
            .collect();
        let (mut avx2, mut portable) = (Vec::new(), Vec::new());
        for_each_row_dot_avx2(&weights, &COLUMN, &mut |sum| avx2.push(sum));
        for_each_row_dot_portable(&weights, &COLUMN, &mut |sum| portable.push(sum));
        let wide = (131_074_i64 * 16384) as i32;
        assert_eq!(avx2, [wide; 4]);
        assert_eq!(portable, avx2);
    }

    #[test]
    fn switching_reports_the_state() {
        // Only reads the state: other tests of this process may run the kernels concurrently.
        assert_eq!(avx2_active(), avx2_supported());
    }
}
