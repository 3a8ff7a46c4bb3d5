//! The element types of quantized activations, so that one fully connected kernel serves both
//! schemes:
//!
//! | | [`Precision`] `i8` (TFLite int8) | [`Precision`] `i16` (TFLite 16x8) |
//! | --- | --- | --- |
//! | activations | asymmetric, zero point in `[-128, 127]` | symmetric, zero point 0 |
//! | accumulator, bias ([`Accumulator`]) | `i32`, wrapping over the whole row | `i64`, exact: int32 partial sums of 512 columns |
//! | requantization | [`crate::quant::requantize_valid`] (Q31, double rounding) | [`crate::quant::requantize_s64`] (Q15, one rounding) |
//! | shifts | `SHIFT_MIN..=SHIFT_MAX` (-31..=30) | `SHIFT16_MIN..=SHIFT16_MAX` (-31..=7) |
//! | activation table | [`LutTable`] (256 entries) | [`Lut16Table`] (513 knots, interpolated) |
//!
//! Both traits are sealed (implemented for exactly these types). The kernels' inner loops are
//! the same for both: every row kernel computes int32 wrapping sums over a range of columns; the
//! accumulator type decides how those sums become a row's accumulator (`sealed::Accumulate`).

use core::fmt::Debug;
use core::ops::Range;

use super::input::LayerInput;
use super::lut::{self, LutTable};
#[cfg(not(frmd_arm_dsp))]
use super::lut16;
use super::lut16::Lut16Table;
use super::BLOCK_ROWS;
#[cfg(not(frmd_arm_dsp))]
use crate::quant::requantize_s64;
use crate::quant::{
    dequantize_accumulator, dequantize_wide, quantize_sym16, requantize_valid, QuantParams,
    BIAS16_MAX, CHUNK16, IN_FEATURES16_MAX, SHIFT16_MAX, SHIFT16_MIN, SHIFT_MAX, SHIFT_MIN,
};

mod quantize;

/// The crate-private parts of the two traits (a public trait in a crate-private module: nameable
/// inside the crate only, so nobody else can implement [`Accumulator`] or [`Precision`]). Its
/// hooks take crate-private types (the AVX2 token), which nobody outside can name or call.
#[allow(private_interfaces)]
pub(crate) mod sealed {
    use core::ops::Range;

    /// How the int32 column sums of the row kernels make a block of accumulators.
    pub trait Accumulate: Copy {
        /// Fills `sums` (at most `BLOCK_ROWS` rows of `width` columns) with
        /// `bias[r] + the row's products` by calls `kernel(columns, start, residues)`, each of
        /// which must set `residues[r] = start[r] + sum over columns of the row's products`
        /// (int32, wrapping; missing `start` entries count as 0).
        fn block(
            bias: &[Self],
            sums: &mut [Self],
            width: usize,
            kernel: impl FnMut(Range<usize>, &[i32], &mut [i32]),
        );

        /// `FullyConnected::accumulate` with the portable loops (the caller checked the shapes).
        /// Implemented per type without `#[inline]` on hosts, so that it is compiled in
        /// frmd-core with frmd-core's optimization whoever instantiates the generic callers.
        fn accumulate_portable(
            fc: &crate::kernels::FullyConnected<'_, Self>,
            input: crate::kernels::LayerInput<'_>,
            acc: &mut [Self],
        );

        /// The accumulators of `fc` with the x86 kernels (the caller checked the shapes):
        /// `true` if every row was written (packed weights), else the whole blocks of eight
        /// rows only (`x86::layer`) and the caller does the remaining rows.
        #[cfg(target_arch = "x86_64")]
        fn accumulate_x86(
            fc: &crate::kernels::FullyConnected<'_, Self>,
            avx2: crate::kernels::x86::Avx2,
            input: crate::kernels::LayerInput<'_>,
            acc: &mut [Self],
        ) -> bool;

        /// `kernels::dequantize_accumulators` with the x86 kernels (the caller checked the
        /// lengths): `true` if they wrote every output (int64 accumulators, eight at a time,
        /// the same bits as `Accumulator::dequantize`), `false` to use the scalar loop.
        #[cfg(target_arch = "x86_64")]
        fn dequantize_x86(
            _avx2: crate::kernels::x86::Avx2,
            _acc: &[Self],
            _scales: &[f32],
            _out: &mut [f32],
        ) -> bool {
            false
        }
    }

    /// The x86-64 requantizing kernels of a precision, and the DSP cores' fused int16 path.
    pub trait Quantize {
        /// `FullyConnected::forward_validated` on DSP cores when the precision has a kernel of
        /// its own for this layer (the caller checked every length); `false` means "use the
        /// generic rows". int8: never; int16: layers up to 512 columns (one chunk), where the
        /// bias is added to each row's int32 sum inside the requantization loop.
        #[cfg(frmd_arm_dsp)]
        #[inline(always)]
        fn forward_dsp(
            _fc: &crate::kernels::FullyConnected<'_, <Self as super::Precision>::Acc>,
            _requant: &crate::kernels::FcRequant<'_, Self>,
            _table: Option<&<Self as super::Precision>::Table>,
            _input: crate::kernels::LayerInput<'_>,
            _output: &mut [Self],
        ) -> bool
        where
            Self: super::Precision,
        {
            false
        }

        /// `FullyConnected::forward_validated` with the portable loops (the caller checked every
        /// length), compiled in frmd-core as [`Accumulate::accumulate_portable`] is.
        fn forward_portable(
            fc: &crate::kernels::FullyConnected<'_, <Self as super::Precision>::Acc>,
            requant: &crate::kernels::FcRequant<'_, Self>,
            table: Option<&<Self as super::Precision>::Table>,
            input: crate::kernels::LayerInput<'_>,
            output: &mut [Self],
        ) where
            Self: super::Precision;

        /// `FullyConnected::forward_validated` with the x86 kernels (the caller checked every
        /// length).
        #[cfg(target_arch = "x86_64")]
        fn forward_x86(
            fc: &crate::kernels::FullyConnected<'_, <Self as super::Precision>::Acc>,
            avx2: crate::kernels::x86::Avx2,
            requant: &crate::kernels::FcRequant<'_, Self>,
            table: Option<&<Self as super::Precision>::Table>,
            input: crate::kernels::LayerInput<'_>,
            output: &mut [Self],
        ) where
            Self: super::Precision;
    }
}

/// The accumulator (and bias) type of a fully connected layer: `i32` (int8 activations) or `i64`
/// (int16 activations). Sealed.
///
/// A row's accumulator is, for every kernel and target:
/// - `i32`: `bias + sum_i w_i x_i` modulo 2^32 (wrapping, like `SMLAD`); [`Self::CHUNK`] is
///   `usize::MAX` (one pass over the row);
/// - `i64`: `bias + sum over chunks c of sext32(sum_{i in c} w_i x_i mod 2^32)` with the chunks
///   `[0, 512), [512, 1024), ...` of the columns. With every weight in `[-127, 127]` each chunk's
///   sum fits in i32 (`512 * 127 * 32768 < 2^31`), so this is the exact sum; with `-128` weights
///   it is still the same value on every target. [`crate::kernels::FullyConnected::validate_exact`]
///   checks the weights, `|bias| <=` [`BIAS16_MAX`] and the width, which bound every accumulator by
///   `2^47` (the domain of [`crate::quant::requantize_s64`]).
pub trait Accumulator:
    sealed::Accumulate
    + bytemuck::Pod
    + Into<i64>
    + Default
    + Debug
    + PartialEq
    + Eq
    + Send
    + Sync
    + 'static
{
    /// Zero (usable in `const` items, e.g. to initialize scratch arrays).
    const ZERO: Self;
    /// Columns per int32 partial sum.
    const CHUNK: usize;
    /// Smallest weight for which the accumulation is exact (`-128` for `i32`: wrapping is the
    /// definition there; `-127` for `i64`).
    const WEIGHT_MIN: i8;
    /// Widest input for which every accumulator of a valid layer stays in the exact domain.
    const MAX_COLUMNS: usize;
    /// Whether `self` is a valid bias (always for `i32`; `|bias| <= 2^46` for `i64`).
    fn bias_valid(self) -> bool;
    /// The accumulator's real value at `scale` (`input_scale * weight_scale[o]`):
    /// [`dequantize_accumulator`] (`acc as f32 * scale`) for `i32`, [`dequantize_wide`] for `i64`.
    fn dequantize(self, scale: f32) -> f32;
}

#[allow(private_interfaces)]
impl sealed::Accumulate for i32 {
    /// One kernel call over the whole row, started at the bias: the int8 kernels as they were.
    #[inline(always)]
    fn block(
        bias: &[i32],
        sums: &mut [i32],
        width: usize,
        mut kernel: impl FnMut(Range<usize>, &[i32], &mut [i32]),
    ) {
        kernel(0..width, bias, sums);
    }

    #[cfg_attr(target_os = "none", inline(always))]
    fn accumulate_portable(
        fc: &super::FullyConnected<'_, i32>,
        input: LayerInput<'_>,
        acc: &mut [i32],
    ) {
        fc.copy_sums(input, acc);
    }

    #[cfg(target_arch = "x86_64")]
    #[inline]
    fn accumulate_x86(
        fc: &super::FullyConnected<'_, i32>,
        avx2: super::x86::Avx2,
        input: LayerInput<'_>,
        acc: &mut [i32],
    ) -> bool {
        avx2.accumulate_layer(fc, input, acc)
    }
}

impl Accumulator for i32 {
    const ZERO: i32 = 0;
    const CHUNK: usize = usize::MAX;
    const WEIGHT_MIN: i8 = i8::MIN;
    const MAX_COLUMNS: usize = usize::MAX;
    #[inline(always)]
    fn bias_valid(self) -> bool {
        true
    }
    #[inline(always)]
    fn dequantize(self, scale: f32) -> f32 {
        dequantize_accumulator(self, scale)
    }
}

#[allow(private_interfaces)]
impl sealed::Accumulate for i64 {
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn dequantize_x86(
        avx2: super::x86::Avx2,
        acc: &[i64],
        scales: &[f32],
        out: &mut [f32],
    ) -> bool {
        avx2.dequantize_wide(acc, scales, out);
        true
    }

    /// One kernel call per 512-column chunk, started at 0; each int32 result is sign-extended and
    /// added to the row's int64 sum (the first chunk's to the bias).
    #[inline(always)]
    fn block(
        bias: &[i64],
        sums: &mut [i64],
        width: usize,
        mut kernel: impl FnMut(Range<usize>, &[i32], &mut [i32]),
    ) {
        // Start values for the row kernels: zeros they can read as pairs in place.
        const ZERO: [i32; BLOCK_ROWS] = [0; BLOCK_ROWS];
        let mut residues = [0_i32; BLOCK_ROWS];
        let rows = sums.len().min(BLOCK_ROWS);
        let (Some(sums), Some(residues)) = (sums.get_mut(..rows), residues.get_mut(..rows)) else {
            return;
        };
        let first_end = width.min(CHUNK16);
        kernel(0..first_end, &ZERO, residues);
        match bias.get(..rows) {
            Some(bias) => {
                for ((sum, b), residue) in sums.iter_mut().zip(bias).zip(residues.iter()) {
                    *sum = b.wrapping_add(i64::from(*residue));
                }
            }
            None => {
                let bias = bias.iter().chain(core::iter::repeat(&0));
                for ((sum, b), residue) in sums.iter_mut().zip(bias).zip(residues.iter()) {
                    *sum = b.wrapping_add(i64::from(*residue));
                }
            }
        }
        let mut start = first_end;
        while start < width {
            let end = start.saturating_add(CHUNK16).min(width);
            kernel(start..end, &ZERO, residues);
            for (sum, residue) in sums.iter_mut().zip(residues.iter()) {
                *sum = sum.wrapping_add(i64::from(*residue));
            }
            start = end;
        }
    }

    #[cfg_attr(target_os = "none", inline(always))]
    fn accumulate_portable(
        fc: &super::FullyConnected<'_, i64>,
        input: LayerInput<'_>,
        acc: &mut [i64],
    ) {
        fc.copy_sums(input, acc);
    }

    #[cfg(target_arch = "x86_64")]
    #[inline]
    fn accumulate_x86(
        fc: &super::FullyConnected<'_, i64>,
        avx2: super::x86::Avx2,
        input: LayerInput<'_>,
        acc: &mut [i64],
    ) -> bool {
        avx2.accumulate_layer_wide(fc, input, acc)
    }
}

impl Accumulator for i64 {
    const ZERO: i64 = 0;
    const CHUNK: usize = CHUNK16;
    const WEIGHT_MIN: i8 = -127;
    const MAX_COLUMNS: usize = IN_FEATURES16_MAX;
    #[inline(always)]
    fn bias_valid(self) -> bool {
        self.unsigned_abs() <= BIAS16_MAX.unsigned_abs()
    }
    #[inline(always)]
    fn dequantize(self, scale: f32) -> f32 {
        dequantize_wide(self, scale)
    }
}

/// The element type of quantized activations: `i8` (TFLite int8) or `i16` (TFLite 16x8). Sealed.
///
/// Selects the layer's accumulator ([`Self::Acc`], also the bias type), its requantization, the
/// valid shifts and zero points, and its activation table.
pub trait Precision:
    sealed::Quantize + bytemuck::Pod + Default + Debug + Ord + Send + Sync + 'static
{
    /// The code of real value 0 at zero point 0 (usable in `const` items).
    const ZERO: Self;
    /// Bits of a code (8 or 16).
    const BITS: u8;
    /// Entries of an activation table (256 for [`LutTable`], [`super::LUT16_LEN`] for [`Lut16Table`]).
    const TABLE_LEN: usize;
    /// Accumulator and bias type.
    type Acc: Accumulator;
    /// Activation table type ([`LutTable`] or [`Lut16Table`]).
    type Table: Copy + Debug + PartialEq + Eq + Send + Sync + 'static;
    /// Smallest code.
    const MIN: Self;
    /// Largest code.
    const MAX: Self;
    /// Smallest valid per-channel shift.
    const SHIFT_MIN: i32;
    /// Largest valid per-channel shift.
    const SHIFT_MAX: i32;
    /// Whether `zero_point` is a valid output zero point (`[-128, 127]` for i8, 0 for i16).
    fn zero_point_valid(zero_point: i32) -> bool;
    /// Requantizes one accumulator for parameters that passed `FcRequant::validate`
    /// ([`requantize_valid`] or [`requantize_s64`], which ignores the zero point: it is 0).
    fn requantize(
        acc: Self::Acc,
        multiplier: i32,
        shift: i32,
        zero_point: i32,
        lo: Self,
        hi: Self,
    ) -> Self;
    /// The activation table's value at `x` ([`lut::lookup`] or [`lut16::lookup`]).
    fn lookup(table: &Self::Table, x: Self) -> Self;
    /// The codes as a layer input.
    fn layer_input(values: &[Self]) -> LayerInput<'_>;
    /// `entries` as a table, if there are exactly [`Self::TABLE_LEN`] of them.
    fn table(entries: &[Self]) -> Option<&Self::Table>;
    /// The entries of `table`.
    fn table_entries(table: &Self::Table) -> &[Self];
    /// The code of the real `value` at `params`: int8 [`QuantParams::quantize`] (asymmetric);
    /// int16 [`quantize_sym16`] at `params.scale` (symmetric: an int16 activation's zero point
    /// is 0, which [`Self::zero_point_valid`] demands of its parameters).
    fn quantize(value: f32, params: QuantParams) -> Self;
}

impl Precision for i8 {
    const ZERO: i8 = 0;
    const BITS: u8 = 8;
    const TABLE_LEN: usize = 256;
    type Acc = i32;
    type Table = LutTable;
    const MIN: i8 = i8::MIN;
    const MAX: i8 = i8::MAX;
    const SHIFT_MIN: i32 = SHIFT_MIN;
    const SHIFT_MAX: i32 = SHIFT_MAX;
    #[inline(always)]
    fn zero_point_valid(zero_point: i32) -> bool {
        (-128..=127).contains(&zero_point)
    }
    #[inline(always)]
    fn requantize(acc: i32, multiplier: i32, shift: i32, zero_point: i32, lo: i8, hi: i8) -> i8 {
        requantize_valid(acc, multiplier, shift, zero_point, lo, hi)
    }
    #[inline(always)]
    fn lookup(table: &LutTable, x: i8) -> i8 {
        lut::lookup(table, x)
    }
    #[inline(always)]
    fn layer_input(values: &[i8]) -> LayerInput<'_> {
        LayerInput::Int8(values)
    }
    fn table(entries: &[i8]) -> Option<&LutTable> {
        entries.try_into().ok()
    }
    fn table_entries(table: &LutTable) -> &[i8] {
        table
    }
    #[inline(always)]
    fn quantize(value: f32, params: QuantParams) -> i8 {
        params.quantize(value)
    }
}

impl Precision for i16 {
    const ZERO: i16 = 0;
    const BITS: u8 = 16;
    const TABLE_LEN: usize = super::lut16::LUT16_LEN;
    type Acc = i64;
    type Table = Lut16Table;
    const MIN: i16 = i16::MIN;
    const MAX: i16 = i16::MAX;
    const SHIFT_MIN: i32 = SHIFT16_MIN;
    const SHIFT_MAX: i32 = SHIFT16_MAX;
    #[inline(always)]
    fn zero_point_valid(zero_point: i32) -> bool {
        zero_point == 0
    }
    /// On DSP cores the rounding shift and saturation are one `asm!` block
    /// (`dsp_asm::scale_s64`, the same steps; the QEMU digests compare it with the host).
    #[inline(always)]
    fn requantize(
        acc: i64,
        multiplier: i32,
        shift: i32,
        _zero_point: i32,
        lo: i16,
        hi: i16,
    ) -> i16 {
        #[cfg(frmd_arm_dsp)]
        {
            let r = super::dsp_asm::scale_s64(acc, multiplier, shift);
            r.max(i32::from(lo)).min(i32::from(hi)) as i16
        }
        #[cfg(not(frmd_arm_dsp))]
        requantize_s64(acc, multiplier, shift, lo, hi)
    }
    /// On DSP cores one `SMLAD` of the knot pair (`dsp_asm::lookup16`, the same arithmetic).
    #[inline(always)]
    fn lookup(table: &Lut16Table, x: i16) -> i16 {
        #[cfg(frmd_arm_dsp)]
        {
            super::dsp_asm::lookup16(table, x)
        }
        #[cfg(not(frmd_arm_dsp))]
        lut16::lookup(table, x)
    }
    #[inline(always)]
    fn layer_input(values: &[i16]) -> LayerInput<'_> {
        LayerInput::Int16(values)
    }
    fn table(entries: &[i16]) -> Option<&Lut16Table> {
        entries.try_into().ok()
    }
    fn table_entries(table: &Lut16Table) -> &[i16] {
        table
    }
    #[inline(always)]
    fn quantize(value: f32, params: QuantParams) -> i16 {
        quantize_sym16(value, params.scale)
    }
}
