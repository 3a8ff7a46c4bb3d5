//! The fronts of the eight-row sums with the VNNI dot-product instructions: `vpdpbusd` (four
//! unsigned x signed byte products per int32 lane) on 256 bits (AVX-VNNI) or 512 bits (AVX-512
//! VNNI), and `vpdpwssd` (two int16 x int16 products per lane, AVX-512) for int16 inputs. Each
//! front sums the whole blocks of columns from `start` on and returns eight 256-bit partial
//! accumulators (a 512-bit one folded in halves) with the column where it stopped; `x86::matvec`
//! finishes the row with its AVX2 steps and reduces.
//!
//! `vpdpbusd` needs one unsigned operand. The weights are made unsigned, `u = w ^ 0x80 = w + 128`
//! (one `vpxor` per weight vector, no re-layout), so each lane accumulates
//! `sum u x = sum w x + 128 sum x`; the term `128 sum x` depends on the input alone and is summed
//! once per column block for all eight rows (`vpdpbusd` of the constant 128 bytes and `x`), then
//! subtracted from every row. Every four-product group is at most `4 * 255 * 128` in magnitude
//! and lanes add modulo 2^32 (the non-saturating instructions), so each row's result is the
//! wrapping int32 sum of its products `w x`, as in the portable kernel. `vpdpwssd` on weights
//! sign-extended to int16 (`vpmovsxbw`) adds pair sums of at most `2^23` modulo 2^32: the same.
#![allow(unsafe_code)]

use super::{rows_from, BLOCK_ROWS};
use core::arch::x86_64::{
    __m256i, __m512i, _mm256_add_epi32, _mm256_dpbusd_avx_epi32, _mm256_loadu_si256,
    _mm256_set1_epi8, _mm256_setzero_si256, _mm256_sub_epi32, _mm256_xor_si256,
    _mm512_castsi512_si256, _mm512_cvtepi8_epi16, _mm512_dpbusd_epi32, _mm512_dpwssd_epi32,
    _mm512_extracti64x4_epi64, _mm512_loadu_si512, _mm512_set1_epi8, _mm512_setzero_si512,
    _mm512_sub_epi32, _mm512_xor_si512,
};

/// Columns per 256-bit `vpdpbusd` step.
const YMM_BYTES: usize = 32;
/// Columns per 512-bit `vpdpbusd` step.
const ZMM_BYTES: usize = 64;
/// Columns per `vpdpwssd` step (32 int16 lanes).
const ZMM_WORDS: usize = 32;

/// Partial accumulators of the eight rows and the first column not yet summed.
pub(super) type Front = ([__m256i; BLOCK_ROWS], usize);

/// AVX-VNNI front for an int8 input: the 32-column blocks of columns `start..`.
#[inline]
#[target_feature(enable = "avx2,avxvnni")]
pub(super) fn front_i8_avx(rows: [&[i8]; BLOCK_ROWS], input: &[i8], start: usize) -> Front {
    let [r0, r1, r2, r3, r4, r5, r6, r7] = rows_from(rows, start);
    let (x_blocks, _) = input.get(start..).unwrap_or(&[]).as_chunks::<YMM_BYTES>();
    let blocks = x_blocks
        .iter()
        .zip(r0.as_chunks::<YMM_BYTES>().0)
        .zip(r1.as_chunks::<YMM_BYTES>().0)
        .zip(r2.as_chunks::<YMM_BYTES>().0)
        .zip(r3.as_chunks::<YMM_BYTES>().0)
        .zip(r4.as_chunks::<YMM_BYTES>().0)
        .zip(r5.as_chunks::<YMM_BYTES>().0)
        .zip(r6.as_chunks::<YMM_BYTES>().0)
        .zip(r7.as_chunks::<YMM_BYTES>().0);
    let offset = _mm256_set1_epi8(i8::MIN);
    let mut acc = [_mm256_setzero_si256(); BLOCK_ROWS];
    let mut shift = _mm256_setzero_si256();
    let mut steps = 0;
    for ((((((((x, w0), w1), w2), w3), w4), w5), w6), w7) in blocks {
        let x = load_ymm(x);
        shift = _mm256_dpbusd_avx_epi32(shift, offset, x);
        let [a0, a1, a2, a3, a4, a5, a6, a7] = &mut acc;
        *a0 = _mm256_dpbusd_avx_epi32(*a0, flip_ymm(w0, offset), x);
        *a1 = _mm256_dpbusd_avx_epi32(*a1, flip_ymm(w1, offset), x);
        *a2 = _mm256_dpbusd_avx_epi32(*a2, flip_ymm(w2, offset), x);
        *a3 = _mm256_dpbusd_avx_epi32(*a3, flip_ymm(w3, offset), x);
        *a4 = _mm256_dpbusd_avx_epi32(*a4, flip_ymm(w4, offset), x);
        *a5 = _mm256_dpbusd_avx_epi32(*a5, flip_ymm(w5, offset), x);
        *a6 = _mm256_dpbusd_avx_epi32(*a6, flip_ymm(w6, offset), x);
        *a7 = _mm256_dpbusd_avx_epi32(*a7, flip_ymm(w7, offset), x);
        steps += 1;
    }
    for a in &mut acc {
        *a = _mm256_sub_epi32(*a, shift);
    }
    (acc, start + steps * YMM_BYTES)
}

/// AVX-512 VNNI front for an int8 input: the 64-column blocks of columns `start..`.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512bw,avx512vnni")]
pub(super) fn front_i8_512(rows: [&[i8]; BLOCK_ROWS], input: &[i8], start: usize) -> Front {
    let [r0, r1, r2, r3, r4, r5, r6, r7] = rows_from(rows, start);
    let (x_blocks, _) = input.get(start..).unwrap_or(&[]).as_chunks::<ZMM_BYTES>();
    let blocks = x_blocks
        .iter()
        .zip(r0.as_chunks::<ZMM_BYTES>().0)
        .zip(r1.as_chunks::<ZMM_BYTES>().0)
        .zip(r2.as_chunks::<ZMM_BYTES>().0)
        .zip(r3.as_chunks::<ZMM_BYTES>().0)
        .zip(r4.as_chunks::<ZMM_BYTES>().0)
        .zip(r5.as_chunks::<ZMM_BYTES>().0)
        .zip(r6.as_chunks::<ZMM_BYTES>().0)
        .zip(r7.as_chunks::<ZMM_BYTES>().0);
    let offset = _mm512_set1_epi8(i8::MIN);
    let mut acc = [_mm512_setzero_si512(); BLOCK_ROWS];
    let mut shift = _mm512_setzero_si512();
    let mut steps = 0;
    for ((((((((x, w0), w1), w2), w3), w4), w5), w6), w7) in blocks {
        let x = load_zmm(x);
        shift = _mm512_dpbusd_epi32(shift, offset, x);
        let [a0, a1, a2, a3, a4, a5, a6, a7] = &mut acc;
        *a0 = _mm512_dpbusd_epi32(*a0, flip_zmm(w0, offset), x);
        *a1 = _mm512_dpbusd_epi32(*a1, flip_zmm(w1, offset), x);
        *a2 = _mm512_dpbusd_epi32(*a2, flip_zmm(w2, offset), x);
        *a3 = _mm512_dpbusd_epi32(*a3, flip_zmm(w3, offset), x);
        *a4 = _mm512_dpbusd_epi32(*a4, flip_zmm(w4, offset), x);
        *a5 = _mm512_dpbusd_epi32(*a5, flip_zmm(w5, offset), x);
        *a6 = _mm512_dpbusd_epi32(*a6, flip_zmm(w6, offset), x);
        *a7 = _mm512_dpbusd_epi32(*a7, flip_zmm(w7, offset), x);
        steps += 1;
    }
    let [a0, a1, a2, a3, a4, a5, a6, a7] = acc;
    let acc = [
        fold(_mm512_sub_epi32(a0, shift)),
        fold(_mm512_sub_epi32(a1, shift)),
        fold(_mm512_sub_epi32(a2, shift)),
        fold(_mm512_sub_epi32(a3, shift)),
        fold(_mm512_sub_epi32(a4, shift)),
        fold(_mm512_sub_epi32(a5, shift)),
        fold(_mm512_sub_epi32(a6, shift)),
        fold(_mm512_sub_epi32(a7, shift)),
    ];
    (acc, start + steps * ZMM_BYTES)
}

/// AVX-512 front for an int16 input: the 32-column blocks of columns `start..` with `vpdpwssd`
/// on the sign-extended weights.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512bw,avx512vnni")]
pub(super) fn front_i16_512(rows: [&[i8]; BLOCK_ROWS], input: &[i16], start: usize) -> Front {
    let [r0, r1, r2, r3, r4, r5, r6, r7] = rows_from(rows, start);
    let (x_blocks, _) = input.get(start..).unwrap_or(&[]).as_chunks::<ZMM_WORDS>();
    let blocks = x_blocks
        .iter()
        .zip(r0.as_chunks::<ZMM_WORDS>().0)
        .zip(r1.as_chunks::<ZMM_WORDS>().0)
        .zip(r2.as_chunks::<ZMM_WORDS>().0)
        .zip(r3.as_chunks::<ZMM_WORDS>().0)
        .zip(r4.as_chunks::<ZMM_WORDS>().0)
        .zip(r5.as_chunks::<ZMM_WORDS>().0)
        .zip(r6.as_chunks::<ZMM_WORDS>().0)
        .zip(r7.as_chunks::<ZMM_WORDS>().0);
    let mut acc = [_mm512_setzero_si512(); BLOCK_ROWS];
    let mut steps = 0;
    for ((((((((x, w0), w1), w2), w3), w4), w5), w6), w7) in blocks {
        // SAFETY: the pointer comes from a `&[i16; 32]`: 64 initialized, readable bytes; `loadu`
        // has no alignment requirement.
        let x = unsafe { _mm512_loadu_si512(x.as_ptr().cast::<__m512i>()) };
        let [a0, a1, a2, a3, a4, a5, a6, a7] = &mut acc;
        *a0 = _mm512_dpwssd_epi32(*a0, widen_zmm(w0), x);
        *a1 = _mm512_dpwssd_epi32(*a1, widen_zmm(w1), x);
        *a2 = _mm512_dpwssd_epi32(*a2, widen_zmm(w2), x);
        *a3 = _mm512_dpwssd_epi32(*a3, widen_zmm(w3), x);
        *a4 = _mm512_dpwssd_epi32(*a4, widen_zmm(w4), x);
        *a5 = _mm512_dpwssd_epi32(*a5, widen_zmm(w5), x);
        *a6 = _mm512_dpwssd_epi32(*a6, widen_zmm(w6), x);
        *a7 = _mm512_dpwssd_epi32(*a7, widen_zmm(w7), x);
        steps += 1;
    }
    let [a0, a1, a2, a3, a4, a5, a6, a7] = acc;
    let acc = [
        fold(a0),
        fold(a1),
        fold(a2),
        fold(a3),
        fold(a4),
        fold(a5),
        fold(a6),
        fold(a7),
    ];
    (acc, start + steps * ZMM_WORDS)
}

/// The sum of the two 256-bit halves (lane `i` of the result: lanes `i` and `i + 8`).
#[inline]
#[target_feature(enable = "avx2,avx512f")]
fn fold(a: __m512i) -> __m256i {
    _mm256_add_epi32(_mm512_castsi512_si256(a), _mm512_extracti64x4_epi64::<1>(a))
}

/// 32 weights made unsigned (`w ^ 0x80`, `offset` holds 0x80 in every byte).
#[inline]
#[target_feature(enable = "avx2")]
fn flip_ymm(block: &[i8; YMM_BYTES], offset: __m256i) -> __m256i {
    _mm256_xor_si256(load_ymm(block), offset)
}

/// 64 weights made unsigned (`w ^ 0x80`).
#[inline]
#[target_feature(enable = "avx512f")]
fn flip_zmm(block: &[i8; ZMM_BYTES], offset: __m512i) -> __m512i {
    _mm512_xor_si512(load_zmm(block), offset)
}

/// 32 weights sign-extended to 32 int16 lanes.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512bw")]
fn widen_zmm(block: &[i8; ZMM_WORDS]) -> __m512i {
    _mm512_cvtepi8_epi16(load_ymm(block))
}

/// Loads 32 bytes.
#[inline]
#[target_feature(enable = "avx2")]
fn load_ymm(block: &[i8; YMM_BYTES]) -> __m256i {
    // SAFETY: the pointer comes from a `&[i8; 32]`: 32 initialized, readable bytes; `loadu` has
    // no alignment requirement.
    unsafe { _mm256_loadu_si256(block.as_ptr().cast::<__m256i>()) }
}

/// Loads 64 bytes.
#[inline]
#[target_feature(enable = "avx512f")]
fn load_zmm(block: &[i8; ZMM_BYTES]) -> __m512i {
    // SAFETY: the pointer comes from a `&[i8; 64]`: 64 initialized, readable bytes; `loadu` has
    // no alignment requirement.
    unsafe { _mm512_loadu_si512(block.as_ptr().cast::<__m512i>()) }
}
