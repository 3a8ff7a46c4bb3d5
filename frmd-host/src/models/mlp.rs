//! MLP backbone: input = [condition, c_in-scaled noisy trajectory, noise embedding], hidden layers
//! with Mish or SiLU, a linear output layer.
use super::act::{Activation, ActivationExt};
use candle_core::{Result, Tensor, D};
use candle_nn::{Linear, Module, VarBuilder};

/// Variables: `layers.{i}.weight` [out, in], `layers.{i}.bias` [out]; the last layer is linear.
pub struct Mlp {
    layers: Vec<Linear>,
    activation: Activation,
}

impl Mlp {
    pub fn new(
        input: usize,
        hidden: &[usize],
        output: usize,
        activation: Activation,
        vb: VarBuilder,
    ) -> Result<Self> {
        let mut layers = Vec::with_capacity(hidden.len() + 1);
        let mut width = input;
        for (i, &next) in hidden.iter().chain(std::iter::once(&output)).enumerate() {
            layers.push(candle_nn::linear(
                width,
                next,
                vb.pp(format!("layers.{i}")),
            )?);
            width = next;
        }
        Ok(Mlp { layers, activation })
    }

    /// `x_scaled` [B, n*k], `cond` [B, C], `emb` [B, E] -> [B, output].
    pub fn forward(&self, x_scaled: &Tensor, cond: &Tensor, emb: &Tensor) -> Result<Tensor> {
        let mut h = Tensor::cat(&[cond, x_scaled, emb], D::Minus1)?;
        let last = self.layers.len().saturating_sub(1);
        for (i, layer) in self.layers.iter().enumerate() {
            h = layer.forward(&h)?;
            if i < last {
                h = self.activation.apply(&h)?;
            }
        }
        Ok(h)
    }
}
