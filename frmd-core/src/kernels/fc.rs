//! int8 fully connected layer: `y[o] = requant(bias[o] + sum_i w[o][i] * x[i])`.
//!
//! Weights are int8 symmetric per output channel, row-major `[out_features, in_features]`; the
//! int32 bias already contains the folded input zero point (`quant::fold_input_zero_point`), so the
//! kernel is a plain int8 matrix-vector product. Requantization per output channel uses
//! [`crate::quant::requantize_to_i8`]; the activation clamp (`activation_min..=activation_max`)
//! implements ReLU-like activations for free.

#[cfg(target_arch = "x86_64")]
use super::dot::dot_i8_prefix;
use super::dot::for_each_row_dot;
use super::KernelError;
use crate::quant::{dequantize_accumulator, requantize_to_i8, SHIFT_MAX, SHIFT_MIN};

/// Weights and bias of one fully connected layer, borrowed (typically `&'static` baked data).
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

    fn check_input(&self, input: &[i8]) -> Result<(), KernelError> {
        self.validate()?;
        if input.len() != self.in_features {
            return Err(KernelError::InputLength);
        }
        Ok(())
    }

    /// Raw int32 accumulators `acc[o] = bias[o] + sum_i w[o][i] * input[i]` (wrapping), e.g. for the
    /// last layer, whose output is dequantized to f32 ([`dequantize_accumulators`]).
    pub fn forward_accumulators(&self, input: &[i8], acc: &mut [i32]) -> Result<(), KernelError> {
        self.check_input(input)?;
        if acc.len() != self.out_features {
            return Err(KernelError::OutputLength);
        }
        let mut outputs = acc.iter_mut();
        let mut write = |acc| {
            if let Some(out) = outputs.next() {
                *out = acc;
            }
        };
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = super::x86::Avx2::get() {
            self.for_each_sum_avx2(avx2, input, true, &mut write);
            return Ok(());
        }
        self.for_each_accumulator(input, write);
        Ok(())
    }

    /// Calls `emit(dot(w[o], input))` (bias-free, wrapping) for `o = 0..out_features` in order,
    /// e.g. for the fine plane of a two-plane input. Same kernels as [`Self::forward_accumulators`].
    pub fn for_each_dot(&self, input: &[i8], mut emit: impl FnMut(i32)) -> Result<(), KernelError> {
        self.check_input(input)?;
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = super::x86::Avx2::get() {
            self.for_each_sum_avx2(avx2, input, false, emit);
            return Ok(());
        }
        for_each_row_dot(self.weights, input, &mut emit);
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
        self.check_input(input)?;
        requant.validate(self.out_features)?;
        if output.len() != self.out_features {
            return Err(KernelError::OutputLength);
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = super::x86::Avx2::get() {
            self.forward_avx2(avx2, requant, input, output);
            return Ok(());
        }
        let channels = requant.multipliers.iter().zip(requant.shifts);
        let mut outputs = output.iter_mut().zip(channels);
        self.for_each_accumulator(input, |acc| {
            if let Some((out, (multiplier, shift))) = outputs.next() {
                *out = requantize_to_i8(
                    acc,
                    *multiplier,
                    *shift,
                    requant.output_zero_point,
                    requant.activation_min,
                    requant.activation_max,
                );
            }
        });
        Ok(())
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

    /// Calls `emit(bias[o] + sum_i w[o][i] * input[i])` for `o = 0..out_features` in order
    /// (callers have checked the shapes). The products come from [`for_each_row_dot`], which on
    /// Cortex-M4/M7 is the `SMLAD` kernel (four rows per pass over the input).
    #[inline]
    fn for_each_accumulator(&self, input: &[i8], mut emit: impl FnMut(i32)) {
        let mut biases = self.bias.iter();
        for_each_row_dot(self.weights, input, |dot| {
            let bias = biases.next().copied().unwrap_or(0);
            emit(bias.wrapping_add(dot));
        });
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
mod tests {
    extern crate std;
    use super::*;
    use crate::quant::{quantize_multiplier, reference};
    use crate::rng::SplitMix64;
    use std::{vec, vec::Vec};

    struct Case {
        in_features: usize,
        out_features: usize,
        weights: Vec<i8>,
        bias: Vec<i32>,
        multipliers: Vec<i32>,
        shifts: Vec<i32>,
        zero_point: i32,
        clamp: (i8, i8),
        input: Vec<i8>,
    }

    fn random_case(rng: &mut SplitMix64) -> Case {
        let in_features = 1 + (rng.next_u64() % 97) as usize;
        let out_features = 1 + (rng.next_u64() % 23) as usize;
        let weights = (0..in_features * out_features)
            .map(|_| (rng.next_u64() as u8 as i8).max(-127))
            .collect();
        let bias = (0..out_features)
            .map(|_| (rng.next_u64() as i32) >> 16)
            .collect();
        let mut multipliers = Vec::new();
        let mut shifts = Vec::new();
        for _ in 0..out_features {
            // Real multipliers between 1e-5 and 5e-3, typical of FC layers.
            let u = (rng.next_u64() >> 11) as f64 / (1_u64 << 53) as f64;
            let (m, s) = quantize_multiplier(1e-5 * 500f64.powf(u)).unwrap();
            multipliers.push(m);
            shifts.push(s);
        }
        let zero_point = (rng.next_u64() as u8 as i8) as i32;
        let clamp = if rng.next_u64().is_multiple_of(3) {
            (zero_point as i8, 127) // ReLU
        } else {
            (-128, 127)
        };
        let input = (0..in_features)
            .map(|_| rng.next_u64() as u8 as i8)
            .collect();
        Case {
            in_features,
            out_features,
            weights,
            bias,
            multipliers,
            shifts,
            zero_point,
            clamp,
            input,
        }
    }

    fn naive_accumulators(case: &Case) -> Vec<i64> {
        (0..case.out_features)
            .map(|o| {
                let row = &case.weights[o * case.in_features..(o + 1) * case.in_features];
                let dot: i64 = row
                    .iter()
                    .zip(&case.input)
                    .map(|(w, x)| i64::from(*w) * i64::from(*x))
                    .sum();
                i64::from(case.bias[o]) + dot
            })
            .collect()
    }

    #[test]
    fn matches_naive_wide_reference_on_random_shapes() {
        let mut rng = SplitMix64::new(0xFC);
        let mut unclamped = 0_usize;
        let mut total = 0_usize;
        for _ in 0..400 {
            let case = random_case(&mut rng);
            let layer = FullyConnected::new(
                case.in_features,
                case.out_features,
                &case.weights,
                &case.bias,
            );
            let requant = FcRequant {
                multipliers: &case.multipliers,
                shifts: &case.shifts,
                output_zero_point: case.zero_point,
                activation_min: case.clamp.0,
                activation_max: case.clamp.1,
            };
            let mut acc = vec![0_i32; case.out_features];
            layer.forward_accumulators(&case.input, &mut acc).unwrap();
            let mut dots = Vec::new();
            layer
                .for_each_dot(&case.input, |dot| dots.push(dot))
                .unwrap();
            let without_bias: Vec<i32> = acc
                .iter()
                .zip(&case.bias)
                .map(|(a, b)| a.wrapping_sub(*b))
                .collect();
            assert_eq!(dots, without_bias);
            let mut out = vec![0_i8; case.out_features];
            layer.forward(&requant, &case.input, &mut out).unwrap();
            for (o, wide) in naive_accumulators(&case).into_iter().enumerate() {
                let wide_i32 = i32::try_from(wide).expect("test accumulators fit i32");
                assert_eq!(acc[o], wide_i32);
                let want = reference::requantize(
                    wide_i32,
                    case.multipliers[o],
                    case.shifts[o],
                    case.zero_point,
                    case.clamp.0,
                    case.clamp.1,
                );
                assert_eq!(out[o], want, "channel {o}");
                total += 1;
                if want != case.clamp.0 && want != case.clamp.1 {
                    unclamped += 1;
                }
            }
        }
        assert!(
            unclamped * 4 > total,
            "{unclamped} of {total} outputs unclamped"
        );
    }

    #[test]
    fn length_and_parameter_errors() {
        let weights = [1_i8; 6];
        let bias = [0_i32; 2];
        let layer = FullyConnected::new(3, 2, &weights, &bias);
        let m = [1 << 30; 2];
        let s = [-3; 2];
        let good = FcRequant {
            multipliers: &m,
            shifts: &s,
            output_zero_point: 0,
            activation_min: -128,
            activation_max: 127,
        };
        let mut out = [0_i8; 2];
        let mut acc = [0_i32; 2];
        assert!(layer.forward(&good, &[1, 2, 3], &mut out).is_ok());
        assert_eq!(
            layer.forward(&good, &[1, 2], &mut out),
            Err(KernelError::InputLength)
        );
        assert_eq!(
            layer.forward(&good, &[1, 2, 3], &mut out[..1]),
            Err(KernelError::OutputLength)
        );
        assert_eq!(
            layer.forward_accumulators(&[1, 2, 3], &mut acc[..1]),
            Err(KernelError::OutputLength)
        );
        assert_eq!(
            layer.forward_accumulators(&[1, 2, 3, 4], &mut acc),
            Err(KernelError::InputLength)
        );
        let bad_weights = FullyConnected::new(3, 2, &weights[..5], &bias);
        assert_eq!(
            bad_weights.forward_accumulators(&[1, 2, 3], &mut acc),
            Err(KernelError::WeightsLength)
        );
        let zero_in = FullyConnected::new(0, 2, &[], &bias);
        assert_eq!(
            zero_in.forward_accumulators(&[], &mut acc),
            Err(KernelError::WeightsLength)
        );
        let overflow = FullyConnected::new(usize::MAX, 2, &weights, &bias);
        assert_eq!(overflow.validate(), Err(KernelError::WeightsLength));
        let bad_bias = FullyConnected::new(3, 2, &weights, &bias[..1]);
        assert_eq!(
            bad_bias.forward_accumulators(&[1, 2, 3], &mut acc),
            Err(KernelError::BiasLength)
        );
        let short = FcRequant {
            multipliers: &m[..1],
            ..good
        };
        assert_eq!(
            layer.forward(&short, &[1, 2, 3], &mut out),
            Err(KernelError::RequantLength)
        );
        let zp = FcRequant {
            output_zero_point: 128,
            ..good
        };
        assert_eq!(
            layer.forward(&zp, &[1, 2, 3], &mut out),
            Err(KernelError::ZeroPoint)
        );
        let range = FcRequant {
            activation_min: 5,
            activation_max: 4,
            ..good
        };
        assert_eq!(
            layer.forward(&range, &[1, 2, 3], &mut out),
            Err(KernelError::ActivationRange)
        );
        let shift = [-3, 31];
        let bad_shift = FcRequant {
            shifts: &shift,
            ..good
        };
        assert_eq!(
            layer.forward(&bad_shift, &[1, 2, 3], &mut out),
            Err(KernelError::Multiplier)
        );
        let neg = [1 << 30, -1];
        let bad_mult = FcRequant {
            multipliers: &neg,
            ..good
        };
        assert_eq!(
            layer.forward(&bad_mult, &[1, 2, 3], &mut out),
            Err(KernelError::Multiplier)
        );
    }

    #[test]
    fn dequantizes_accumulators_per_channel() {
        let mut out = [0.0_f32; 3];
        dequantize_accumulators(&[4, -8, 0], &[0.5, 0.25, 3.0], &mut out).unwrap();
        assert_eq!(out, [2.0, -2.0, 0.0]);
        assert_eq!(
            dequantize_accumulators(&[1, 2], &[1.0], &mut out[..2]),
            Err(KernelError::ScaleLength)
        );
        assert_eq!(
            dequantize_accumulators(&[1, 2], &[1.0, 1.0], &mut out),
            Err(KernelError::OutputLength)
        );
    }
}
