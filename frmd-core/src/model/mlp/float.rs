//! The f32 reference MLP: [`F32Linear`] layers, with calibration probes.

use super::{check_lengths, check_widths, ModelError, Probe};
use crate::model::linear::F32Linear;

/// f32 reference MLP with the same structure as [`super::Int8Mlp`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct F32Mlp<'a> {
    /// Hidden layers in order (may be empty).
    pub hidden: &'a [F32Linear<'a>],
    /// Output layer (normally `Activation::Identity`).
    pub output: F32Linear<'a>,
}

/// Working memory of [`F32Mlp`], borrowed: two activation buffers (ping-pong), each holding the
/// widest layer it receives.
#[derive(Debug)]
pub struct F32Buffers<'s> {
    /// The input copy, then every other layer's output.
    pub ping: &'s mut [f32],
    /// The other layers' outputs.
    pub pong: &'s mut [f32],
}

/// [`F32Buffers`] as fixed arrays of `WIDTH` (at least the widest layer).
#[derive(Clone, Debug, PartialEq)]
pub struct F32Scratch<const WIDTH: usize> {
    ping: [f32; WIDTH],
    pong: [f32; WIDTH],
}

impl<const WIDTH: usize> F32Scratch<WIDTH> {
    /// Zeroed scratch.
    pub const fn new() -> Self {
        Self {
            ping: [0.0; WIDTH],
            pong: [0.0; WIDTH],
        }
    }

    /// The arrays as [`F32Buffers`].
    pub fn buffers(&mut self) -> F32Buffers<'_> {
        F32Buffers {
            ping: &mut self.ping,
            pong: &mut self.pong,
        }
    }
}

impl<const WIDTH: usize> Default for F32Scratch<WIDTH> {
    fn default() -> Self {
        Self::new()
    }
}

impl F32Mlp<'_> {
    /// Input width (first layer's `in_features`).
    pub fn input_width(&self) -> usize {
        self.hidden
            .first()
            .map_or(self.output.in_features, |layer| layer.in_features)
    }

    /// Output width.
    pub fn output_width(&self) -> usize {
        self.output.out_features
    }

    /// Checks every layer's slices, consecutive widths and that every width is at most
    /// `max_width` (the scratch width).
    pub fn validate(&self, max_width: usize) -> Result<(), ModelError> {
        for layer in self.hidden.iter().chain([&self.output]) {
            layer.validate()?;
        }
        let widths = self
            .hidden
            .iter()
            .chain([&self.output])
            .map(|layer| (layer.in_features, layer.out_features));
        check_widths(self.input_width(), widths, max_width)
    }

    /// Runs the network.
    pub fn forward<const WIDTH: usize>(
        &self,
        input: &[f32],
        output: &mut [f32],
        scratch: &mut F32Scratch<WIDTH>,
    ) -> Result<(), ModelError> {
        self.forward_observed(input, output, scratch, |_, _| {})
    }

    /// Runs the network and shows every intermediate tensor to `observe` (input, each hidden
    /// layer's pre-activation and output, the final output), e.g. to record calibration ranges.
    pub fn forward_observed<const WIDTH: usize, F: FnMut(Probe, &[f32])>(
        &self,
        input: &[f32],
        output: &mut [f32],
        scratch: &mut F32Scratch<WIDTH>,
        observe: F,
    ) -> Result<(), ModelError> {
        self.forward_in(input, output, scratch.buffers(), observe)
    }

    /// [`Self::forward_observed`] on borrowed buffers (each checked as it is used).
    pub fn forward_in<F: FnMut(Probe, &[f32])>(
        &self,
        input: &[f32],
        output: &mut [f32],
        buffers: F32Buffers<'_>,
        mut observe: F,
    ) -> Result<(), ModelError> {
        self.check_io(input.len(), output.len())?;
        observe(Probe::Input, input);
        let ping = buffers
            .ping
            .get_mut(..input.len())
            .ok_or(ModelError::ScratchTooSmall)?;
        ping.copy_from_slice(input);
        self.run(buffers.ping, buffers.pong, output, observe)
    }

    /// [`Self::forward_in`] that reads its input from `values` and writes its output there
    /// (input and output width must agree).
    pub fn forward_in_place<F: FnMut(Probe, &[f32])>(
        &self,
        values: &mut [f32],
        buffers: F32Buffers<'_>,
        mut observe: F,
    ) -> Result<(), ModelError> {
        self.check_io(values.len(), values.len())?;
        observe(Probe::Input, values);
        let ping = buffers
            .ping
            .get_mut(..values.len())
            .ok_or(ModelError::ScratchTooSmall)?;
        ping.copy_from_slice(values);
        self.run(buffers.ping, buffers.pong, values, observe)
    }

    fn check_io(&self, input_len: usize, output_len: usize) -> Result<(), ModelError> {
        self.validate(usize::MAX)?;
        check_lengths(
            (input_len, output_len),
            (self.input_width(), self.output_width()),
        )
    }

    /// The layers on the input in `ping` (shapes checked by the caller).
    fn run<F: FnMut(Probe, &[f32])>(
        &self,
        ping: &mut [f32],
        pong: &mut [f32],
        output: &mut [f32],
        mut observe: F,
    ) -> Result<(), ModelError> {
        let (mut current, mut next) = (ping, pong);
        let mut width = self.input_width();
        for (index, layer) in self.hidden.iter().enumerate() {
            let out_width = layer.out_features;
            let layer_input = current.get(..width).ok_or(ModelError::ScratchTooSmall)?;
            let layer_output = next
                .get_mut(..out_width)
                .ok_or(ModelError::ScratchTooSmall)?;
            layer.affine(layer_input, layer_output)?;
            observe(Probe::PreActivation(index), layer_output);
            layer.activation.apply_in_place(layer_output);
            observe(Probe::Output(index), layer_output);
            core::mem::swap(&mut current, &mut next);
            width = out_width;
        }
        let last_input = current.get(..width).ok_or(ModelError::ScratchTooSmall)?;
        self.output.affine(last_input, output)?;
        observe(Probe::Final, output);
        self.output.activation.apply_in_place(output);
        Ok(())
    }
}
