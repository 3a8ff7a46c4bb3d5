//! Fully connected layer: `y[o] = requant(bias[o] + sum_i w[o][i] * x[i])`, for int8 activations
//! (int32 bias and accumulators) and, generic over [`Precision`], int16 activations (the 16x8
//! scheme: int64 bias and accumulators, see [`Accumulator`]).
//!
//! Weights are int8 symmetric per output channel, row-major `[out_features, in_features]`; the
//! bias already contains the folded input zero point (`quant::fold_input_zero_point`), so the
//! kernel is a plain matrix-vector product. The input is int8 or int16 ([`LayerInput`]: the 16-bit
//! input plane of a first layer, or an int16-activation layer's input). Requantization per output
//! channel uses [`crate::quant::requantize_to_i8`] (int8 outputs) or
//! [`crate::quant::requantize_s64`] (int16 outputs); the activation clamp
//! (`activation_min..=activation_max`) implements ReLU-like activations for free, and an optional
//! table ([`super::LutTable`], or the interpolated [`super::Lut16Table`]) maps every requantized output in
//! the same pass.

use super::dot::RowInput;
pub use super::input::LayerInput;
use super::packed::PackedWeights;
use super::precision::{Accumulator, Precision};
use super::rows::for_each_block;
use super::KernelError;

/// Weights and bias of one fully connected layer, borrowed (typically `&'static` baked data).
/// `A` is the accumulator and bias type: `i32` (int8 activations, the default) or `i64` (int16
/// activations, exact accumulation; see [`Accumulator`]).
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
pub struct FullyConnected<'a, A = i32> {
    /// Input width.
    pub in_features: usize,
    /// Output width.
    pub out_features: usize,
    /// `[out_features, in_features]` row-major int8 weights.
    pub weights: &'a [i8],
    /// `[out_features]` bias (int32, or int64 for int16 activations) at scale
    /// `input_scale * weight_scale[o]`, input zero point folded.
    pub bias: &'a [A],
    /// The same weights packed for a host's dot-product kernels ([`super::packed`]: x86-64
    /// with AVX-VNNI or AVX-512 VNNI; int64 accumulators for layers of one 512-column chunk),
    /// or `None` ([`Self::new`]'s default): the row-major `weights` run. Same results either
    /// way.
    pub packed: Option<PackedWeights<'a>>,
}

/// Per-output-channel requantization of a layer's accumulators to `P` codes: int8 (the default)
/// or int16 ([`Precision`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FcRequant<'a, P = i8> {
    /// `[out_features]` Q31 multiplier mantissas (`quant::quantize_multiplier`), non-negative
    /// (int16 outputs use their Q15 reduction, `quant::reduce_multiplier`).
    pub multipliers: &'a [i32],
    /// `[out_features]` shifts in `SHIFT_MIN..=SHIFT_MAX` (int16 outputs:
    /// `SHIFT16_MIN..=SHIFT16_MAX`); positive shifts left.
    pub shifts: &'a [i32],
    /// Output zero point in `[-128, 127]` (int16 outputs: 0).
    pub output_zero_point: i32,
    /// Lower clamp of the output.
    pub activation_min: P,
    /// Upper clamp of the output.
    pub activation_max: P,
}

impl<'a, A: Accumulator> FullyConnected<'a, A> {
    /// Unchecked constructor usable in `const` items; every forward call validates the shapes.
    pub const fn new(
        in_features: usize,
        out_features: usize,
        weights: &'a [i8],
        bias: &'a [A],
    ) -> Self {
        Self {
            in_features,
            out_features,
            weights,
            bias,
            packed: None,
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

    /// Checks what makes every accumulator the exact `bias + w . x` (O(weights), for a network
    /// to run once when it is built): for `i64` accumulators no weight is -128, every
    /// `|bias| <= quant::BIAS16_MAX` and `in_features <= quant::IN_FEATURES16_MAX`, so that every
    /// 512-column partial sum fits in i32 and every accumulator in `2^47`. For `i32` accumulators
    /// (wrapping by definition) there is nothing to check beyond [`Self::validate`].
    pub fn validate_exact(&self) -> Result<(), KernelError> {
        self.validate()?;
        if A::WEIGHT_MIN > i8::MIN {
            let low = self
                .weights
                .iter()
                .fold(false, |bad, w| bad | (*w < A::WEIGHT_MIN));
            if low {
                return Err(KernelError::WeightRange);
            }
        }
        let bad_bias = self.bias.iter().fold(false, |bad, b| bad | !b.bias_valid());
        if bad_bias || self.in_features > A::MAX_COLUMNS {
            return Err(KernelError::BiasRange);
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

    /// Raw accumulators `acc[o] = bias[o] + sum_i w[o][i] * input[i]` (as [`Accumulator`]
    /// defines) for an int8 or int16 input, e.g. for a last layer whose output is dequantized to
    /// f32 ([`dequantize_accumulators`]). Same kernels as the requantizing forward passes.
    pub fn accumulate(&self, input: LayerInput<'_>, acc: &mut [A]) -> Result<(), KernelError> {
        self.check_input(input.len())?;
        if acc.len() != self.out_features {
            return Err(KernelError::OutputLength);
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = super::x86::Avx2::get() {
            self.accumulate_avx2(avx2, input, acc);
            return Ok(());
        }
        A::accumulate_portable(self, input, acc);
        Ok(())
    }

    /// The portable (and DSP) accumulators of every row into `acc` (callers checked the shapes).
    #[inline(always)]
    pub(super) fn copy_sums(&self, input: LayerInput<'_>, acc: &mut [A]) {
        let mut copy = |first: usize, sums: &[A]| {
            if let Some(out) = acc.get_mut(first..first + sums.len()) {
                out.copy_from_slice(sums);
            }
        };
        match input {
            LayerInput::Int8(values) => for_each_block(values, self.weights, self.bias, &mut copy),
            LayerInput::Int16(values) => for_each_block(values, self.weights, self.bias, &mut copy),
        }
    }

    /// [`Self::accumulate`] with the x86 kernels (callers checked the shapes): the whole blocks
    /// of eight rows by `x86::layer` (the accumulator type's loop), the last `out_features % 8`
    /// rows by the portable dot products.
    #[cfg(target_arch = "x86_64")]
    fn accumulate_avx2(&self, avx2: super::x86::Avx2, input: LayerInput<'_>, acc: &mut [A]) {
        use super::x86::BLOCK_ROWS;
        if A::accumulate_x86(self, avx2, input, acc) {
            return;
        }
        let Some(block_len) = self.in_features.checked_mul(BLOCK_ROWS) else {
            return;
        };
        let rows = self.weights.chunks_exact(block_len).remainder();
        let tail = acc
            .as_chunks_mut::<BLOCK_ROWS>()
            .1
            .iter_mut()
            .zip(rows.chunks_exact(self.in_features))
            .zip(self.bias.as_chunks::<BLOCK_ROWS>().1);
        for ((out, row), bias) in tail {
            use super::rows::for_each_accumulator;
            let bias = core::slice::from_ref(bias);
            match input {
                LayerInput::Int8(values) => {
                    for_each_accumulator(values, row, bias, |sum| *out = sum)
                }
                LayerInput::Int16(values) => {
                    for_each_accumulator(values, row, bias, |sum| *out = sum)
                }
            }
        }
    }

    /// Requantized output for any [`LayerInput`], with `activation` (if any) applied to every
    /// requantized output: `output[o] = table(requantize(bias[o] + dot(w[o], input)))`, through
    /// [`crate::quant::requantize_to_i8`] for int8 outputs and [`crate::quant::requantize_s64`]
    /// for int16 outputs. Validates `requant` ([`FcRequant::validate`]) on every call.
    pub fn forward_activated<P: Precision<Acc = A>>(
        &self,
        requant: &FcRequant<'_, P>,
        activation: Option<&P::Table>,
        input: LayerInput<'_>,
        output: &mut [P],
    ) -> Result<(), KernelError> {
        requant.validate(self.out_features)?;
        self.forward_validated(requant, activation, input, output)
    }

    /// [`Self::forward_activated`] for a `requant` that passed [`FcRequant::validate`] for this
    /// layer (the per-channel checks are not repeated; the shapes are). With unvalidated
    /// parameters the outputs are unspecified, never a panic.
    pub(crate) fn forward_validated<P: Precision<Acc = A>>(
        &self,
        requant: &FcRequant<'_, P>,
        activation: Option<&P::Table>,
        input: LayerInput<'_>,
        output: &mut [P],
    ) -> Result<(), KernelError> {
        self.check_input(input.len())?;
        let channels = self.out_features;
        if requant.multipliers.len() != channels || requant.shifts.len() != channels {
            return Err(KernelError::RequantLength);
        }
        if output.len() != channels {
            return Err(KernelError::OutputLength);
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = super::x86::Avx2::get() {
            P::forward_x86(self, avx2, requant, activation, input, output);
            return Ok(());
        }
        #[cfg(frmd_arm_dsp)]
        if P::forward_dsp(self, requant, activation, input, output) {
            return Ok(());
        }
        P::forward_portable(self, requant, activation, input, output);
        Ok(())
    }

    /// [`Self::requantize_rows`] through `activation`'s table, or none (the portable loops of
    /// [`Self::forward_validated`]).
    #[inline(always)]
    pub(super) fn requantize_activated<P: Precision<Acc = A>>(
        &self,
        requant: &FcRequant<'_, P>,
        activation: Option<&P::Table>,
        input: LayerInput<'_>,
        output: &mut [P],
    ) {
        match (activation, input) {
            (Some(table), LayerInput::Int8(x)) => {
                self.requantize_rows(requant, x, output, |v| P::lookup(table, v))
            }
            (Some(table), LayerInput::Int16(x)) => {
                self.requantize_rows(requant, x, output, |v| P::lookup(table, v))
            }
            (None, LayerInput::Int8(x)) => self.requantize_rows(requant, x, output, |v| v),
            (None, LayerInput::Int16(x)) => self.requantize_rows(requant, x, output, |v| v),
        }
    }

    /// Requantizes `bias[o] + dot(w[o], input)` for every row into `output`, through `map`, two
    /// rows per kernel call (callers checked the shapes; `requant` must be valid for the results
    /// to equal [`Precision::requantize`]'s).
    #[inline(always)]
    fn requantize_rows<T: RowInput, P: Precision<Acc = A>>(
        &self,
        requant: &FcRequant<'_, P>,
        input: &[T],
        output: &mut [P],
        map: impl Fn(P) -> P,
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
}

/// `out[r] = map(P::requantize(sums[r], multipliers[r], shifts[r], ...))` for one block of
/// rows. Not inlined, so that its loop has the registers to itself; a full clamp range (the
/// common case) takes a loop without the two compares.
#[inline(never)]
fn requantize_block<P: Precision>(
    sums: &[P::Acc],
    multipliers: &[i32],
    shifts: &[i32],
    requant: &FcRequant<'_, P>,
    out: &mut [P],
    map: &impl Fn(P) -> P,
) {
    let zero_point = requant.output_zero_point;
    let channels = out.iter_mut().zip(sums).zip(multipliers.iter().zip(shifts));
    if (requant.activation_min, requant.activation_max) == (P::MIN, P::MAX) {
        for ((out, sum), (multiplier, shift)) in channels {
            *out = map(P::requantize(
                *sum,
                *multiplier,
                *shift,
                zero_point,
                P::MIN,
                P::MAX,
            ));
        }
    } else {
        let (lo, hi) = (requant.activation_min, requant.activation_max);
        for ((out, sum), (multiplier, shift)) in channels {
            *out = map(P::requantize(*sum, *multiplier, *shift, zero_point, lo, hi));
        }
    }
}

impl<P: Precision> FcRequant<'_, P> {
    /// Checks lengths against `out_features`, the zero point (`[-128, 127]` for int8 outputs, 0
    /// for int16), the clamp range, multiplier signs and shift ranges (`P::SHIFT_MIN..=
    /// P::SHIFT_MAX`).
    pub fn validate(&self, out_features: usize) -> Result<(), KernelError> {
        if self.multipliers.len() != out_features || self.shifts.len() != out_features {
            return Err(KernelError::RequantLength);
        }
        if !P::zero_point_valid(self.output_zero_point) {
            return Err(KernelError::ZeroPoint);
        }
        if self.activation_min > self.activation_max {
            return Err(KernelError::ActivationRange);
        }
        // Folds without early exit: LLVM vectorizes them (this runs on every forward call).
        let bad_multiplier = self.multipliers.iter().fold(false, |bad, m| bad | (*m < 0));
        let bad_shift = self.shifts.iter().fold(false, |bad, s| {
            bad | !(P::SHIFT_MIN..=P::SHIFT_MAX).contains(s)
        });
        if bad_multiplier || bad_shift {
            return Err(KernelError::Multiplier);
        }
        Ok(())
    }
}

/// `out[o] = acc[o] as f32 * scales[o]` where `scales[o] = input_scale * weight_scale[o]`
/// (see [`crate::quant::dequantize_accumulator`]; int64 accumulators:
/// [`crate::quant::dequantize_wide`]).
pub fn dequantize_accumulators<A: Accumulator>(
    acc: &[A],
    scales: &[f32],
    out: &mut [f32],
) -> Result<(), KernelError> {
    if scales.len() != acc.len() {
        return Err(KernelError::ScaleLength);
    }
    if out.len() != acc.len() {
        return Err(KernelError::OutputLength);
    }
    #[cfg(target_arch = "x86_64")]
    if let Some(avx2) = super::x86::Avx2::get() {
        if A::dequantize_x86(avx2, acc, scales, out) {
            return Ok(());
        }
    }
    for ((a, s), o) in acc.iter().zip(scales).zip(out.iter_mut()) {
        *o = a.dequantize(*s);
    }
    Ok(())
}

#[cfg(all(test, target_arch = "x86_64"))]
mod int16_measure;
#[cfg(test)]
mod int16_tests;
mod int8;
#[cfg(test)]
mod tests;
