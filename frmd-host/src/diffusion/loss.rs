//! The teacher's denoising loss: lambda(sigma) ||D(x0 + sigma eps, o, sigma) - x0||^2 with
//! log-normal sigma (P_mean -1.2, P_std 1.2).
use super::precond::{column, teacher_denoise};
use super::samplers::gaussian;
use super::sigma_err;
use crate::models::{Condition, Network};
use crate::rng::HostRng;
use candle_core::Tensor;
use frmd_core::sigma::SigmaConfig;
use serde::{Deserialize, Serialize};

/// Per-sample weighting of the teacher loss.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LossWeight {
    /// EDM: (sigma^2 + sigma_data^2) / (sigma sigma_data)^2.
    Edm,
    /// The paper's 1 / sigma^2.
    InvSigmaSquared,
    /// No weighting.
    Uniform,
}

impl LossWeight {
    pub fn parse(text: &str) -> anyhow::Result<Self> {
        Ok(match text {
            "edm" => LossWeight::Edm,
            "inv-sigma2" => LossWeight::InvSigmaSquared,
            "uniform" => LossWeight::Uniform,
            other => anyhow::bail!("unknown loss weight `{other}` (edm, inv-sigma2, uniform)"),
        })
    }
}

/// Log-normal noise-level distribution of the teacher loss.
pub const P_MEAN: f64 = -1.2;
pub const P_STD: f64 = 1.2;

/// The weighted teacher loss on one batch (clean trajectories `x0` [B, n k]).
pub fn teacher_loss(net: &Network, sig: &SigmaConfig, x0: &Tensor, cond: &Condition, weight: LossWeight, rng: &mut HostRng) -> anyhow::Result<Tensor> {
    let (batch, dim) = x0.dims2()?;
    let device = x0.device();
    let sigmas: Vec<f64> = (0..batch).map(|_| (P_MEAN + P_STD * rng.normal()).exp()).collect();
    let weights = sigmas
        .iter()
        .map(|&s| match weight {
            LossWeight::Edm => sig.edm_loss_weight(s).map_err(sigma_err("loss weight")),
            LossWeight::InvSigmaSquared => Ok(1.0 / (s * s)),
            LossWeight::Uniform => Ok(1.0),
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let eps = gaussian(rng, batch, dim, device)?;
    let noisy = (x0 + eps.broadcast_mul(&column(&sigmas, device)?)?)?;
    let denoised = teacher_denoise(net, sig, &noisy, cond, &sigmas)?;
    let per_element = (denoised - x0)?.sqr()?.broadcast_mul(&column(&weights, device)?)?;
    Ok(per_element.mean_all()?)
}
