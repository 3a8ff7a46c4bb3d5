//! int8 fully connected layer: `y[o] = requant(bias[o] + sum_i w[o][i] * x[i])`.
//!
//! Weights are int8 symmetric per output channel, row-major `[out_features, in_features]`; the
//! int32 bias already contains the folded input zero point (`quant::fold_input_zero_point`), so the
//! kernel is a plain int8 matrix-vector product. The input is int8, or int16 for a first layer fed
//! the 16-bit input plane ([`LayerInput::Int16`]). Requantization per output channel uses
//! [`crate::quant::requantize_to_i8`]; the activation clamp (`activation_min..=activation_max`)
//! implements ReLU-like activations for free, and an optional table ([`LutTable`]) maps every requantized
//! output in the same pass.

#[cfg(target_arch = "x86_64")]
use super::dot::dot_i8_prefix;
use super::dot::RowInput;
use super::lut::{self, LutTable};
use super::rows::{for_each_block, for_each_sum};
use super::KernelError;
#[cfg(target_arch = "x86_64")]
use crate::quant::requantize_to_i8;
use crate::quant::{dequantize_accumulator, requantize_valid, SHIFT_MAX, SHIFT_MIN};

/// The input vector of a fully connected layer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerInput<'a> {
    /// int8 codes (every hidden layer, and a first layer with int8 input).
    Int8(&'a [i8]),
    /// int16 codes of the 16-bit input plane (`model::mlp::InputPrecision::Int16`).
    Int16(&'a [i16]),
}

impl LayerInput<'_> {
    /// Number of input values.
    pub fn len(&self) -> usize {
        match self {
            Self::Int8(values) => values.len(),
            Self::Int16(values) => values.len(),
        }
    }

    /// Whether there are no input values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Weights and bias of one fully connected layer, borrowed (typically `&'static` baked data).
///
/// On Cortex-M cores with the DSP extension the two-row `SMLAD` kernel needs the rows to start on
/// word boundaries: `weights` 4-byte aligned and `in_features` a multiple of 4 (baked modules and
/// blobs align every array to 16 bytes). Other rows take the portable loop: the same results, but
/// the synthetic MLP-256 of the Cortex-M examples took 2.5 times the instructions that way.
///
/// ```
/// use frmd_core::kernels::{FcRequant, FullyConnected};
/// use frmd_core::quant::requantization_multiplier;
///
/// // 2 inputs -> 2 outputs; input scale 0.1, weight scales 0.01, output scale 0.05.
/// static WEIGHTS: [i8; 4] = [10, -20, 127, 0];
/// static BIAS: [i32; 2] = [0, 5];
/// let (m, s) = requantization_multiplier(0.1, 0.01, 0.05).unwrap();
/// let (multipliers, shifts) = ([m, m], [s, s]);
/// let layer = FullyConnected::new(2, 2, &WEIGHTS, &BIAS);
/// let requant = FcRequant {
///     multipliers: &multipliers,
///     shifts: &shifts,
///     output_zero_point: 0,
///     activation_min: -128,
///     activation_max: 127,
/// };
/// let mut out = [0_i8; 2];
/// layer.forward(&requant, &[50, 20], &mut out).unwrap();
/// // acc = [500 - 400, 6350 + 5] = [100, 6355]; times 0.1 * 0.01 / 0.05 = 0.02 -> [2, 127.1]
/// assert_eq!(out, [2, 127]);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FullyConnected<'a> {
    /// Input width.
    pub in_features: usize,
    /// Output width.
    pub out_features: usize,
    /// `[out_features, in_features]` row-major int8 weights.
    pub weights: &'a [i8],
    /// `[out_features]` int32 bias at scale `input_scale * weight_scale[o]`, input zero point folded.
    pub bias: &'a [i32],
}

/// Per-output-channel requantization of a layer's accumulators to int8.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FcRequant<'a> {
    /// `[out_features]` Q31 multiplier mantissas (`quant::quantize_multiplier`), non-negative.
    pub multipliers: &'a [i32],
    /// `[out_features]` shifts in `SHIFT_MIN..=SHIFT_MAX`; positive shifts left.
    pub shifts: &'a [i32],
    /// Output zero point in `[-128, 127]`.
    pub output_zero_point: i32,
    /// Lower clamp of the int8 output.
    pub activation_min: i8,
    /// Upper clamp of the int8 output.
    pub activation_max: i8,
}

impl<'a> FullyConnected<'a> {
    /// Unchecked constructor usable in `const` items; every forward call validates the shapes.
    pub const fn new(
        in_features: usize,
        out_features: usize,
        weights: &'a [i8],
        bias: &'a [i32],
    ) -> Self {
        Self {
            in_features,
            out_features,
            weights,
            bias,
        }
    }

    /// Checks `weights` and `bias` lengths against the shape (both dimensions non-zero).
    pub fn validate(&self) -> Result<(), KernelError> {
        let expected = self.out_features.checked_mul(self.in_features);
        if self.in_features == 0 || self.out_features == 0 || expected != Some(self.weights.len()) {
            return Err(KernelError::WeightsLength);
        }
        if self.bias.len() != self.out_features {
            return Err(KernelError::BiasLength);
        }
        Ok(())
    }

    fn check_input(&self, input_len: usize) -> Result<(), KernelError> {
        self.validate()?;
        if input_len != self.in_features {
            return Err(KernelError::InputLength);
        }
        Ok(())
    }

    /// Raw int32 accumulators `acc[o] = bias[o] + sum_i w[o][i] * input[i]` (wrapping), e.g. for the
    /// last layer, whose output is dequantized to f32 ([`dequantize_accumulators`]).
    pub fn forward_accumulators(&self, input: &[i8], acc: &mut [i32]) -> Result<(), KernelError> {
        self.check_input(input.len())?;
        if acc.len() != self.out_features {
            return Err(KernelError::OutputLength);
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = super::x86::Avx2::get() {
            let mut outputs = acc.iter_mut();
            self.for_each_sum_avx2(avx2, input, true, |sum| {
                if let Some(out) = outputs.next() {
                    *out = sum;
                }
            });
            return Ok(());
        }
        for_each_block(input, self.weights, self.bias, |first, sums| {
            if let Some(out) = acc.get_mut(first..first + sums.len()) {
                out.copy_from_slice(sums);
            }
        });
        Ok(())
    }

    /// Calls `emit(dot(w[o], input))` (bias-free, wrapping) for `o = 0..out_features` in order,
    /// e.g. for the fine plane of a two-plane input. Same kernels as [`Self::forward_accumulators`].
    pub fn for_each_dot(&self, input: &[i8], mut emit: impl FnMut(i32)) -> Result<(), KernelError> {
        self.check_input(input.len())?;
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = super::x86::Avx2::get() {
            self.for_each_sum_avx2(avx2, input, false, emit);
            return Ok(());
        }
        for_each_sum(input, self.weights, &[], &mut emit);
        Ok(())
    }

    /// Requantized int8 output:
    /// `output[o] = requantize_to_i8(bias[o] + dot(w[o], input), multiplier[o], shift[o], ...)`.
    pub fn forward(
        &self,
        requant: &FcRequant<'_>,
        input: &[i8],
        output: &mut [i8],
    ) -> Result<(), KernelError> {
        self.forward_activated(requant, None, LayerInput::Int8(input), output)
    }

    /// [`Self::forward`] for any [`LayerInput`], with `activation` (if any) applied to every
    /// requantized output: `output[o] = lut(requantize_to_i8(...))`.
    pub fn forward_activated(
        &self,
        requant: &FcRequant<'_>,
        activation: Option<&LutTable>,
        input: LayerInput<'_>,
        output: &mut [i8],
    ) -> Result<(), KernelError> {
        requant.validate(self.out_features)?;
        self.forward_validated(requant, activation, input, output)
    }

    /// [`Self::forward_activated`] for a `requant` that passed [`FcRequant::validate`] for this
    /// layer (the per-channel checks are not repeated; the shapes are). With unvalidated
    /// parameters the outputs are unspecified, never a panic.
    pub(crate) fn forward_validated(
        &self,
        requant: &FcRequant<'_>,
        activation: Option<&LutTable>,
        input: LayerInput<'_>,
        output: &mut [i8],
    ) -> Result<(), KernelError> {
        self.check_input(input.len())?;
        let channels = self.out_features;
        if requant.multipliers.len() != channels || requant.shifts.len() != channels {
            return Err(KernelError::RequantLength);
        }
        if output.len() != channels {
            return Err(KernelError::OutputLength);
        }
        match input {
            LayerInput::Int8(values) => {
                #[cfg(target_arch = "x86_64")]
                if let Some(avx2) = super::x86::Avx2::get() {
                    self.forward_avx2(avx2, requant, values, output);
                    if let Some(table) = activation {
                        lut::apply_in_place(table, output);
                    }
                    return Ok(());
                }
                self.requantize_activated(requant, activation, values, output);
            }
            LayerInput::Int16(values) => {
                self.requantize_activated(requant, activation, values, output)
            }
        }
        Ok(())
    }

    /// [`Self::requantize_rows`] through `activation`'s table, or none.
    #[inline(always)]
    fn requantize_activated<T: RowInput>(
        &self,
        requant: &FcRequant<'_>,
        activation: Option<&LutTable>,
        input: &[T],
        output: &mut [i8],
    ) {
        match activation {
            Some(table) => self.requantize_rows(requant, input, output, |v| lut::lookup(table, v)),
            None => self.requantize_rows(requant, input, output, |v| v),
        }
    }

    /// Requantizes `bias[o] + dot(w[o], input)` for every row into `output`, through `map`, two
    /// rows per kernel call (callers checked the shapes; `requant` must be valid for the results
    /// to equal [`requantize_to_i8`]'s).
    #[inline(always)]
    fn requantize_rows<T: RowInput>(
        &self,
        requant: &FcRequant<'_>,
        input: &[T],
        output: &mut [i8],
        map: impl Fn(i8) -> i8,
    ) {
        let Self { weights, bias, .. } = *self;
        let (multipliers, shifts) = (requant.multipliers, requant.shifts);
        for_each_block(input, weights, bias, |first, sums| {
            let end = first + sums.len();
            if let (Some(out), Some(m), Some(s)) = (
                output.get_mut(first..end),
                multipliers.get(first..end),
                shifts.get(first..end),
            ) {
                requantize_block(sums, m, s, requant, out, &map);
            }
        });
    }

    /// [`Self::forward`] with the AVX2 kernels (x86-64; callers checked the shapes and
    /// `requant`): eight output channels per kernel call, requantized in registers; the last
    /// `out_features % 8` channels one at a time. Same outputs as the portable loop.
    #[cfg(target_arch = "x86_64")]
    fn forward_avx2(
        &self,
        avx2: super::x86::Avx2,
        requant: &FcRequant<'_>,
        input: &[i8],
        output: &mut [i8],
    ) {
        use super::x86::{RequantBlock, BLOCK_ROWS};
        let Some(block_len) = self.in_features.checked_mul(BLOCK_ROWS) else {
            return;
        };
        let zero_point = requant.output_zero_point;
        let bounds = (requant.activation_min, requant.activation_max);
        let mut row_blocks = self.weights.chunks_exact(block_len);
        let (out_blocks, out_tail) = output.as_chunks_mut::<BLOCK_ROWS>();
        let (bias_blocks, bias_tail) = self.bias.as_chunks::<BLOCK_ROWS>();
        let (multiplier_blocks, multiplier_tail) = requant.multipliers.as_chunks();
        let (shift_blocks, shift_tail) = requant.shifts.as_chunks();
        let blocks = out_blocks
            .iter_mut()
            .zip(row_blocks.by_ref())
            .zip(bias_blocks)
            .zip(multiplier_blocks.iter().zip(shift_blocks));
        for (((out, rows), bias), (multipliers, shifts)) in blocks {
            let block = RequantBlock {
                multipliers,
                shifts,
                zero_point,
                bounds,
            };
            *out = avx2.requantize_rows(rows, input, bias, block);
        }
        let tail = out_tail
            .iter_mut()
            .zip(row_blocks.remainder().chunks_exact(self.in_features))
            .zip(bias_tail)
            .zip(multiplier_tail.iter().zip(shift_tail));
        for (((out, row), bias), (multiplier, shift)) in tail {
            let acc = bias.wrapping_add(dot_i8_prefix(row, input));
            *out = requantize_to_i8(acc, *multiplier, *shift, zero_point, bounds.0, bounds.1);
        }
    }

    /// Calls `emit(bias[o] + dot(w[o], input))` (or the bias-free dot when `with_bias` is false)
    /// for `o = 0..out_features` in order with the AVX2 kernel, eight rows per call (x86-64;
    /// callers checked the shapes). Same sums as the portable loop.
    #[cfg(target_arch = "x86_64")]
    fn for_each_sum_avx2(
        &self,
        avx2: super::x86::Avx2,
        input: &[i8],
        with_bias: bool,
        mut emit: impl FnMut(i32),
    ) {
        use super::x86::BLOCK_ROWS;
        let Some(block_len) = self.in_features.checked_mul(BLOCK_ROWS) else {
            return;
        };
        let no_bias = [0_i32; BLOCK_ROWS];
        let mut row_blocks = self.weights.chunks_exact(block_len);
        let (bias_blocks, bias_tail) = self.bias.as_chunks::<BLOCK_ROWS>();
        for (rows, bias) in row_blocks.by_ref().zip(bias_blocks) {
            let bias = if with_bias { bias } else { &no_bias };
            avx2.accumulate_rows(rows, input, bias)
                .into_iter()
                .for_each(&mut emit);
        }
        let rows = row_blocks.remainder().chunks_exact(self.in_features);
        for (row, bias) in rows.zip(bias_tail) {
            let bias = if with_bias { *bias } else { 0 };
            emit(bias.wrapping_add(dot_i8_prefix(row, input)));
        }
    }
}

/// `out[r] = map(requantize_valid(sums[r], multipliers[r], shifts[r], ...))` for one block of
/// rows. Not inlined, so that its loop has the registers to itself; a full int8 clamp range (the
/// common case) takes a loop without the two compares.
#[inline(never)]
fn requantize_block(
    sums: &[i32],
    multipliers: &[i32],
    shifts: &[i32],
    requant: &FcRequant<'_>,
    out: &mut [i8],
    map: &impl Fn(i8) -> i8,
) {
    let zero_point = requant.output_zero_point;
    let channels = out.iter_mut().zip(sums).zip(multipliers.iter().zip(shifts));
    if (requant.activation_min, requant.activation_max) == (i8::MIN, i8::MAX) {
        for ((out, sum), (multiplier, shift)) in channels {
            *out = map(requantize_valid(
                *sum,
                *multiplier,
                *shift,
                zero_point,
                i8::MIN,
                i8::MAX,
            ));
        }
    } else {
        let (lo, hi) = (requant.activation_min, requant.activation_max);
        for ((out, sum), (multiplier, shift)) in channels {
            *out = map(requantize_valid(
                *sum,
                *multiplier,
                *shift,
                zero_point,
                lo,
                hi,
            ));
        }
    }
}

impl FcRequant<'_> {
    /// Checks lengths against `out_features`, the zero point, the clamp range, multiplier signs and
    /// shift ranges.
    pub fn validate(&self, out_features: usize) -> Result<(), KernelError> {
        if self.multipliers.len() != out_features || self.shifts.len() != out_features {
            return Err(KernelError::RequantLength);
        }
        if !(-128..=127).contains(&self.output_zero_point) {
            return Err(KernelError::ZeroPoint);
        }
        if self.activation_min > self.activation_max {
            return Err(KernelError::ActivationRange);
        }
        // Folds without early exit: LLVM vectorizes them (this runs on every forward call).
        let bad_multiplier = self.multipliers.iter().fold(false, |bad, m| bad | (*m < 0));
        let bad_shift = self
            .shifts
            .iter()
            .fold(false, |bad, s| bad | !(SHIFT_MIN..=SHIFT_MAX).contains(s));
        if bad_multiplier || bad_shift {
            return Err(KernelError::Multiplier);
        }
        Ok(())
    }
}

/// `out[o] = acc[o] as f32 * scales[o]` where `scales[o] = input_scale * weight_scale[o]`
/// (see [`crate::quant::dequantize_accumulator`]).
pub fn dequantize_accumulators(
    acc: &[i32],
    scales: &[f32],
    out: &mut [f32],
) -> Result<(), KernelError> {
    if scales.len() != acc.len() {
        return Err(KernelError::ScaleLength);
    }
    if out.len() != acc.len() {
        return Err(KernelError::OutputLength);
    }
    for ((a, s), o) in acc.iter().zip(scales).zip(out.iter_mut()) {
        *o = dequantize_accumulator(*a, *s);
    }
    Ok(())
}

#[cfg(test)]
mod tests;
