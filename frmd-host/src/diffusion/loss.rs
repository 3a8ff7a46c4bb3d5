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

variant_names!(LossWeight, "loss weight", { Edm = "edm", InvSigmaSquared = "inv-sigma2", Uniform = "uniform" });

/// Log-normal noise-level distribution of the teacher loss.
pub const P_MEAN: f64 = -1.2;
pub const P_STD: f64 = 1.2;

/// Noise-level distribution of the teacher loss: log-normal (P_MEAN, P_STD), and with
/// probability `uniform_fraction` log-uniform on [sigma_min, sigma_max] instead.
///
/// Why the mixture: the teacher predicts the clean trajectory directly (no EDM skip), so its
/// output at levels the log-normal almost never draws (sigma_max = 80 is 4.6 standard deviations
/// out) is an extrapolation — yet every sampler and the one-step student start there.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SigmaSampling {
    pub uniform_fraction: f64,
}

impl SigmaSampling {
    /// The log-normal levels alone (no log-uniform draws).
    pub const LOG_NORMAL: SigmaSampling = SigmaSampling {
        uniform_fraction: 0.0,
    };

    pub fn draw(&self, sig: &SigmaConfig, rng: &mut HostRng) -> f64 {
        if self.uniform_fraction > 0.0 && rng.uniform() < self.uniform_fraction {
            let (lo, hi) = (sig.sigma_min.ln(), sig.sigma_max.ln());
            (lo + (hi - lo) * rng.uniform()).exp()
        } else {
            (P_MEAN + P_STD * rng.normal()).exp()
        }
    }
}

/// The weighted teacher loss on one batch (clean trajectories `x0` [B, n k]).
pub fn teacher_loss(
    net: &Network,
    sig: &SigmaConfig,
    x0: &Tensor,
    cond: &Condition,
    weight: LossWeight,
    sampling: SigmaSampling,
    rng: &mut HostRng,
) -> anyhow::Result<Tensor> {
    let (batch, dim) = x0.dims2()?;
    let device = x0.device();
    let sigmas: Vec<f64> = (0..batch).map(|_| sampling.draw(sig, rng)).collect();
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
    let per_element = (denoised - x0)?
        .sqr()?
        .broadcast_mul(&column(&weights, device)?)?;
    Ok(per_element.mean_all()?)
}
