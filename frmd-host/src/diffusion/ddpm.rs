//! The DP baseline's discrete diffusion: squared-cosine beta schedule with T = 100 training
//! steps, epsilon prediction, DDPM (ancestral, T steps) and DDIM (eta = 0) sampling, with the
//! predicted clean sample clipped to [-1, 1] as in Diffusion Policy. The network's noise input is
//! the embedding of c_noise = ln(sigma_t)/4 with the equivalent VE level
//! sigma_t = sqrt((1 - abar_t) / abar_t), so every method shares one embedding.
use super::precond::{column, embedding};
use super::samplers::gaussian;
use crate::models::{Condition, Network};
use crate::rng::HostRng;
use anyhow::bail;
use candle_core::Tensor;

/// Discrete DDPM schedule.
#[derive(Clone, Debug)]
pub struct DdpmSchedule {
    pub betas: Vec<f64>,
    /// Cumulative products of (1 - beta).
    pub alpha_bars: Vec<f64>,
}

impl DdpmSchedule {
    /// Squared-cosine ("squaredcos_cap_v2") schedule with `steps` training steps.
    pub fn cosine(steps: usize) -> Self {
        let f = |t: f64| ((t / steps as f64 + 0.008) / 1.008 * std::f64::consts::FRAC_PI_2).cos().powi(2);
        let betas: Vec<f64> = (0..steps).map(|i| (1.0 - f(i as f64 + 1.0) / f(i as f64)).min(0.999)).collect();
        let mut alpha_bars = Vec::with_capacity(steps);
        let mut product = 1.0;
        for beta in &betas {
            product *= 1.0 - beta;
            alpha_bars.push(product);
        }
        DdpmSchedule { betas, alpha_bars }
    }

    pub fn steps(&self) -> usize {
        self.betas.len()
    }

    /// c_noise = ln(sqrt((1 - abar) / abar)) / 4 for each timestep.
    pub fn c_noise(&self, timesteps: &[usize]) -> Vec<f64> {
        timesteps.iter().map(|&t| {
            let abar = self.alpha_bars[t];
            ((1.0 - abar) / abar).sqrt().ln() / 4.0
        }).collect()
    }
}

/// Predicted noise eps(x_t, o, t) [B, n k].
pub fn predict_noise(net: &Network, sched: &DdpmSchedule, x: &Tensor, cond: &Condition, timesteps: &[usize]) -> anyhow::Result<Tensor> {
    let emb = embedding(&sched.c_noise(timesteps), net.config().embed_dim, x.device())?;
    net.predict(x, cond, &emb)
}

/// Training loss: mean squared error of the predicted noise at uniformly drawn timesteps.
pub fn dp_loss(net: &Network, sched: &DdpmSchedule, x0: &Tensor, cond: &Condition, rng: &mut HostRng) -> anyhow::Result<Tensor> {
    let (batch, dim) = x0.dims2()?;
    let device = x0.device();
    let timesteps: Vec<usize> = (0..batch).map(|_| rng.below(sched.steps())).collect();
    let signal: Vec<f64> = timesteps.iter().map(|&t| sched.alpha_bars[t].sqrt()).collect();
    let noise_scale: Vec<f64> = timesteps.iter().map(|&t| (1.0 - sched.alpha_bars[t]).sqrt()).collect();
    let eps = gaussian(rng, batch, dim, device)?;
    let noisy = (x0.broadcast_mul(&column(&signal, device)?)? + eps.broadcast_mul(&column(&noise_scale, device)?)?)?;
    let predicted = predict_noise(net, sched, &noisy, cond, &timesteps)?;
    Ok((predicted - eps)?.sqr()?.mean_all()?)
}

/// How the DP baseline is sampled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DpSampler {
    /// Ancestral DDPM over every training step.
    Ddpm,
    /// Deterministic DDIM over `steps` evenly spaced timesteps.
    Ddim,
}

fn clean_estimate(x: &Tensor, eps: &Tensor, abar: f64) -> anyhow::Result<Tensor> {
    Ok(((x - (eps * (1.0 - abar).sqrt())?)? / abar.sqrt())?.clamp(-1f32, 1f32)?)
}

/// Samples the DP baseline from standard-normal `x` [B, n k]. DDPM uses all T steps (`steps`
/// must be T); DDIM uses `steps` timesteps t = (steps-1) s, .., s, 0 with s = T / steps.
pub fn sample_dp(net: &Network, sched: &DdpmSchedule, cond: &Condition, x: Tensor, sampler: DpSampler, steps: usize, rng: &mut dyn super::samplers::NoiseSource) -> anyhow::Result<Tensor> {
    let total = sched.steps();
    let batch = x.dim(0)?;
    let mut x = x;
    match sampler {
        DpSampler::Ddpm => {
            if steps != total {
                bail!("DDPM samples all {total} training steps, not {steps}");
            }
            for t in (0..total).rev() {
                let eps = predict_noise(net, sched, &x, cond, &vec![t; batch])?;
                let abar = sched.alpha_bars[t];
                let abar_prev = if t > 0 { sched.alpha_bars[t - 1] } else { 1.0 };
                let beta = sched.betas[t];
                let x0 = clean_estimate(&x, &eps, abar)?;
                // Posterior mean of q(x_{t-1} | x_t, x0).
                let coef_x0 = abar_prev.sqrt() * beta / (1.0 - abar);
                let coef_xt = (1.0 - beta).sqrt() * (1.0 - abar_prev) / (1.0 - abar);
                x = ((x0 * coef_x0)? + (&x * coef_xt)?)?;
                if t > 0 {
                    let variance = (beta * (1.0 - abar_prev) / (1.0 - abar)).max(1e-20);
                    let noise = gaussian(rng, batch, x.dim(1)?, x.device())?;
                    x = (x + (noise * variance.sqrt())?)?;
                }
            }
        }
        DpSampler::Ddim => {
            if steps == 0 || steps > total {
                bail!("DDIM needs 1..={total} steps, got {steps}");
            }
            let stride = total / steps;
            for i in (0..steps).rev() {
                let t = i * stride;
                let eps = predict_noise(net, sched, &x, cond, &vec![t; batch])?;
                let abar = sched.alpha_bars[t];
                let abar_prev = if i > 0 { sched.alpha_bars[t - stride] } else { 1.0 };
                let x0 = clean_estimate(&x, &eps, abar)?;
                // Direction recomputed from the clipped x0 (as diffusers does after clipping).
                let eps = ((&x - (&x0 * abar.sqrt())?)? / (1.0 - abar).sqrt())?;
                x = ((x0 * abar_prev.sqrt())? + (eps * (1.0 - abar_prev).sqrt())?)?;
            }
        }
    }
    Ok(x)
}
