//! The int16-activation layers (int64 accumulators, `x86::wide`) of packed weights, for layers
//! of one column chunk (`in_features <= quant::CHUNK16`): there a row's accumulator is the
//! bias plus its int32 sum sign-extended, which the packed block sums give directly (the int16
//! inputs split into bytes, `x86::packed`). The sums
//! then take `x86::wide`'s requantization to int16 and interpolated table, eight rows at a time.
#![allow(unsafe_code)]

use super::{blocks, padded, store_block, weight_offset, with_prepared, BlockSums, Prepared};
use crate::kernels::lut16::Lut16Table;
use crate::kernels::packed::{PackedWeights, PACK_ROWS};
use crate::kernels::x86::wide::{finish_wide, load_i64x4, pack_i16, RequantBlock16};
use crate::kernels::x86::{Avx2, BLOCK_ROWS};
use crate::kernels::{FcRequant, FullyConnected, LayerInput};
use crate::quant::CHUNK16;
use core::arch::x86_64::{
    __m256i, _mm256_add_epi64, _mm256_castsi256_si128, _mm256_cvtepi32_epi64,
    _mm256_extracti128_si256, _mm256_storeu_si256, _mm256_sub_epi32,
};

/// The int64 accumulators of sixteen rows, four per register: `bias + sext(sums - offset)`.
#[inline]
#[target_feature(enable = "avx2")]
fn widen(sums: BlockSums, offset: __m256i, bias: &[i64; PACK_ROWS]) -> [__m256i; 4] {
    let (bias, _) = bias.as_chunks::<4>();
    let mut out = [sums[0]; 4];
    let halves = sums.map(|lanes| {
        let lanes = _mm256_sub_epi32(lanes, offset);
        [
            _mm256_cvtepi32_epi64(_mm256_castsi256_si128(lanes)),
            _mm256_cvtepi32_epi64(_mm256_extracti128_si256::<1>(lanes)),
        ]
    });
    for ((slot, lanes), bias) in out.iter_mut().zip(halves.as_flattened()).zip(bias) {
        *slot = _mm256_add_epi64(*lanes, load_i64x4(bias));
    }
    out
}

/// The layer loops of one level over its block sums `$sums`.
macro_rules! wide_level {
    ($level:ident, $features:literal) => {
        mod $level {
            use super::*;

            /// `out[o] = table(requantize_s64(acc_o, ...))` for every row.
            #[target_feature(enable = $features)]
            pub(super) fn requantize(
                packed: &PackedWeights<'_>,
                fc: &FullyConnected<'_, i64>,
                requant: &FcRequant<'_, i16>,
                table: Option<&Lut16Table>,
                input: Prepared<'_>,
                out: &mut [i16],
            ) {
                let offset = weight_offset(input);
                let bounds = (requant.activation_min, requant.activation_max);
                with_sums!(super::super::$level, input, |sums| {
                    for (index, block) in blocks(packed).enumerate() {
                        let first = index * PACK_ROWS;
                        let acc = widen(sums(block), offset, &padded(fc.bias, first));
                        let (multipliers, shifts) = (
                            padded(requant.multipliers, first),
                            padded(requant.shifts, first),
                        );
                        let mut codes = [0_i16; PACK_ROWS];
                        let halves = codes
                            .as_chunks_mut::<BLOCK_ROWS>()
                            .0
                            .iter_mut()
                            .zip(acc.as_chunks::<2>().0)
                            .zip(multipliers.as_chunks::<BLOCK_ROWS>().0)
                            .zip(shifts.as_chunks::<BLOCK_ROWS>().0);
                        for (((codes, [low, high]), multipliers), shifts) in halves {
                            let block = RequantBlock16 {
                                multipliers,
                                shifts,
                                bounds,
                            };
                            *codes = pack_i16(finish_wide(*low, *high, block, table));
                        }
                        store_block(out, first, codes);
                    }
                })
            }

            /// `acc[o] = bias[o] + dot(row o, input)` (int64) for every row.
            #[target_feature(enable = $features)]
            pub(super) fn accumulate(
                packed: &PackedWeights<'_>,
                fc: &FullyConnected<'_, i64>,
                input: Prepared<'_>,
                acc: &mut [i64],
            ) {
                let offset = weight_offset(input);
                with_sums!(super::super::$level, input, |sums| {
                    for (index, block) in blocks(packed).enumerate() {
                        let first = index * PACK_ROWS;
                        let lanes = widen(sums(block), offset, &padded(fc.bias, first));
                        let mut sums = [0_i64; PACK_ROWS];
                        for (quarter, lanes) in sums.as_chunks_mut::<4>().0.iter_mut().zip(lanes) {
                            // SAFETY: the pointer comes from a `&mut [i64; 4]`: 32 writable
                            // bytes; no alignment needed.
                            unsafe {
                                _mm256_storeu_si256(quarter.as_mut_ptr().cast::<__m256i>(), lanes)
                            };
                        }
                        store_block(acc, first, sums);
                    }
                })
            }
        }
    };
}

wide_level!(avx, "avx2,avxvnni");
wide_level!(zmm, "avx2,avx512f,avx512bw,avx512vnni");

impl Avx2 {
    /// Every int16 output (requantized, then `table`) of the int64-accumulating `fc` from its
    /// packed copy (which serves `fc` and `input`); `false` (nothing written) without a packed
    /// level or for a layer of more than one column chunk.
    pub(crate) fn requantize_packed_wide(
        self,
        packed: &PackedWeights<'_>,
        fc: &FullyConnected<'_, i64>,
        requant: &FcRequant<'_, i16>,
        table: Option<&Lut16Table>,
        input: LayerInput<'_>,
        out: &mut [i16],
    ) -> bool {
        self.packed
            && fc.in_features <= CHUNK16
            && with_prepared(self, input, |input| {
                by_packed_level!(self, requantize(packed, fc, requant, table, input, out))
            })
    }

    /// The int64 accumulators of `fc`: `true` if every row was written (from its packed copy),
    /// else the whole blocks of eight rows only (`x86::layer`).
    pub(crate) fn accumulate_layer_wide(
        self,
        fc: &FullyConnected<'_, i64>,
        input: LayerInput<'_>,
        acc: &mut [i64],
    ) -> bool {
        if let Some(packed) = fc.packed.filter(|p| p.serves(fc, input)) {
            if self.accumulate_packed_wide(&packed, fc, input, acc) {
                return true;
            }
        }
        self.accumulate_blocks_wide(fc, input, acc);
        false
    }

    /// Every int64 accumulator of `fc` from its packed copy; `false` (nothing written) as for
    /// [`Self::requantize_packed_wide`].
    pub(crate) fn accumulate_packed_wide(
        self,
        packed: &PackedWeights<'_>,
        fc: &FullyConnected<'_, i64>,
        input: LayerInput<'_>,
        acc: &mut [i64],
    ) -> bool {
        self.packed
            && fc.in_features <= CHUNK16
            && with_prepared(self, input, |input| {
                by_packed_level!(self, accumulate(packed, fc, input, acc))
            })
    }
}
