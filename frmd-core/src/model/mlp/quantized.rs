//! The int8 MLP: input quantization, hidden [`RequantizedLinear`] layers, a dequantized
//! [`Int8Linear`] output layer.

use super::{
    check_lengths, check_widths, quantize_input_i16, quantize_input_two_plane, InputPrecision,
    ModelError,
};
use crate::kernels::LayerInput;
use crate::model::linear::{Int8Linear, RequantizedLinear};
use crate::quant::QuantParams;

/// int8 MLP: hidden [`RequantizedLinear`]s, then an [`Int8Linear`] output layer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Int8Mlp<'a> {
    /// Quantization of the f32 input vector (first layer's input).
    pub input: QuantParams,
    /// Hidden layers in order (may be empty).
    pub hidden: &'a [RequantizedLinear<'a>],
    /// Output layer; its int32 accumulators are dequantized, not requantized.
    pub output: Int8Linear<'a>,
}

/// Working memory of [`Int8Mlp`], borrowed: two int8 activation buffers (ping-pong) and the int32
/// accumulators of the output layer (which also hold the 16-bit input codes of
/// [`InputPrecision::Int16`]). Each must hold the widest layer it receives.
#[derive(Debug)]
pub struct Int8Buffers<'s> {
    /// Input codes, then every other layer's output.
    pub ping: &'s mut [i8],
    /// The other layers' outputs (and the fine plane of a two-plane input).
    pub pong: &'s mut [i8],
    /// Accumulators (and 16-bit input codes).
    pub accumulators: &'s mut [i32],
}

/// [`Int8Buffers`] as fixed arrays of `WIDTH` (at least the widest layer).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Int8Scratch<const WIDTH: usize> {
    ping: [i8; WIDTH],
    pong: [i8; WIDTH],
    accumulators: [i32; WIDTH],
}

impl<const WIDTH: usize> Int8Scratch<WIDTH> {
    /// Zeroed scratch.
    pub const fn new() -> Self {
        Self {
            ping: [0; WIDTH],
            pong: [0; WIDTH],
            accumulators: [0; WIDTH],
        }
    }

    /// The output layer's int32 accumulators of the last forward pass (`out_features` long prefix).
    pub fn accumulators(&self) -> &[i32; WIDTH] {
        &self.accumulators
    }

    /// The arrays as [`Int8Buffers`].
    pub fn buffers(&mut self) -> Int8Buffers<'_> {
        Int8Buffers {
            ping: &mut self.ping,
            pong: &mut self.pong,
            accumulators: &mut self.accumulators,
        }
    }
}

impl<const WIDTH: usize> Default for Int8Scratch<WIDTH> {
    fn default() -> Self {
        Self::new()
    }
}

impl Int8Mlp<'_> {
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

    /// Checks every hidden layer's requantization parameters ([`crate::kernels::FcRequant::validate`]).
    pub fn validate_requantization(&self) -> Result<(), ModelError> {
        for layer in self.hidden {
            layer.requant.validate(layer.fc.out_features)?;
        }
        Ok(())
    }

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

    /// [`Self::forward`] with the input quantized as `precision` says.
    pub fn forward_with_input<const WIDTH: usize>(
        &self,
        precision: InputPrecision,
        input: &[f32],
        output: &mut [f32],
        scratch: &mut Int8Scratch<WIDTH>,
    ) -> Result<(), ModelError> {
        self.validate_requantization()?;
        self.forward_prevalidated(precision, input, output, scratch.buffers())
    }

    /// The forward pass on borrowed buffers for a network whose requantization passed
    /// [`Self::validate_requantization`] before (the per-channel checks are not repeated; see
    /// [`RequantizedLinear::forward_prevalidated`]); shapes are checked.
    pub fn forward_prevalidated(
        &self,
        precision: InputPrecision,
        input: &[f32],
        output: &mut [f32],
        buffers: Int8Buffers<'_>,
    ) -> Result<(), ModelError> {
        self.check_io(input.len(), output.len())?;
        let Int8Buffers {
            ping,
            pong,
            accumulators,
        } = buffers;
        let in_width = input.len();
        let first = ping
            .get_mut(..in_width)
            .ok_or(ModelError::ScratchTooSmall)?;
        let layer = match precision {
            InputPrecision::Int8 => {
                for (q, x) in first.iter_mut().zip(input) {
                    *q = self.input.quantize(*x);
                }
                return self.run(ping, pong, in_width, self.hidden, accumulators, output);
            }
            InputPrecision::TwoPlane | InputPrecision::Int16 => self
                .hidden
                .first()
                .ok_or(ModelError::TwoPlaneWithoutHiddenLayer)?,
        };
        let out_width = layer.fc.out_features;
        if precision == InputPrecision::TwoPlane {
            let fine = pong
                .get_mut(..in_width)
                .ok_or(ModelError::ScratchTooSmall)?;
            quantize_input_two_plane(input, self.input, first, fine);
            let acc = accumulators
                .get_mut(..out_width)
                .ok_or(ModelError::ScratchTooSmall)?;
            layer.two_plane_accumulators(first, fine, acc)?;
            let layer_output = pong
                .get_mut(..out_width)
                .ok_or(ModelError::ScratchTooSmall)?;
            layer.requantize_and_activate(acc, layer_output)?;
        } else {
            // The accumulators are free until the output layer: they hold the 16-bit codes.
            let codes = bytemuck::cast_slice_mut::<i32, i16>(&mut *accumulators)
                .get_mut(..in_width)
                .ok_or(ModelError::ScratchTooSmall)?;
            quantize_input_i16(input, self.input, codes);
            let layer_output = pong
                .get_mut(..out_width)
                .ok_or(ModelError::ScratchTooSmall)?;
            layer.forward_prevalidated(LayerInput::Int16(codes), layer_output)?;
        }
        let rest = self.hidden.get(1..).unwrap_or(&[]);
        self.run(pong, ping, out_width, rest, accumulators, output)
    }

    /// The network on `values` with int8 input ([`InputPrecision::Int8`]), writing its output
    /// back into `values` (input and output width must agree); requantization as for
    /// [`Self::forward_prevalidated`].
    pub fn forward_in_place_prevalidated(
        &self,
        values: &mut [f32],
        buffers: Int8Buffers<'_>,
    ) -> Result<(), ModelError> {
        self.check_io(values.len(), values.len())?;
        let Int8Buffers {
            ping,
            pong,
            accumulators,
        } = buffers;
        let first = ping
            .get_mut(..values.len())
            .ok_or(ModelError::ScratchTooSmall)?;
        for (q, x) in first.iter_mut().zip(values.iter()) {
            *q = self.input.quantize(*x);
        }
        self.run(ping, pong, values.len(), self.hidden, accumulators, values)
    }

    fn check_io(&self, input_len: usize, output_len: usize) -> Result<(), ModelError> {
        self.validate(usize::MAX)?;
        check_lengths(
            (input_len, output_len),
            (self.input_width(), self.output_width()),
        )
    }

    /// `hidden`, then the output layer, on the `width` codes in `current` (ping-pong with
    /// `next`).
    fn run<'s>(
        &self,
        mut current: &'s mut [i8],
        mut next: &'s mut [i8],
        mut width: usize,
        hidden: &[RequantizedLinear<'_>],
        accumulators: &mut [i32],
        output: &mut [f32],
    ) -> Result<(), ModelError> {
        for layer in hidden {
            let out_width = layer.fc.out_features;
            let layer_input = current.get(..width).ok_or(ModelError::ScratchTooSmall)?;
            let layer_output = next
                .get_mut(..out_width)
                .ok_or(ModelError::ScratchTooSmall)?;
            layer.forward_prevalidated(LayerInput::Int8(layer_input), layer_output)?;
            core::mem::swap(&mut current, &mut next);
            width = out_width;
        }
        let last_input = current.get(..width).ok_or(ModelError::ScratchTooSmall)?;
        let acc = accumulators
            .get_mut(..self.output_width())
            .ok_or(ModelError::ScratchTooSmall)?;
        self.output.forward(last_input, acc, output)?;
        Ok(())
    }
}
