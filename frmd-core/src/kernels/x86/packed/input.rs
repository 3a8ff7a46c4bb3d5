//! The input of a packed layer as its kernels read it: int8 codes as they are, int16 codes split
//! into low bytes and high bytes plus 128 (`x86::packed`), and the corrections that make the
//! block sums exact: `128 sum x` for int8 inputs, the split sums' combination for int16 ones.
#![allow(unsafe_code)]

use super::{halves, load_half, BlockSums};
use crate::kernels::packed::{GROUP_BYTES, GROUP_COLUMNS, MAX_PACKED_COLUMNS};
use crate::kernels::x86::Avx2;
use crate::kernels::LayerInput;
use core::arch::x86_64::{
    __m128i, __m256i, _mm256_add_epi32, _mm256_castsi256_si128, _mm256_extracti128_si256,
    _mm256_loadu_si256, _mm256_permute4x64_epi64, _mm256_set1_epi32, _mm256_setr_epi8,
    _mm256_setzero_si256, _mm256_shuffle_epi8, _mm256_slli_epi32, _mm256_sub_epi32, _mm_set1_epi8,
    _mm_storeu_si128, _mm_xor_si128,
};

/// Words a split int16 input may take (four columns each).
const MAX_WORDS: usize = MAX_PACKED_COLUMNS / GROUP_COLUMNS;

/// Stack space for a split int16 input.
pub(super) struct SplitWords {
    low: [i32; MAX_WORDS],
    high: [i32; MAX_WORDS],
}

/// A layer's input as the packed kernels read it.
#[derive(Clone, Copy)]
pub(super) enum Prepared<'a> {
    /// int8 codes, read four at a time as broadcast words.
    Bytes(&'a [i8]),
    /// int16 codes split per group of four columns: the low bytes, and the high bytes plus 128.
    Split(&'a [i32], &'a [i32]),
}

impl SplitWords {
    /// `x` split into the words of [`Prepared::Split`]; `None` beyond [`MAX_PACKED_COLUMNS`].
    /// Sixteen columns per step: `vpshufb` gathers each 128-bit half's low and high bytes,
    /// `vpermq` joins the halves; the last `len % 16` columns one by one.
    #[target_feature(enable = "avx2")]
    fn split<'a>(&'a mut self, x: &[i16]) -> Option<Prepared<'a>> {
        let groups = x.len().div_ceil(GROUP_COLUMNS);
        let low = self.low.get_mut(..groups)?;
        let high = self.high.get_mut(..groups)?;
        let order = _mm256_setr_epi8(
            0, 2, 4, 6, 8, 10, 12, 14, 1, 3, 5, 7, 9, 11, 13, 15, 0, 2, 4, 6, 8, 10, 12, 14, 1, 3,
            5, 7, 9, 11, 13, 15,
        );
        let (steps, rest) = x.as_chunks::<16>();
        let (low_steps, low_rest) = low.split_at_mut_checked(4 * steps.len())?;
        let (high_steps, high_rest) = high.split_at_mut_checked(4 * steps.len())?;
        let (low_steps, high_steps) = (
            low_steps.as_chunks_mut::<4>().0,
            high_steps.as_chunks_mut::<4>().0,
        );
        let words = low_steps.iter_mut().zip(high_steps.iter_mut());
        for ((low, high), codes) in words.zip(steps) {
            // SAFETY: the pointer comes from a `&[i16; 16]`: 32 initialized, readable bytes;
            // `loadu` has no alignment requirement.
            let codes = unsafe { _mm256_loadu_si256(codes.as_ptr().cast::<__m256i>()) };
            // Per half: low bytes, then high bytes; then [low 0..16, high 0..16].
            let bytes =
                _mm256_permute4x64_epi64::<0b11_01_10_00>(_mm256_shuffle_epi8(codes, order));
            let flipped =
                _mm_xor_si128(_mm256_extracti128_si256::<1>(bytes), _mm_set1_epi8(i8::MIN));
            // SAFETY: the pointers come from `&mut [i32; 4]`: 16 writable bytes each; no
            // alignment needed.
            unsafe {
                _mm_storeu_si128(
                    low.as_mut_ptr().cast::<__m128i>(),
                    _mm256_castsi256_si128(bytes),
                );
                _mm_storeu_si128(high.as_mut_ptr().cast::<__m128i>(), flipped);
            }
        }
        let rest_words = low_rest.iter_mut().zip(high_rest.iter_mut());
        for ((low, high), codes) in rest_words.zip(rest.chunks(GROUP_COLUMNS)) {
            // Missing columns: x = 0, so l = 0 and h + 128 = 128.
            let (mut l, mut h) = ([0_u8; 4], [0x80_u8; 4]);
            for ((l, h), code) in l.iter_mut().zip(&mut h).zip(codes) {
                let [low_byte, high_byte] = code.to_le_bytes();
                (*l, *h) = (low_byte, high_byte ^ 0x80);
            }
            (*low, *high) = (i32::from_le_bytes(l), i32::from_le_bytes(h));
        }
        Some(Prepared::Split(low, high))
    }
}

/// `run(input as the packed kernels read it)`; `false` for an input they do not take. The token
/// proves AVX2 for the split.
#[inline(always)]
pub(super) fn with_prepared(
    _avx2: Avx2,
    input: LayerInput<'_>,
    run: impl FnOnce(Prepared<'_>) -> bool,
) -> bool {
    match input {
        LayerInput::Int8(x) => run(Prepared::Bytes(x)),
        LayerInput::Int16(x) => {
            let mut words = SplitWords {
                low: [0; MAX_WORDS],
                high: [0; MAX_WORDS],
            };
            // SAFETY: an `Avx2` token exists only after `avx2_active()` detected AVX2.
            unsafe { words.split(x) }.is_some_and(run)
        }
    }
}

/// `low + 256 high - 256 * 128 * row_sums`, lane by lane (modulo 2^32): the split sums'
/// combination.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn combine_split(
    low: BlockSums,
    high: BlockSums,
    row_sums: &[u8; GROUP_BYTES],
) -> BlockSums {
    let (first, second) = halves(row_sums);
    let row_sums = [load_half(first), load_half(second)];
    let mut out = low;
    for ((lanes, high), sums) in out.iter_mut().zip(high).zip(row_sums) {
        let scaled = _mm256_sub_epi32(_mm256_slli_epi32::<8>(high), _mm256_slli_epi32::<15>(sums));
        *lanes = _mm256_add_epi32(*lanes, scaled);
    }
    out
}

/// `128 sum x` as eight lanes: what the unsigned int8 weights add to every row (zero for split
/// int16 inputs, whose sums are combined exactly).
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn weight_offset(input: Prepared<'_>) -> __m256i {
    match input {
        Prepared::Bytes(x) => {
            let sum = x.iter().fold(0_i32, |s, v| s.wrapping_add(i32::from(*v)));
            _mm256_set1_epi32(sum.wrapping_mul(128))
        }
        Prepared::Split(..) => _mm256_setzero_si256(),
    }
}
