//! The [`Network`] boundary: one generic sampler path over every backbone and precision.
//!
//! A network maps the model input vector (see [`super::InputLayout`]) to the `k p` ProDMP
//! parameters (DoF-major, normalized action units). The noise-level embedding of each sampling
//! step is folded by the exporter into the network, one [`NoiseVariants`] row per step: the
//! first layer's bias for an MLP ([`mlp`]), the noise token for a transformer ([`transformer`]);
//! `forward` selects the row by index (see [`super::StepConstants::noise_variant`]).

pub mod mlp;
pub mod transformer;

use super::PolicyError;

/// A forward pass the sampler can drive.
pub trait Network {
    /// Input width.
    fn input_width(&self) -> usize;
    /// Output width (`k p` for a ProDMP student).
    fn output_width(&self) -> usize;
    /// Number of noise-level variants; 0 means the network's own values serve variant 0.
    fn num_noise_variants(&self) -> usize;
    /// Runs the network with noise-level variant `variant` on `input`, writing the output
    /// parameters into `output` (f32, normalized units).
    fn forward(
        &mut self,
        variant: usize,
        input: &[f32],
        output: &mut [f32],
    ) -> Result<(), PolicyError>;
}

/// A borrowed network drives the sampler too (e.g. `&mut dyn Network` on a host that picks the
/// network at run time).
impl<N: Network + ?Sized> Network for &mut N {
    fn input_width(&self) -> usize {
        (**self).input_width()
    }
    fn output_width(&self) -> usize {
        (**self).output_width()
    }
    fn num_noise_variants(&self) -> usize {
        (**self).num_noise_variants()
    }
    fn forward(
        &mut self,
        variant: usize,
        input: &[f32],
        output: &mut [f32],
    ) -> Result<(), PolicyError> {
        (**self).forward(variant, input, output)
    }
}

/// The noise-level variants of a network: rows of `len` values back to back, or none (then the
/// network's own values serve variant 0 and no other).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseVariants<'a, T> {
    values: &'a [T],
    len: usize,
}

impl<'a, T> NoiseVariants<'a, T> {
    /// `values` as rows of `len`; [`PolicyError::NoiseVariantLength`] unless they are whole rows
    /// (or empty).
    pub fn new(values: &'a [T], len: usize) -> Result<Self, PolicyError> {
        if !values.is_empty() && (len == 0 || !values.len().is_multiple_of(len)) {
            return Err(PolicyError::NoiseVariantLength);
        }
        Ok(Self { values, len })
    }

    /// Number of rows.
    pub fn count(&self) -> usize {
        self.values.len().checked_div(self.len).unwrap_or(0)
    }

    /// All rows back to back.
    pub fn values(&self) -> &'a [T] {
        self.values
    }

    /// Row `index`, or `None` for index 0 without rows (the network's own values);
    /// [`PolicyError::NoiseVariantIndex`] for any other index beyond the rows.
    pub fn select(&self, index: usize) -> Result<Option<&'a [T]>, PolicyError> {
        if self.values.is_empty() {
            return if index == 0 {
                Ok(None)
            } else {
                Err(PolicyError::NoiseVariantIndex)
            };
        }
        let start = index
            .checked_mul(self.len)
            .ok_or(PolicyError::NoiseVariantIndex)?;
        let end = start
            .checked_add(self.len)
            .ok_or(PolicyError::NoiseVariantIndex)?;
        self.values
            .get(start..end)
            .map(Some)
            .ok_or(PolicyError::NoiseVariantIndex)
    }
}
