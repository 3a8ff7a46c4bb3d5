//! The f32 MLP: the same structure as [`super::Int8Mlp`] in f32 (the reference the exporter
//! calibrates on and the policy's f32 network), with a probe for every intermediate tensor.

use super::ModelError;
use crate::kernels::{Activation, KernelError};

/// One f32 layer: `y = activation(W x + b)`, weights `[out_features, in_features]` row-major.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct F32Layer<'a> {
    /// Input width.
    pub in_features: usize,
    /// Output width.
    pub out_features: usize,
    /// `[out_features, in_features]` row-major weights.
    pub weights: &'a [f32],
    /// `[out_features]` bias.
    pub bias: &'a [f32],
    /// Pointwise activation applied after the affine map.
    pub activation: Activation,
}

impl F32Layer<'_> {
    /// Checks the weight and bias lengths against the shape.
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

    /// `output = activation(W input + b)`; `pre_activation` (same length as `output`) receives
    /// `W input + b` if given.
    /// Dot products are summed sequentially in f32.
    pub fn forward(
        &self,
        input: &[f32],
        output: &mut [f32],
        mut pre_activation: Option<&mut [f32]>,
    ) -> Result<(), KernelError> {
        self.validate()?;
        if input.len() != self.in_features {
            return Err(KernelError::InputLength);
        }
        if output.len() != self.out_features
            || pre_activation
                .as_deref()
                .is_some_and(|p| p.len() != self.out_features)
        {
            return Err(KernelError::OutputLength);
        }
        let rows = self.weights.chunks_exact(self.in_features).zip(self.bias);
        for (o, ((row, bias), out)) in rows.zip(output.iter_mut()).enumerate() {
            let affine = row.iter().zip(input).fold(*bias, |acc, (w, x)| acc + w * x);
            if let Some(slot) = pre_activation.as_deref_mut().and_then(|p| p.get_mut(o)) {
                *slot = affine;
            }
            *out = self.activation.apply(affine);
        }
        Ok(())
    }
}

/// Which tensor an [`F32Mlp::forward_observed`] callback sees (for calibration).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Probe {
    /// The network input.
    Input,
    /// Hidden layer `l`'s affine output before its activation.
    PreActivation(usize),
    /// Hidden layer `l`'s output after its activation (the next layer's input).
    Output(usize),
    /// The output layer's values (before any activation it has).
    Final,
}

/// f32 reference MLP with the same structure as [`super::Int8Mlp`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct F32Mlp<'a> {
    /// Hidden layers in order (may be empty).
    pub hidden: &'a [F32Layer<'a>],
    /// Output layer (normally `Activation::Identity`).
    pub output: F32Layer<'a>,
}

/// Scratch buffers for [`F32Mlp::forward`], each `WIDTH` long.
#[derive(Clone, Debug, PartialEq)]
pub struct F32Scratch<const WIDTH: usize> {
    ping: [f32; WIDTH],
    pong: [f32; WIDTH],
    pre_activation: [f32; WIDTH],
}

impl<const WIDTH: usize> F32Scratch<WIDTH> {
    /// Zeroed scratch.
    pub const fn new() -> Self {
        Self {
            ping: [0.0; WIDTH],
            pong: [0.0; WIDTH],
            pre_activation: [0.0; WIDTH],
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

    /// Checks consecutive widths and that every width fits in `WIDTH`.
    pub fn validate<const WIDTH: usize>(&self) -> Result<(), ModelError> {
        let mut width = self.input_width();
        for (index, layer) in self.hidden.iter().chain([&self.output]).enumerate() {
            layer.validate()?;
            if layer.in_features != width {
                return Err(ModelError::LayerWidth { index });
            }
            if layer.in_features > WIDTH || layer.out_features > WIDTH {
                return Err(ModelError::ScratchTooSmall);
            }
            width = layer.out_features;
        }
        Ok(())
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
        mut observe: F,
    ) -> Result<(), ModelError> {
        self.validate::<WIDTH>()?;
        let in_width = self.input_width();
        if input.len() != in_width {
            return Err(ModelError::InputLength);
        }
        if output.len() != self.output_width() {
            return Err(ModelError::OutputLength);
        }
        observe(Probe::Input, input);
        let F32Scratch {
            ping,
            pong,
            pre_activation,
        } = scratch;
        let (mut current, mut next) = (ping, pong);
        current
            .get_mut(..in_width)
            .ok_or(ModelError::ScratchTooSmall)?
            .copy_from_slice(input);
        let mut width = in_width;
        for (index, layer) in self.hidden.iter().enumerate() {
            let out_width = layer.out_features;
            let layer_input = current.get(..width).ok_or(ModelError::ScratchTooSmall)?;
            let layer_output = next
                .get_mut(..out_width)
                .ok_or(ModelError::ScratchTooSmall)?;
            let pre = pre_activation
                .get_mut(..out_width)
                .ok_or(ModelError::ScratchTooSmall)?;
            layer.forward(layer_input, layer_output, Some(&mut *pre))?;
            observe(Probe::PreActivation(index), pre);
            observe(Probe::Output(index), layer_output);
            core::mem::swap(&mut current, &mut next);
            width = out_width;
        }
        let last_input = current.get(..width).ok_or(ModelError::ScratchTooSmall)?;
        let pre = pre_activation
            .get_mut(..self.output.out_features)
            .ok_or(ModelError::ScratchTooSmall)?;
        self.output.forward(last_input, output, Some(&mut *pre))?;
        observe(Probe::Final, pre);
        Ok(())
    }
}
