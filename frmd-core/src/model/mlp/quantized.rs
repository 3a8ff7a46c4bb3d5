//! The quantized MLP ([`QuantMlp`], int8 weights with int8 or int16 activations): input
//! quantization, hidden [`RequantizedLinear`] layers, a dequantized [`Int8Linear`] output layer.

use super::{
    check_lengths, check_widths, quantize_input_i16, quantize_input_two_plane, InputPrecision,
    ModelError,
};
use crate::kernels::{dequantize_accumulators, LayerInput, Precision};
use crate::model::linear::{Int8Linear, RequantizedLinear};
use crate::quant::QuantParams;

/// Quantized MLP: hidden [`RequantizedLinear`]s, then an [`Int8Linear`] output layer, with int8
/// weights and `P` activations (`i8`, the default, or `i16`: the 16x8 scheme, see
/// [`MlpPrecision`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QuantMlp<'a, P: Precision = i8> {
    /// Quantization of the f32 input vector (first layer's input).
    pub input: QuantParams,
    /// Hidden layers in order (may be empty).
    pub hidden: &'a [RequantizedLinear<'a, P>],
    /// Output layer; its accumulators are dequantized, not requantized.
    pub output: Int8Linear<'a, P::Acc>,
}

/// The int8-activation MLP.
pub type Int8Mlp<'a> = QuantMlp<'a, i8>;
/// The int16-activation MLP (int8 weights, int64 bias and accumulators).
pub type Int16Mlp<'a> = QuantMlp<'a, i16>;

/// Working memory of [`QuantMlp`], borrowed: two activation buffers (ping-pong) and the
/// accumulators of the output layer (which also hold the 16-bit input codes of
/// [`InputPrecision::Int16`]). Each must hold the widest layer it receives.
#[derive(Debug)]
pub struct QuantBuffers<'s, P: Precision = i8> {
    /// Input codes, then every other layer's output.
    pub ping: &'s mut [P],
    /// The other layers' outputs (and the fine plane of a two-plane input).
    pub pong: &'s mut [P],
    /// Accumulators (and 16-bit input codes).
    pub accumulators: &'s mut [P::Acc],
}

/// The buffers of an [`Int8Mlp`].
pub type Int8Buffers<'s> = QuantBuffers<'s, i8>;

/// [`QuantBuffers`] as fixed arrays of `WIDTH` (at least the widest layer).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct QuantScratch<P: Precision, const WIDTH: usize> {
    ping: [P; WIDTH],
    pong: [P; WIDTH],
    accumulators: [P::Acc; WIDTH],
}

/// The scratch of an [`Int8Mlp`].
pub type Int8Scratch<const WIDTH: usize> = QuantScratch<i8, WIDTH>;

impl<P: Precision, const WIDTH: usize> QuantScratch<P, WIDTH> {
    /// Zeroed scratch.
    pub const fn new() -> Self {
        Self {
            ping: [P::ZERO; WIDTH],
            pong: [P::ZERO; WIDTH],
            accumulators: [<P::Acc as crate::kernels::Accumulator>::ZERO; WIDTH],
        }
    }

    /// The output layer's accumulators of the last forward pass (`out_features` long prefix).
    pub fn accumulators(&self) -> &[P::Acc; WIDTH] {
        &self.accumulators
    }

    /// The arrays as [`QuantBuffers`].
    pub fn buffers(&mut self) -> QuantBuffers<'_, P> {
        QuantBuffers {
            ping: &mut self.ping,
            pong: &mut self.pong,
            accumulators: &mut self.accumulators,
        }
    }
}

impl<P: Precision, const WIDTH: usize> Default for QuantScratch<P, WIDTH> {
    fn default() -> Self {
        Self::new()
    }
}

/// The activation precisions an MLP runs in, and how each takes its input: int8 activations
/// with any [`InputPrecision`]; int16 activations with the 16-bit input plane only
/// ([`InputPrecision::Int16`], the first layer's input is then an int16 activation like any
/// other, at the fine input scale).
pub trait MlpPrecision: Precision {
    /// Whether a network of this precision takes its input as `precision` says.
    fn accepts(precision: InputPrecision) -> bool;
    /// [`QuantMlp::forward_staged`] for this precision.
    fn forward(
        mlp: &QuantMlp<'_, Self>,
        precision: InputPrecision,
        input: &[f32],
        output: &mut [f32],
        buffers: QuantBuffers<'_, Self>,
        stage: &mut impl FnMut(),
    ) -> Result<(), ModelError>;
}

impl MlpPrecision for i8 {
    fn accepts(_: InputPrecision) -> bool {
        true
    }
    fn forward(
        mlp: &Int8Mlp<'_>,
        precision: InputPrecision,
        input: &[f32],
        output: &mut [f32],
        buffers: Int8Buffers<'_>,
        stage: &mut impl FnMut(),
    ) -> Result<(), ModelError> {
        mlp.forward_int8(precision, input, output, buffers, stage)
    }
}

impl MlpPrecision for i16 {
    fn accepts(precision: InputPrecision) -> bool {
        precision == InputPrecision::Int16
    }
    fn forward(
        mlp: &Int16Mlp<'_>,
        precision: InputPrecision,
        input: &[f32],
        output: &mut [f32],
        buffers: QuantBuffers<'_, i16>,
        stage: &mut impl FnMut(),
    ) -> Result<(), ModelError> {
        mlp.validate_input_precision(precision)?;
        mlp.check_io(input.len(), output.len())?;
        mlp.forward_wide_input(input, output, buffers, stage)
    }
}

impl<P: MlpPrecision> QuantMlp<'_, P> {
    /// Runs the network on `input` (f32, `input_width()` long) with the input quantized as
    /// `precision` says, and writes the dequantized last layer into `output` (`output_width()`
    /// long).
    pub fn forward_with_input<const WIDTH: usize>(
        &self,
        precision: InputPrecision,
        input: &[f32],
        output: &mut [f32],
        scratch: &mut QuantScratch<P, WIDTH>,
    ) -> Result<(), ModelError> {
        self.validate_requantization()?;
        self.forward_prevalidated(precision, input, output, scratch.buffers())
    }

    /// [`ModelError::InputPrecision`] unless this precision takes its input as `precision` says
    /// ([`MlpPrecision::accepts`]).
    pub fn validate_input_precision(&self, precision: InputPrecision) -> Result<(), ModelError> {
        if P::accepts(precision) {
            Ok(())
        } else {
            Err(ModelError::InputPrecision)
        }
    }

    /// The forward pass on borrowed buffers for a network whose requantization passed
    /// [`Self::validate_requantization`] before (the per-channel checks are not repeated; see
    /// [`RequantizedLinear::forward_prevalidated`]); shapes are checked.
    pub fn forward_prevalidated(
        &self,
        precision: InputPrecision,
        input: &[f32],
        output: &mut [f32],
        buffers: QuantBuffers<'_, P>,
    ) -> Result<(), ModelError> {
        P::forward(self, precision, input, output, buffers, &mut || {})
    }

    /// [`Self::forward_prevalidated`] calling `stage` at every stage boundary: after the input
    /// is quantized, after each hidden layer, after the output layer's accumulators and after
    /// their dequantization (the hidden layers plus 3 calls; a firmware's per-stage timing). The
    /// same kernels in the same order, so the same outputs.
    pub fn forward_staged(
        &self,
        precision: InputPrecision,
        input: &[f32],
        output: &mut [f32],
        buffers: QuantBuffers<'_, P>,
        stage: &mut impl FnMut(),
    ) -> Result<(), ModelError> {
        P::forward(self, precision, input, output, buffers, stage)
    }
}

impl<P: Precision> QuantMlp<'_, P> {
    /// Input width (first layer's `in_features`).
    pub fn input_width(&self) -> usize {
        self.hidden
            .first()
            .map_or(self.output.fc.in_features, |layer| layer.fc.in_features)
    }

    /// Output width.
    pub fn output_width(&self) -> usize {
        self.output.fc.out_features
    }

    /// Checks the input parameters, every layer's slices, that consecutive widths agree and that
    /// every width is at most `max_width` (the scratch width).
    pub fn validate(&self, max_width: usize) -> Result<(), ModelError> {
        self.input.validate().map_err(|_| ModelError::InputParams)?;
        for fc in self.hidden.iter().map(|layer| &layer.fc) {
            fc.validate()?;
        }
        self.output.validate()?;
        let widths = self
            .hidden
            .iter()
            .map(|layer| &layer.fc)
            .chain([&self.output.fc])
            .map(|fc| (fc.in_features, fc.out_features));
        check_widths(self.input_width(), widths, max_width)
    }

    /// Checks every hidden layer's requantization parameters ([`crate::kernels::FcRequant::validate`])
    /// and, for int64 accumulators, what keeps every accumulator exact (weights, bias bounds:
    /// [`crate::kernels::FullyConnected::validate_exact`], O(weights); nothing more for int8).
    pub fn validate_requantization(&self) -> Result<(), ModelError> {
        for layer in self.hidden {
            layer.requant.validate(layer.fc.out_features)?;
            layer.fc.validate_exact()?;
        }
        self.output.fc.validate_exact()?;
        Ok(())
    }

    fn check_io(&self, input_len: usize, output_len: usize) -> Result<(), ModelError> {
        self.validate(usize::MAX)?;
        check_lengths(
            (input_len, output_len),
            (self.input_width(), self.output_width()),
        )
    }

    /// `hidden`, then the output layer, on the `width` codes in `current` (ping-pong with
    /// `next`), calling `stage` after each hidden layer, the output accumulators and their
    /// dequantization.
    #[allow(clippy::too_many_arguments)]
    fn run<'s>(
        &self,
        mut current: &'s mut [P],
        mut next: &'s mut [P],
        mut width: usize,
        hidden: &[RequantizedLinear<'_, P>],
        accumulators: &mut [P::Acc],
        output: &mut [f32],
        stage: &mut impl FnMut(),
    ) -> Result<(), ModelError> {
        for layer in hidden {
            let out_width = layer.fc.out_features;
            let layer_input = current.get(..width).ok_or(ModelError::ScratchTooSmall)?;
            let layer_output = next
                .get_mut(..out_width)
                .ok_or(ModelError::ScratchTooSmall)?;
            layer.forward_prevalidated(P::layer_input(layer_input), layer_output)?;
            core::mem::swap(&mut current, &mut next);
            width = out_width;
            stage();
        }
        let last_input = current.get(..width).ok_or(ModelError::ScratchTooSmall)?;
        let acc = accumulators
            .get_mut(..self.output_width())
            .ok_or(ModelError::ScratchTooSmall)?;
        self.output.fc.accumulate(P::layer_input(last_input), acc)?;
        stage();
        dequantize_accumulators(acc, self.output.output_scales, output)?;
        stage();
        Ok(())
    }

    /// The 16-bit input plane through the first hidden layer, then the rest ([`Self::run`]).
    fn forward_wide_input(
        &self,
        input: &[f32],
        output: &mut [f32],
        buffers: QuantBuffers<'_, P>,
        stage: &mut impl FnMut(),
    ) -> Result<(), ModelError> {
        let QuantBuffers {
            ping,
            pong,
            accumulators,
        } = buffers;
        let layer = self
            .hidden
            .first()
            .ok_or(ModelError::TwoPlaneWithoutHiddenLayer)?;
        // The accumulators are free until the output layer: they hold the 16-bit codes.
        let codes = bytemuck::cast_slice_mut::<P::Acc, i16>(&mut *accumulators)
            .get_mut(..input.len())
            .ok_or(ModelError::ScratchTooSmall)?;
        quantize_input_i16(input, self.input, codes);
        stage();
        let out_width = layer.fc.out_features;
        let layer_output = pong
            .get_mut(..out_width)
            .ok_or(ModelError::ScratchTooSmall)?;
        layer.forward_prevalidated(LayerInput::Int16(codes), layer_output)?;
        stage();
        let rest = self.hidden.get(1..).unwrap_or(&[]);
        self.run(pong, ping, out_width, rest, accumulators, output, stage)
    }
}

impl Int8Mlp<'_> {
    /// Runs the network on `input` (f32, `input_width()` long) and writes the dequantized last
    /// layer into `output` (`output_width()` long); the input is quantized to int8
    /// ([`InputPrecision::Int8`]).
    pub fn forward<const WIDTH: usize>(
        &self,
        input: &[f32],
        output: &mut [f32],
        scratch: &mut Int8Scratch<WIDTH>,
    ) -> Result<(), ModelError> {
        self.forward_with_input(InputPrecision::Int8, input, output, scratch)
    }

    /// [`MlpPrecision::forward`] of int8 activations: every [`InputPrecision`].
    fn forward_int8(
        &self,
        precision: InputPrecision,
        input: &[f32],
        output: &mut [f32],
        buffers: Int8Buffers<'_>,
        stage: &mut impl FnMut(),
    ) -> Result<(), ModelError> {
        self.check_io(input.len(), output.len())?;
        if precision == InputPrecision::Int16 {
            return self.forward_wide_input(input, output, buffers, stage);
        }
        let Int8Buffers {
            ping,
            pong,
            accumulators,
        } = buffers;
        let in_width = input.len();
        let first = ping
            .get_mut(..in_width)
            .ok_or(ModelError::ScratchTooSmall)?;
        if precision == InputPrecision::Int8 {
            for (q, x) in first.iter_mut().zip(input) {
                *q = self.input.quantize(*x);
            }
            stage();
            return self.run(
                ping,
                pong,
                in_width,
                self.hidden,
                accumulators,
                output,
                stage,
            );
        }
        let layer = self
            .hidden
            .first()
            .ok_or(ModelError::TwoPlaneWithoutHiddenLayer)?;
        let out_width = layer.fc.out_features;
        let fine = pong
            .get_mut(..in_width)
            .ok_or(ModelError::ScratchTooSmall)?;
        quantize_input_two_plane(input, self.input, first, fine);
        stage();
        let acc = accumulators
            .get_mut(..out_width)
            .ok_or(ModelError::ScratchTooSmall)?;
        layer.two_plane_accumulators(first, fine, acc)?;
        let layer_output = pong
            .get_mut(..out_width)
            .ok_or(ModelError::ScratchTooSmall)?;
        layer.requantize_and_activate(acc, layer_output)?;
        stage();
        let rest = self.hidden.get(1..).unwrap_or(&[]);
        self.run(pong, ping, out_width, rest, accumulators, output, stage)
    }
}
