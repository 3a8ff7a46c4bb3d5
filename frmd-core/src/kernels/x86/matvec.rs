//! AVX2 int8 fully connected rows, eight output channels per call (see `kernels::x86`).
//!
//! Per 16 input columns the input is loaded and sign-extended to 16 halfwords once
//! (`vpmovsxbw`), and for each of the eight rows: one `vpmovsxbw` of 16 weights, one `vpmaddwd`
//! (16 products summed in pairs into 8 int32 lanes) and one `vpaddd`: 25 instructions per 128
//! multiply-accumulates (then one 8-column step with 128-bit registers if at least 8 columns are
//! left). Three `vphaddd` levels and one 128-bit lane swap reduce the eight
//! accumulators to one vector of eight row sums, to which the bias is added; the requantizing
//! variant then runs `x86::requant` on that vector and packs eight int8 outputs, so accumulators
//! never leave the registers. The last `columns % 8` columns use [`dot_i8_prefix`].
//!
//! Bit-exactness: an int8 x int8 product lies in `[-16256, 16384]`, so a `vpmaddwd` pair sum (at
//! most 32768 in magnitude) is exact in int32; `vpaddd` and `vphaddd` add modulo 2^32. Every row
//! sum is the wrapping int32 sum of the same products as the portable kernel (wrapping addition
//! does not depend on order), plus the bias with wrapping addition as in `FullyConnected`.
//!
//! int16 inputs (the 16-bit first-layer plane, int16-activation layers) run the same loop with
//! the 16 codes loaded as they are instead of sign-extended (an int8 x int16 product is at most
//! `2^22`, a pair sum `2^23`: exact), so they cost the same 25 instructions per 128 MACs; the
//! [`Avx2::residues`] form sums a range of columns (one 512-column chunk of an int64
//! accumulator, see `x86::wide`).
#![allow(unsafe_code)]

use super::requant::{load_i32, pack_i8, requantize_lanes, RequantBlock};
use super::{Avx2, BLOCK_ROWS};
use crate::kernels::dot::{dot_i8_i16_prefix, dot_i8_prefix};
use crate::kernels::LayerInput;
use core::arch::x86_64::{
    __m128i, __m256i, _mm256_add_epi32, _mm256_cvtepi8_epi16, _mm256_dpbusd_avx_epi32,
    _mm256_hadd_epi32, _mm256_loadu_si256, _mm256_madd_epi16, _mm256_permute2x128_si256,
    _mm256_set1_epi8, _mm256_setzero_si256, _mm256_storeu_si256, _mm256_sub_epi32,
    _mm256_xor_si256, _mm256_zextsi128_si256, _mm_cvtepi8_epi16, _mm_loadl_epi64, _mm_loadu_si128,
    _mm_madd_epi16,
};
use core::ops::Range;

/// Columns per `vpmaddwd` step.
const COLUMNS: usize = 16;

/// Columns of the 128-bit step after the 16-column blocks.
const HALF: usize = 8;

impl Avx2 {
    /// `bias[r] + dot(row r, input)` (wrapping) for the eight rows stored back to back in `rows`
    /// (`8 * input.len()` weights). An empty `input` gives `bias`.
    #[inline]
    pub(crate) fn accumulate_rows(
        self,
        rows: &[i8],
        input: &[i8],
        bias: &[i32; BLOCK_ROWS],
    ) -> [i32; BLOCK_ROWS] {
        // SAFETY: an `Avx2` token exists only after `avx2_active()` returned true.
        unsafe { accumulate_rows(self.vnni(), rows, input, bias) }
    }

    /// `requantize_to_i8(bias[r] + dot(row r, input), ...)` for the eight rows of `rows`;
    /// `requant` must satisfy `FcRequant::validate` (shift range, zero point, clamp order).
    #[inline]
    pub(crate) fn requantize_rows(
        self,
        rows: &[i8],
        input: &[i8],
        bias: &[i32; BLOCK_ROWS],
        requant: RequantBlock<'_>,
    ) -> [i8; BLOCK_ROWS] {
        // SAFETY: an `Avx2` token exists only after `avx2_active()` returned true.
        unsafe { requantize_rows(self.vnni(), rows, input, bias, requant) }
    }

    /// [`Self::requantize_rows`] for an int16 input (the 16-bit first-layer plane of an int8
    /// network): the same kernel with the codes loaded as they are.
    #[inline]
    pub(crate) fn requantize_rows_i16(
        self,
        rows: &[i8],
        input: &[i16],
        bias: &[i32; BLOCK_ROWS],
        requant: RequantBlock<'_>,
    ) -> [i8; BLOCK_ROWS] {
        // SAFETY: an `Avx2` token exists only after `avx2_active()` returned true.
        unsafe { requantize_rows_i16(rows, input, bias, requant) }
    }

    /// `start[r] + sum over columns of row r times input` (int32, wrapping) for the eight rows
    /// stored back to back in `rows` (`8 * input.len()` weights), int8 or int16 input; columns
    /// outside the input are ignored. The whole row of an int8 input takes the VNNI kernel when
    /// the token allows it (the same sums).
    #[inline]
    pub(crate) fn residues(
        self,
        rows: &[i8],
        input: LayerInput<'_>,
        columns: Range<usize>,
        start: &[i32; BLOCK_ROWS],
    ) -> [i32; BLOCK_ROWS] {
        // SAFETY: an `Avx2` token exists only after `avx2_active()` returned true.
        unsafe { residues(self.vnni(), rows, input, columns, start) }
    }
}

#[target_feature(enable = "avx2")]
fn requantize_rows_i16(
    rows: &[i8],
    input: &[i16],
    bias: &[i32; BLOCK_ROWS],
    requant: RequantBlock<'_>,
) -> [i8; BLOCK_ROWS] {
    let sums = row_sums_i16(split_rows(rows, input.len()), input, 0);
    let acc = _mm256_add_epi32(sums, load_i32(bias));
    pack_i8(requantize_lanes(acc, requant))
}

#[target_feature(enable = "avx2")]
fn residues(
    vnni: bool,
    rows: &[i8],
    input: LayerInput<'_>,
    columns: Range<usize>,
    start: &[i32; BLOCK_ROWS],
) -> [i32; BLOCK_ROWS] {
    let (first, end) = (columns.start, columns.end);
    let sums = match input {
        LayerInput::Int8(values) if first == 0 && end >= values.len() => {
            row_sums(vnni, rows, values)
        }
        LayerInput::Int8(values) => {
            let upto = values.get(..end).unwrap_or(values);
            row_sums_i8(split_rows(rows, values.len()), upto, first)
        }
        LayerInput::Int16(values) => {
            let upto = values.get(..end).unwrap_or(values);
            row_sums_i16(split_rows(rows, values.len()), upto, first)
        }
    };
    let sums = _mm256_add_epi32(sums, load_i32(start));
    let mut out = [0_i32; BLOCK_ROWS];
    // SAFETY: the pointer comes from a `&mut [i32; 8]`: 32 writable bytes; no alignment needed.
    unsafe { _mm256_storeu_si256(out.as_mut_ptr().cast::<__m256i>(), sums) };
    out
}

/// The end of both row-sum functions, expanded in each so that everything stays in registers (as
/// a function, LLVM did not inline it and passed the eight accumulators through memory): adds
/// columns `$start..` of the eight `$rows` times `$input` to the partial sums `$acc` (16-column
/// `vpmaddwd` blocks, one 8-column step, then scalar) and reduces them to one vector of row sums.
/// The input is loaded by `$load` (16 columns), `$load_half` (8) and its tail summed by `$dot`:
/// int8 codes sign-extended by default, int16 codes as they are.
macro_rules! finish_row_sums {
    ($rows:expr, $input:expr, $acc:expr, $start:expr) => {
        finish_row_sums!(
            $rows,
            $input,
            $acc,
            $start,
            widen,
            widen_half,
            dot_i8_prefix
        )
    };
    ($rows:expr, $input:expr, $acc:expr, $start:expr, $load:ident, $load_half:ident, $dot:path) => {{
        let rows: [&[i8]; BLOCK_ROWS] = $rows;
        let start: usize = $start;
        let mut acc: [__m256i; BLOCK_ROWS] = $acc;
        let input = $input.get(start..).unwrap_or(&[]);
        let [r0, r1, r2, r3, r4, r5, r6, r7] = rows;
        let (r0, r1, r2, r3) = (
            from(r0, start),
            from(r1, start),
            from(r2, start),
            from(r3, start),
        );
        let (r4, r5, r6, r7) = (
            from(r4, start),
            from(r5, start),
            from(r6, start),
            from(r7, start),
        );

        let (x_blocks, x_tail) = input.as_chunks::<COLUMNS>();
        let blocks = x_blocks
            .iter()
            .zip(r0.as_chunks::<COLUMNS>().0)
            .zip(r1.as_chunks::<COLUMNS>().0)
            .zip(r2.as_chunks::<COLUMNS>().0)
            .zip(r3.as_chunks::<COLUMNS>().0)
            .zip(r4.as_chunks::<COLUMNS>().0)
            .zip(r5.as_chunks::<COLUMNS>().0)
            .zip(r6.as_chunks::<COLUMNS>().0)
            .zip(r7.as_chunks::<COLUMNS>().0);
        for ((((((((x, w0), w1), w2), w3), w4), w5), w6), w7) in blocks {
            let x = $load(x);
            let [a0, a1, a2, a3, a4, a5, a6, a7] = &mut acc;
            *a0 = _mm256_add_epi32(*a0, _mm256_madd_epi16(widen(w0), x));
            *a1 = _mm256_add_epi32(*a1, _mm256_madd_epi16(widen(w1), x));
            *a2 = _mm256_add_epi32(*a2, _mm256_madd_epi16(widen(w2), x));
            *a3 = _mm256_add_epi32(*a3, _mm256_madd_epi16(widen(w3), x));
            *a4 = _mm256_add_epi32(*a4, _mm256_madd_epi16(widen(w4), x));
            *a5 = _mm256_add_epi32(*a5, _mm256_madd_epi16(widen(w5), x));
            *a6 = _mm256_add_epi32(*a6, _mm256_madd_epi16(widen(w6), x));
            *a7 = _mm256_add_epi32(*a7, _mm256_madd_epi16(widen(w7), x));
        }
        let rows = [r0, r1, r2, r3, r4, r5, r6, r7];
        // Eight more columns with 128-bit registers when at least eight are left.
        let mut column = input.len() - x_tail.len();
        if let Some((x_half, _)) = x_tail.split_first_chunk::<HALF>() {
            let x = $load_half(x_half);
            for (a, row) in acc.iter_mut().zip(rows) {
                let weights = row
                    .get(column..)
                    .and_then(|w| w.split_first_chunk::<HALF>());
                if let Some((w, _)) = weights {
                    let products = _mm_madd_epi16(widen_half(w), x);
                    *a = _mm256_add_epi32(*a, _mm256_zextsi128_si256(products));
                }
            }
            column += HALF;
        }
        let [a0, a1, a2, a3, a4, a5, a6, a7] = acc;
        // Per 128-bit half: [row 0 .. row 3 partial sums] and [row 4 .. row 7 partial sums].
        let first = _mm256_hadd_epi32(_mm256_hadd_epi32(a0, a1), _mm256_hadd_epi32(a2, a3));
        let second = _mm256_hadd_epi32(_mm256_hadd_epi32(a4, a5), _mm256_hadd_epi32(a6, a7));
        let low_halves = _mm256_permute2x128_si256::<0x20>(first, second);
        let high_halves = _mm256_permute2x128_si256::<0x31>(first, second);
        let sums = _mm256_add_epi32(low_halves, high_halves);
        let Some(x_rest) = input.get(column..).filter(|rest| !rest.is_empty()) else {
            return sums;
        };
        let mut tails = [0_i32; BLOCK_ROWS];
        for (tail, row) in tails.iter_mut().zip(rows) {
            *tail = $dot(row.get(column..).unwrap_or(&[]), x_rest);
        }
        _mm256_add_epi32(sums, load_i32(&tails))
    }};
}

/// `[dot(row r, input) for r in 0..8]` as one vector (wrapping int32 sums); with `vnni` (the
/// caller's `Avx2` token says AVX-VNNI is available) the 32-column blocks use `vpdpbusd`.
#[inline]
#[target_feature(enable = "avx2")]
fn row_sums(vnni: bool, rows: &[i8], input: &[i8]) -> __m256i {
    if vnni {
        // SAFETY: `vnni` comes from an `Avx2` token whose flag `avx_vnni_active()` set only after
        // detecting AVX-VNNI (and AVX2 with OS support).
        unsafe { row_sums_vnni(rows, input) }
    } else {
        row_sums_avx2(rows, input)
    }
}

/// [`row_sums`] with AVX2 only.
#[target_feature(enable = "avx2")]
fn row_sums_avx2(rows: &[i8], input: &[i8]) -> __m256i {
    let rows = split_rows(rows, input.len());
    finish_row_sums!(rows, input, [_mm256_setzero_si256(); BLOCK_ROWS], 0)
}

/// The eight rows of `rows` (`columns` weights each; missing rows are empty).
#[inline]
pub(super) fn split_rows(rows: &[i8], columns: usize) -> [&[i8]; BLOCK_ROWS] {
    if columns == 0 {
        return [&[]; BLOCK_ROWS];
    }
    // Plain `next()` calls rather than `array::from_fn`: closures do not inherit the target
    // features, and LLVM left them as out-of-line calls.
    let mut split = rows.chunks_exact(columns);
    let r0 = split.next().unwrap_or(&[]);
    let r1 = split.next().unwrap_or(&[]);
    let r2 = split.next().unwrap_or(&[]);
    let r3 = split.next().unwrap_or(&[]);
    let r4 = split.next().unwrap_or(&[]);
    let r5 = split.next().unwrap_or(&[]);
    let r6 = split.next().unwrap_or(&[]);
    let r7 = split.next().unwrap_or(&[]);
    [r0, r1, r2, r3, r4, r5, r6, r7]
}

/// AVX-VNNI front of [`row_sums`]: the 32-column blocks with `vpdpbusd` (unsigned x signed bytes),
/// four rows at a time, then `finish_row_sums!` for the remaining columns.
///
/// `vpdpbusd` needs an unsigned operand: the input is offset to `u = x + 128` (flipping the sign
/// bit), so each lane accumulates `sum u * w = sum x * w + 128 * sum w`; a second `vpdpbusd` with
/// the constant 128 accumulates `128 * sum w`, which is subtracted. Each group of four products
/// is at most `4 * 255 * 128` in magnitude and is added modulo 2^32 (the non-saturating
/// instruction), so the difference equals the wrapping sum of `x * w` exactly.
#[target_feature(enable = "avx2,avxvnni")]
fn row_sums_vnni(rows: &[i8], input: &[i8]) -> __m256i {
    let rows = split_rows(rows, input.len());
    let [r0, r1, r2, r3, r4, r5, r6, r7] = rows;
    let (x_blocks, _) = input.as_chunks::<WIDE>();
    let mut acc = [_mm256_setzero_si256(); BLOCK_ROWS];
    let [a0, a1, a2, a3, a4, a5, a6, a7] = &mut acc;
    dpbusd_four_rows([a0, a1, a2, a3], [r0, r1, r2, r3], x_blocks);
    dpbusd_four_rows([a4, a5, a6, a7], [r4, r5, r6, r7], x_blocks);
    finish_row_sums!(rows, input, acc, x_blocks.len() * WIDE)
}

/// Columns per `vpdpbusd` step.
const WIDE: usize = 32;

/// `acc[r] += sum over the blocks of x * w` for four rows (see [`row_sums_vnni`]).
#[inline]
#[target_feature(enable = "avx2,avxvnni")]
fn dpbusd_four_rows(acc: [&mut __m256i; 4], rows: [&[i8]; 4], x_blocks: &[[i8; WIDE]]) {
    let offset = _mm256_set1_epi8(i8::MIN);
    let [r0, r1, r2, r3] = rows;
    let blocks = x_blocks
        .iter()
        .zip(r0.as_chunks::<WIDE>().0)
        .zip(r1.as_chunks::<WIDE>().0)
        .zip(r2.as_chunks::<WIDE>().0)
        .zip(r3.as_chunks::<WIDE>().0);
    let zero = _mm256_setzero_si256();
    let (mut p0, mut p1, mut p2, mut p3) = (zero, zero, zero, zero);
    let (mut s0, mut s1, mut s2, mut s3) = (zero, zero, zero, zero);
    for ((((x, w0), w1), w2), w3) in blocks {
        let u = _mm256_xor_si256(load_bytes(x), offset);
        let (w0, w1, w2, w3) = (
            load_bytes(w0),
            load_bytes(w1),
            load_bytes(w2),
            load_bytes(w3),
        );
        p0 = _mm256_dpbusd_avx_epi32(p0, u, w0);
        s0 = _mm256_dpbusd_avx_epi32(s0, offset, w0);
        p1 = _mm256_dpbusd_avx_epi32(p1, u, w1);
        s1 = _mm256_dpbusd_avx_epi32(s1, offset, w1);
        p2 = _mm256_dpbusd_avx_epi32(p2, u, w2);
        s2 = _mm256_dpbusd_avx_epi32(s2, offset, w2);
        p3 = _mm256_dpbusd_avx_epi32(p3, u, w3);
        s3 = _mm256_dpbusd_avx_epi32(s3, offset, w3);
    }
    let [a0, a1, a2, a3] = acc;
    *a0 = _mm256_add_epi32(*a0, _mm256_sub_epi32(p0, s0));
    *a1 = _mm256_add_epi32(*a1, _mm256_sub_epi32(p1, s1));
    *a2 = _mm256_add_epi32(*a2, _mm256_sub_epi32(p2, s2));
    *a3 = _mm256_add_epi32(*a3, _mm256_sub_epi32(p3, s3));
}

/// `row[start..]`, empty if `start` is past the end.
#[inline(always)]
fn from(row: &[i8], start: usize) -> &[i8] {
    row.get(start..).unwrap_or(&[])
}

/// Loads 32 int8 values.
#[inline]
#[target_feature(enable = "avx2")]
fn load_bytes(block: &[i8; WIDE]) -> __m256i {
    // SAFETY: the pointer comes from a `&[i8; 32]`: 32 initialized, readable bytes; `loadu` has
    // no alignment requirement.
    unsafe { _mm256_loadu_si256(block.as_ptr().cast::<__m256i>()) }
}

/// Loads 8 int8 values and sign-extends them to 8 int16 lanes.
#[inline]
#[target_feature(enable = "avx2")]
fn widen_half(block: &[i8; HALF]) -> __m128i {
    // SAFETY: the pointer comes from a `&[i8; 8]`: `loadl` reads exactly 8 initialized bytes and
    // has no alignment requirement.
    let bytes = unsafe { _mm_loadl_epi64(block.as_ptr().cast::<__m128i>()) };
    _mm_cvtepi8_epi16(bytes)
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

/// Loads 16 int16 values.
#[inline]
#[target_feature(enable = "avx2")]
fn load_halves(block: &[i16; COLUMNS]) -> __m256i {
    // SAFETY: the pointer comes from a `&[i16; 16]`: 32 initialized, readable bytes; `loadu` has
    // no alignment requirement.
    unsafe { _mm256_loadu_si256(block.as_ptr().cast::<__m256i>()) }
}

/// Loads 8 int16 values.
#[inline]
#[target_feature(enable = "avx2")]
fn load_halves_half(block: &[i16; HALF]) -> __m128i {
    // SAFETY: the pointer comes from a `&[i16; 8]`: 16 initialized, readable bytes; `loadu` has
    // no alignment requirement.
    unsafe { _mm_loadu_si128(block.as_ptr().cast::<__m128i>()) }
}

/// Column sums `[dot(rows[r][start..], input[start..]) for r in 0..8]` of an int8 input (AVX2
/// only; `input` ends where the columns end, `rows` are the whole rows).
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn row_sums_i8(rows: [&[i8]; BLOCK_ROWS], input: &[i8], start: usize) -> __m256i {
    finish_row_sums!(rows, input, [_mm256_setzero_si256(); BLOCK_ROWS], start)
}

/// [`row_sums_i8`] for an int16 input.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn row_sums_i16(rows: [&[i8]; BLOCK_ROWS], input: &[i16], start: usize) -> __m256i {
    finish_row_sums!(
        rows,
        input,
        [_mm256_setzero_si256(); BLOCK_ROWS],
        start,
        load_halves,
        load_halves_half,
        dot_i8_i16_prefix
    )
}

#[target_feature(enable = "avx2")]
fn accumulate_rows(
    vnni: bool,
    rows: &[i8],
    input: &[i8],
    bias: &[i32; BLOCK_ROWS],
) -> [i32; BLOCK_ROWS] {
    let sums = _mm256_add_epi32(row_sums(vnni, rows, input), load_i32(bias));
    let mut out = [0_i32; BLOCK_ROWS];
    // SAFETY: the pointer comes from a `&mut [i32; 8]`: 32 writable bytes; no alignment needed.
    unsafe { _mm256_storeu_si256(out.as_mut_ptr().cast::<__m256i>(), sums) };
    out
}

#[target_feature(enable = "avx2")]
fn requantize_rows(
    vnni: bool,
    rows: &[i8],
    input: &[i8],
    bias: &[i32; BLOCK_ROWS],
    requant: RequantBlock<'_>,
) -> [i8; BLOCK_ROWS] {
    let acc = _mm256_add_epi32(row_sums(vnni, rows, input), load_i32(bias));
    pack_i8(requantize_lanes(acc, requant))
}

#[cfg(test)]
mod tests;
