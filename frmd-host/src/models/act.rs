//! Activations with well-behaved gradients (candle's `ops::mish` overflows to NaN gradients
//! for inputs above ~88 and is slow).
use candle_core::{Result, Tensor};

pub use frmd_formats::checkpoint::Activation;

/// The candle forward of an [`Activation`] (the enum itself is part of the checkpoint schema in
/// `frmd_formats::checkpoint`).
pub trait ActivationExt {
    fn apply(self, xs: &Tensor) -> Result<Tensor>;
}

impl ActivationExt for Activation {
    fn apply(self, xs: &Tensor) -> Result<Tensor> {
        match self {
            Activation::Silu => xs.silu(),
            Activation::Mish => mish(xs),
        }
    }
}

/// Mish without overflow: with w = e^min(x, 20) and t = w (w + 2),
/// tanh(ln(1 + w)) = t / (t + 2), so mish(x) = x t / (t + 2). Above 20 the ratio is 1 in f32.
pub fn mish(xs: &Tensor) -> Result<Tensor> {
    let w = xs.minimum(20f32)?.exp()?;
    let t = (&w * (&w + 2.0)?)?;
    let ratio = (&t / (&t + 2.0)?)?;
    xs * ratio
}

/// GELU approximated as x * sigmoid(1.702 x) (fast on CPU, exact gradient of itself).
pub fn gelu_sigmoid(xs: &Tensor) -> Result<Tensor> {
    xs * candle_nn::ops::sigmoid(&(xs * 1.702)?)?
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    #[test]
    fn mish_values_and_finite_gradients() -> Result<()> {
        let xs = Var::new(&[-30f32, -1.0, 0.0, 1.0, 50.0, 200.0], &Device::Cpu)?;
        let ys = mish(xs.as_tensor())?;
        let values = ys.to_vec1::<f32>()?;
        for (x, y) in [-30f32, -1.0, 0.0, 1.0, 50.0, 200.0].iter().zip(&values) {
            let reference = (*x as f64) * ((1.0 + (*x as f64).exp()).ln()).tanh();
            assert!(
                (reference - *y as f64).abs() < 1e-5 * (1.0 + x.abs() as f64),
                "{x}: {y}"
            );
        }
        let grads = ys.sum_all()?.backward()?;
        let g = grads.get(&xs).expect("gradient").to_vec1::<f32>()?;
        assert!(g.iter().all(|v| v.is_finite()));
        assert!((g[5] - 1.0).abs() < 1e-6 && (g[2] - 0.6).abs() < 1e-3);
        Ok(())
    }
}
