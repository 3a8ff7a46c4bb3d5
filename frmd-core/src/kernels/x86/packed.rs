//! Whole layers of packed weights (`kernels::packed`): per block of sixteen rows and group of
//! four columns, `vpdpbusd` of the 64 packed bytes and the group's input word broadcast to every
//! lane, so each lane accumulates its own row and a block's sums are ready without a horizontal
//! reduction. AVX-512 VNNI takes a group in one 512-bit instruction, AVX-VNNI in two 256-bit
//! ones; several groups are in flight at once (independent accumulators). The sums then get the
//! bias and, for hidden layers, `x86::requant`'s requantization, sixteen outputs at a time.
//!
//! Bit-exactness. int8 inputs meet unsigned weights `u = w + 128`: a lane accumulates
//! `sum u x = sum w x + 128 sum x` (four-product groups of at most `4 * 255 * 128` in magnitude,
//! lanes adding modulo 2^32), and `128 sum x`, the same for every row, is subtracted. int16
//! inputs are split, `x = 256 h + l` with `h` the signed high byte and `l` the unsigned low
//! byte, and meet the signed weights twice: `sum w l` and `sum w (h + 128)` (both unsigned
//! inputs), so `sum w x = sum w l + 256 (sum w (h + 128) - 128 sum w)` with the row's weight sum
//! stored beside the packed weights; every step adds modulo 2^32. Each row's result is therefore
//! the wrapping int32 sum of its products, as in the portable kernel; padded columns have zero
//! weights and padded rows are never stored.
#![allow(unsafe_code)]

use super::requant::{load_i32, pack_i8, requantize_lanes, RequantBlock};
use super::{Avx2, BLOCK_ROWS};
use crate::kernels::packed::{PackedWeights, GROUP_BYTES, GROUP_COLUMNS, PACK_ROWS};
use crate::kernels::{FcRequant, FullyConnected, LayerInput};
use core::arch::x86_64::{
    __m256i, __m512i, _mm256_add_epi32, _mm256_dpbusd_avx_epi32, _mm256_loadu_si256,
    _mm256_set1_epi32, _mm256_setzero_si256, _mm256_storeu_si256, _mm256_sub_epi32,
    _mm512_add_epi32, _mm512_castsi512_si256, _mm512_dpbusd_epi32, _mm512_extracti64x4_epi64,
    _mm512_loadu_si512, _mm512_set1_epi32, _mm512_setzero_si512,
};
use input::{combine_split, weight_offset, with_prepared, Prepared};

/// Groups of columns in flight (independent accumulators) for int8 inputs.
const UNROLL: usize = 4;

/// Groups in flight for split int16 inputs (two accumulators each).
const SPLIT_UNROLL: usize = 2;

/// The sums of one block's sixteen rows: rows 0..8 and 8..16.
type BlockSums = [__m256i; 2];

/// The broadcast word of four int8 codes.
#[inline(always)]
fn word_of_bytes(group: &[i8; 4]) -> i32 {
    i32::from_le_bytes(group.map(|code| code as u8))
}

/// Loads 32 packed bytes.
#[inline]
#[target_feature(enable = "avx2")]
fn load_half(bytes: &[u8; 32]) -> __m256i {
    // SAFETY: the pointer comes from a `&[u8; 32]`: 32 initialized, readable bytes; `loadu` has
    // no alignment requirement.
    unsafe { _mm256_loadu_si256(bytes.as_ptr().cast::<__m256i>()) }
}

/// Loads one 64-byte group.
#[inline]
#[target_feature(enable = "avx512f")]
fn load_group(group: &[u8; GROUP_BYTES]) -> __m512i {
    // SAFETY: the pointer comes from a `&[u8; 64]`: 64 initialized, readable bytes; `loadu` has
    // no alignment requirement.
    unsafe { _mm512_loadu_si512(group.as_ptr().cast::<__m512i>()) }
}

/// The two 32-byte halves of a group (rows 0..8 and 8..16).
#[inline(always)]
fn halves(group: &[u8; GROUP_BYTES]) -> (&[u8; 32], &[u8; 32]) {
    let (low, high) = group.split_at(32);
    match (low.as_chunks::<32>().0, high.as_chunks::<32>().0) {
        ([low], [high]) => (low, high),
        _ => (&[0; 32], &[0; 32]),
    }
}

/// One group's products added to the accumulators, per level and input type.
macro_rules! step {
    (avx, $dot:ident, $acc:expr, $group:expr, $word:expr) => {{
        let [low, high] = $acc;
        let (w_low, w_high) = halves($group);
        let x = _mm256_set1_epi32($word);
        [
            $dot(low, load_half(w_low), x),
            $dot(high, load_half(w_high), x),
        ]
    }};
    (zmm, $dot:ident, $acc:expr, $group:expr, $word:expr) => {
        $dot($acc, load_group($group), _mm512_set1_epi32($word))
    };
}

/// One group's products of the split int16 input added to the `(low, high)` accumulators: the
/// broadcast input words are the unsigned operand, the signed weights the other.
macro_rules! split_step {
    (avx, $dot:ident, $acc:expr, $group:expr, $low:expr, $high:expr) => {{
        let ([l0, l1], [h0, h1]) = $acc;
        let (w_low, w_high) = halves($group);
        let (w_low, w_high) = (load_half(w_low), load_half(w_high));
        let (low, high) = (_mm256_set1_epi32($low), _mm256_set1_epi32($high));
        (
            [$dot(l0, low, w_low), $dot(l1, low, w_high)],
            [$dot(h0, high, w_low), $dot(h1, high, w_high)],
        )
    }};
    (zmm, $dot:ident, $acc:expr, $group:expr, $low:expr, $high:expr) => {{
        let (low, high) = $acc;
        let w = load_group($group);
        (
            $dot(low, _mm512_set1_epi32($low), w),
            $dot(high, _mm512_set1_epi32($high), w),
        )
    }};
}

/// Calls `$body` with `$sums` bound to the block sums of `$input`'s kind from the level module
/// `$level` (the body is expanded once per kind, so that each loop inlines its kernel).
macro_rules! with_sums {
    ($level:path, $input:expr, |$sums:ident| $body:expr) => {{
        use $level as level;
        match $input {
            Prepared::Bytes(x) => {
                let $sums = |block: &[u8]| level::bytes_sums(block, x);
                $body
            }
            Prepared::Split(low, high) => {
                let $sums = |block: &[u8]| level::split_sums(block, low, high);
                $body
            }
        }
    }};
}

/// `fn $name(block, input) -> BlockSums`: the sums of one packed block over an int8 `input`
/// (`ceil(len / 4)` groups) for one level (`avx` | `zmm`); `@finish2` / `@finish` add two
/// or four accumulators of the level into one block of sums.
macro_rules! block_sums {
    ($name:ident, $features:literal, $level:ident, $dot:ident) => {
        #[inline]
        #[target_feature(enable = $features)]
        pub(super) fn $name(block: &[u8], input: &[i8]) -> BlockSums {
            let (groups, _) = block.as_chunks::<GROUP_BYTES>();
            let (words, tail) = input.as_chunks::<GROUP_COLUMNS>();
            let mut acc = [zero!($level); UNROLL];
            let (group_runs, _) = groups.as_chunks::<UNROLL>();
            let (word_runs, _) = words.as_chunks::<UNROLL>();
            for (run, x) in group_runs.iter().zip(word_runs) {
                for ((acc, group), x) in acc.iter_mut().zip(run).zip(x) {
                    *acc = step!($level, $dot, *acc, group, word_of_bytes(x));
                }
            }
            let done = word_runs.len() * UNROLL;
            let rest = groups.get(done..).unwrap_or(&[]);
            for (group, x) in rest.iter().zip(words.get(done..).unwrap_or(&[])) {
                acc[0] = step!($level, $dot, acc[0], group, word_of_bytes(x));
            }
            if !tail.is_empty() {
                // The last, partial group: the missing columns meet zero inputs.
                let mut last = [0; GROUP_COLUMNS];
                for (slot, code) in last.iter_mut().zip(tail) {
                    *slot = *code;
                }
                if let Some(group) = groups.get(words.len()) {
                    acc[0] = step!($level, $dot, acc[0], group, word_of_bytes(&last));
                }
            }
            let [a, b, c, d] = acc;
            block_sums!(@finish $level, a, b, c, d)
        }
    };
    (@finish2 avx, $a:ident, $b:ident) => {
        [
            _mm256_add_epi32($a[0], $b[0]),
            _mm256_add_epi32($a[1], $b[1]),
        ]
    };
    (@finish2 zmm, $a:ident, $b:ident) => {{
        let sum = _mm512_add_epi32($a, $b);
        [
            _mm512_castsi512_si256(sum),
            _mm512_extracti64x4_epi64::<1>(sum),
        ]
    }};
    (@finish avx, $a:ident, $b:ident, $c:ident, $d:ident) => {
        [
            _mm256_add_epi32(
                _mm256_add_epi32($a[0], $b[0]),
                _mm256_add_epi32($c[0], $d[0]),
            ),
            _mm256_add_epi32(
                _mm256_add_epi32($a[1], $b[1]),
                _mm256_add_epi32($c[1], $d[1]),
            ),
        ]
    };
    (@finish zmm, $a:ident, $b:ident, $c:ident, $d:ident) => {{
        let sum = _mm512_add_epi32(_mm512_add_epi32($a, $b), _mm512_add_epi32($c, $d));
        [
            _mm512_castsi512_si256(sum),
            _mm512_extracti64x4_epi64::<1>(sum),
        ]
    }};
}

/// The sixteen rows of a block as `bias + sums` (the weight offset removed).
#[inline]
#[target_feature(enable = "avx2")]
fn with_bias(sums: BlockSums, offset: __m256i, bias: &[i32; PACK_ROWS]) -> BlockSums {
    let (bias, _) = bias.as_chunks::<BLOCK_ROWS>();
    let mut out = sums;
    for (lanes, bias) in out.iter_mut().zip(bias) {
        *lanes = _mm256_add_epi32(_mm256_sub_epi32(*lanes, offset), load_i32(bias));
    }
    out
}

/// `values[first..first + 16]`, zero-padded past the end.
#[inline(always)]
fn padded<T: Copy + Default>(values: &[T], first: usize) -> [T; PACK_ROWS] {
    let rest = values.get(first..).unwrap_or(&[]);
    if let Some(block) = rest.first_chunk::<PACK_ROWS>() {
        return *block;
    }
    let mut block = [T::default(); PACK_ROWS];
    for (slot, value) in block.iter_mut().zip(rest) {
        *slot = *value;
    }
    block
}

/// Stores `block` at `out[first..]` (only the rows before the end).
#[inline(always)]
fn store_block<T: Copy>(out: &mut [T], first: usize, block: [T; PACK_ROWS]) {
    let rest = out.get_mut(first..).unwrap_or(&mut []);
    if let Some(whole) = rest.first_chunk_mut::<PACK_ROWS>() {
        *whole = block;
        return;
    }
    for (slot, value) in rest.iter_mut().zip(block) {
        *slot = value;
    }
}

/// The packed blocks of a layer, [`PACK_ROWS`] rows each.
#[inline(always)]
fn blocks<'p>(packed: &PackedWeights<'p>) -> core::slice::ChunksExact<'p, u8> {
    let block_len = packed.kind().block_len(packed.in_features()).unwrap_or(1);
    packed.bytes().chunks_exact(block_len.max(1))
}

/// The layer loops of one level: `$dot` is its `vpdpbusd`.
macro_rules! packed_level {
    ($level:ident, $features:literal, $dot:ident) => {
        mod $level {
            use super::*;

            /// The sums of one block of split int16 inputs (`low`, `high`: one word per group).
            #[inline]
            #[target_feature(enable = $features)]
            pub(super) fn split_sums(block: &[u8], low: &[i32], high: &[i32]) -> BlockSums {
                let (chunks, _) = block.as_chunks::<GROUP_BYTES>();
                let (groups, row_sums) = chunks.split_at_checked(low.len()).unwrap_or((&[], &[]));
                let zero = zero!($level);
                let mut acc = [(zero, zero); SPLIT_UNROLL];
                let (runs, _) = groups.as_chunks::<SPLIT_UNROLL>();
                let (low_runs, _) = low.as_chunks::<SPLIT_UNROLL>();
                let (high_runs, _) = high.as_chunks::<SPLIT_UNROLL>();
                for ((run, low), high) in runs.iter().zip(low_runs).zip(high_runs) {
                    for (((acc, group), low), high) in acc.iter_mut().zip(run).zip(low).zip(high) {
                        *acc = split_step!($level, $dot, *acc, group, *low, *high);
                    }
                }
                let done = runs.len() * SPLIT_UNROLL;
                let rest = (groups.get(done..).unwrap_or(&[]).iter())
                    .zip(low.get(done..).unwrap_or(&[]))
                    .zip(high.get(done..).unwrap_or(&[]));
                for ((group, low), high) in rest {
                    acc[0] = split_step!($level, $dot, acc[0], group, *low, *high);
                }
                let [(l0, h0), (l1, h1)] = acc;
                let (low, high) = (
                    block_sums!(@finish2 $level, l0, l1),
                    block_sums!(@finish2 $level, h0, h1),
                );
                match row_sums.first() {
                    Some(row_sums) => combine_split(low, high, row_sums),
                    None => low,
                }
            }

            /// `out[o] = requantize_to_i8(bias[o] + dot(row o, input), ...)` for every row.
            #[target_feature(enable = $features)]
            pub(super) fn requantize(
                packed: &PackedWeights<'_>,
                fc: &FullyConnected<'_, i32>,
                requant: &FcRequant<'_, i8>,
                input: Prepared<'_>,
                out: &mut [i8],
            ) {
                let offset = weight_offset(input);
                let finish = |sums: BlockSums,
                              bias: &[i32; PACK_ROWS],
                              multipliers: &[i32; PACK_ROWS],
                              shifts: &[i32; PACK_ROWS]| {
                    let lanes = with_bias(sums, offset, bias);
                    let (multipliers, _) = multipliers.as_chunks::<BLOCK_ROWS>();
                    let (shifts, _) = shifts.as_chunks::<BLOCK_ROWS>();
                    let mut codes = [0_i8; PACK_ROWS];
                    let halves = codes.as_chunks_mut::<BLOCK_ROWS>().0.iter_mut().zip(lanes);
                    for ((codes, lanes), (multipliers, shifts)) in
                        halves.zip(multipliers.iter().zip(shifts))
                    {
                        let block = RequantBlock {
                            multipliers,
                            shifts,
                            zero_point: requant.output_zero_point,
                            bounds: (requant.activation_min, requant.activation_max),
                        };
                        *codes = pack_i8(requantize_lanes(lanes, block));
                    }
                    codes
                };
                // Whole blocks read their channels in place and store in place (copying them
                // per block measured ~0.1 us slower per 256-wide layer); the last block pads.
                let mut blocks = blocks(packed);
                let (whole, tail) = out.as_chunks_mut::<PACK_ROWS>();
                let channels = fc
                    .bias
                    .as_chunks::<PACK_ROWS>()
                    .0
                    .iter()
                    .zip(requant.multipliers.as_chunks::<PACK_ROWS>().0)
                    .zip(requant.shifts.as_chunks::<PACK_ROWS>().0);
                with_sums!(super::$level, input, |sums| {
                    for ((out, ((bias, multipliers), shifts)), block) in
                        whole.iter_mut().zip(channels).zip(blocks.by_ref())
                    {
                        *out = finish(sums(block), bias, multipliers, shifts);
                    }
                    if let (false, Some(block)) = (tail.is_empty(), blocks.next()) {
                        let first = whole.len() * PACK_ROWS;
                        let codes = finish(
                            sums(block),
                            &padded(fc.bias, first),
                            &padded(requant.multipliers, first),
                            &padded(requant.shifts, first),
                        );
                        store_block(tail, 0, codes);
                    }
                })
            }

            /// `acc[o] = bias[o] + dot(row o, input)` (wrapping) for every row.
            #[target_feature(enable = $features)]
            pub(super) fn accumulate(
                packed: &PackedWeights<'_>,
                fc: &FullyConnected<'_, i32>,
                input: Prepared<'_>,
                acc: &mut [i32],
            ) {
                let offset = weight_offset(input);
                with_sums!(super::$level, input, |sums| {
                    for (index, block) in blocks(packed).enumerate() {
                        let first = index * PACK_ROWS;
                        let lanes = with_bias(sums(block), offset, &padded(fc.bias, first));
                        let mut block = [0_i32; PACK_ROWS];
                        let halves = block.as_chunks_mut::<BLOCK_ROWS>().0.iter_mut().zip(lanes);
                        for (half, lanes) in halves {
                            // SAFETY: the pointer comes from a `&mut [i32; 8]`: 32 writable
                            // bytes; no alignment needed.
                            unsafe {
                                _mm256_storeu_si256(half.as_mut_ptr().cast::<__m256i>(), lanes)
                            };
                        }
                        store_block(acc, first, block);
                    }
                })
            }

            block_sums!(bytes_sums, $features, $level, $dot);
        }
    };
}

/// A zero accumulator of the level.
macro_rules! zero {
    (avx) => {
        [_mm256_setzero_si256(); 2]
    };
    (zmm) => {
        _mm512_setzero_si512()
    };
}

packed_level!(avx, "avx2,avxvnni", _mm256_dpbusd_avx_epi32);
packed_level!(zmm, "avx2,avx512f,avx512bw,avx512vnni", _mm512_dpbusd_epi32);

/// Calls `$level::$name(args)` for the token's packed level; `false` when it has none.
macro_rules! by_packed_level {
    ($token:expr, $name:ident($($arg:expr),*)) => {
        // SAFETY: the token's `avx512` flag is set only after `avx512_active()` detected AVX-512
        // F/BW/VNNI, its `vnni` flag only after `avx_vnni_active()` detected AVX-VNNI (both on
        // top of AVX2, which every token has).
        unsafe {
            if $token.avx512() {
                zmm::$name($($arg),*);
                true
            } else if $token.vnni() {
                avx::$name($($arg),*);
                true
            } else {
                false
            }
        }
    };
}

impl Avx2 {
    /// Whether this token runs packed weights (a VNNI level, the packed kernels enabled).
    pub(crate) fn runs_packed(self) -> bool {
        self.packed && (self.avx512() || self.vnni())
    }

    /// Every requantized int8 output of `fc` from its packed copy `packed` (which serves `fc`
    /// and `input`; `requant` passed `FcRequant::validate`); `false` (nothing written) without
    /// a VNNI level.
    pub(crate) fn requantize_packed(
        self,
        packed: &PackedWeights<'_>,
        fc: &FullyConnected<'_, i32>,
        requant: &FcRequant<'_, i8>,
        input: LayerInput<'_>,
        out: &mut [i8],
    ) -> bool {
        self.packed
            && with_prepared(self, input, |input| {
                by_packed_level!(self, requantize(packed, fc, requant, input, out))
            })
    }

    /// The accumulators of `fc`: `true` if every row was written (from its packed copy), else
    /// the whole blocks of eight rows only (`x86::layer`).
    pub(crate) fn accumulate_layer(
        self,
        fc: &FullyConnected<'_, i32>,
        input: LayerInput<'_>,
        acc: &mut [i32],
    ) -> bool {
        if let Some(packed) = fc.packed.filter(|p| p.serves(fc, input)) {
            if self.accumulate_packed(&packed, fc, input, acc) {
                return true;
            }
        }
        self.accumulate_blocks(fc, input, true, acc);
        false
    }

    /// Every accumulator of `fc` from its packed copy; `false` (nothing written) without a VNNI
    /// level.
    pub(crate) fn accumulate_packed(
        self,
        packed: &PackedWeights<'_>,
        fc: &FullyConnected<'_, i32>,
        input: LayerInput<'_>,
        acc: &mut [i32],
    ) -> bool {
        self.packed
            && with_prepared(self, input, |input| {
                by_packed_level!(self, accumulate(packed, fc, input, acc))
            })
    }
}

mod input;
mod wide;

#[cfg(test)]
mod tests;
