//! The int8-activation entry points of [`FullyConnected`] (int32 accumulators): raw
//! accumulators, bias-free dot products, the requantized int8 forward pass and its AVX2 form.

#[cfg(target_arch = "x86_64")]
use crate::kernels::dot::{dot_i8_i16_prefix, dot_i8_prefix};
use crate::kernels::rows::{for_each_block, for_each_sum};
use crate::kernels::{FcRequant, FullyConnected, KernelError, LayerInput};
#[cfg(target_arch = "x86_64")]
use crate::quant::requantize_to_i8;

impl<'a> FullyConnected<'a, i32> {
    /// Raw int32 accumulators `acc[o] = bias[o] + sum_i w[o][i] * input[i]` (wrapping), e.g. for
    /// the last layer, whose output is dequantized to f32
    /// ([`crate::kernels::dequantize_accumulators`]).
    pub fn forward_accumulators(&self, input: &[i8], acc: &mut [i32]) -> Result<(), KernelError> {
        self.check_input(input.len())?;
        if acc.len() != self.out_features {
            return Err(KernelError::OutputLength);
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = crate::kernels::x86::Avx2::get() {
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
        if let Some(avx2) = crate::kernels::x86::Avx2::get() {
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

    /// [`Self::forward`] with the x86 kernels (callers checked the shapes and `requant`): the
    /// packed weights if the layer has them and the CPU a VNNI level, else the
    /// whole blocks of eight output channels by `x86::layer` (requantized in registers), the
    /// last `out_features % 8` channels one at a time. Same outputs as the portable loop. int16
    /// inputs (a 16-bit first-layer input plane) take the same kernels with the codes loaded as
    /// they are instead of sign-extended.
    #[cfg(target_arch = "x86_64")]
    pub(in crate::kernels) fn forward_avx2(
        &self,
        avx2: crate::kernels::x86::Avx2,
        requant: &FcRequant<'_>,
        input: LayerInput<'_>,
        output: &mut [i8],
    ) {
        if let Some(packed) = self.packed.filter(|p| p.serves(self, input)) {
            if avx2.requantize_packed(&packed, self, requant, input, output) {
                return;
            }
        }
        avx2.requantize_blocks(self, requant, input, output);
        let zero_point = requant.output_zero_point;
        let bounds = (requant.activation_min, requant.activation_max);
        let tail =
            |(out, row, bias, multiplier, shift): crate::kernels::x86::RowOf<'_, i8, i32>| {
                let dot = match input {
                    LayerInput::Int8(values) => dot_i8_prefix(row, values),
                    LayerInput::Int16(values) => dot_i8_i16_prefix(row, values),
                };
                let acc = bias.wrapping_add(dot);
                *out = requantize_to_i8(acc, multiplier, shift, zero_point, bounds.0, bounds.1);
            };
        crate::kernels::x86::for_each_tail_row(self, requant, output, tail);
    }

    /// Calls `emit(bias[o] + dot(w[o], input))` (or the bias-free dot when `with_bias` is false)
    /// for `o = 0..out_features` in order with the x86 kernels (callers checked the shapes). Same
    /// sums as the portable loop.
    #[cfg(target_arch = "x86_64")]
    fn for_each_sum_avx2(
        &self,
        avx2: crate::kernels::x86::Avx2,
        input: &[i8],
        with_bias: bool,
        mut emit: impl FnMut(i32),
    ) {
        use crate::kernels::x86::BLOCK_ROWS;
        const CHUNK_ROWS: usize = 8 * BLOCK_ROWS;
        let width = self.in_features;
        let Some(chunk_len) = width.checked_mul(CHUNK_ROWS) else {
            return;
        };
        // Up to 64 rows at a time through a stack buffer: the whole blocks of eight by the
        // kernels, the rest (in the last chunk only) one by one.
        let mut buffer = [0_i32; CHUNK_ROWS];
        let chunks = self
            .weights
            .chunks(chunk_len)
            .zip(self.bias.chunks(CHUNK_ROWS));
        for (weights, bias) in chunks {
            let Some(sums) = buffer.get_mut(..bias.len()) else {
                return;
            };
            let layer = FullyConnected::new(width, bias.len(), weights, bias);
            avx2.accumulate_blocks(&layer, LayerInput::Int8(input), with_bias, sums);
            let (_, rest) = sums.as_chunks_mut::<BLOCK_ROWS>();
            let done = bias.len() - rest.len();
            let rows = weights.chunks_exact(width).skip(done);
            for ((slot, row), bias) in rest.iter_mut().zip(rows).zip(bias.iter().skip(done)) {
                let bias = if with_bias { *bias } else { 0 };
                *slot = bias.wrapping_add(dot_i8_prefix(row, input));
            }
            sums.iter().copied().for_each(&mut emit);
        }
    }
}
