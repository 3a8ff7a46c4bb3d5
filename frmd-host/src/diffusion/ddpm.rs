//! The DP baseline's discrete diffusion: squared-cosine beta schedule with T = 100 training
//! steps, epsilon prediction, DDPM (ancestral, T steps) and DDIM (eta = 0) sampling, with the
//! predicted clean sample clipped to [-1, 1] as in Diffusion Policy. The network's noise input is
//! the embedding of c_noise = ln(sigma_t)/4 with the equivalent VE level
//! sigma_t = sqrt((1 - abar_t) / abar_t), so every method shares one embedding.
//!
//! The noise estimate comes from the network in one of two [`EpsParametrization`]s; the loss
//! (mean squared noise error at uniform timesteps) and both samplers are the same for either.
use super::precond::{column, embedding};
use super::samplers::gaussian;
use crate::models::{Condition, Network};
use crate::rng::HostRng;
use anyhow::bail;
use candle_core::Tensor;
use frmd_core::sigma::SigmaConfig;

/// Number of DDPM noise levels of the DP baseline: its training schedule, and the step count at
/// which sampling is full DDPM (fewer steps sample with DDIM).
pub const DP_TRAIN_STEPS: usize = 100;

/// How the network's output F becomes the noise estimate eps(x_t, o, t).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EpsParametrization {
    /// eps = F(x_t, o, t), as in Chi et al.'s Diffusion Policy.
    #[default]
    Direct,
    /// EDM-style preconditioning written for the noise (Karras et al. 2022, with sigma_data of
    /// docs/design.md section 3): with s2 = (1 - abar) + abar sigma_data^2,
    /// eps = sqrt(1 - abar) / s2 * x_t - sigma_data sqrt(abar) / sqrt(s2) * F(x_t / sqrt(s2), o, t).
    /// The skip term is the exact noise estimate for data ~ N(0, sigma_data^2), so F only learns
    /// a unit-scale correction and never has to carry x_t through the network (with `Direct`, an
    /// MLP must reproduce x_t / sqrt(1 - abar), 40x at t = 0, and its error shows up as
    /// per-action jitter in the chunk). Same loss, same samplers.
    Preconditioned,
}

variant_names!(EpsParametrization, "DP parametrization", { Direct = "direct", Preconditioned = "preconditioned" });

/// Discrete DDPM schedule plus the parametrization of the noise network.
#[derive(Clone, Debug)]
pub struct DdpmSchedule {
    pub betas: Vec<f64>,
    /// Cumulative products of (1 - beta).
    pub alpha_bars: Vec<f64>,
    pub parametrization: EpsParametrization,
}

impl DdpmSchedule {
    /// Squared-cosine ("squaredcos_cap_v2") schedule with `steps` training steps and the
    /// `Direct` parametrization.
    pub fn cosine(steps: usize) -> Self {
        let f = |t: f64| {
            ((t / steps as f64 + 0.008) / 1.008 * std::f64::consts::FRAC_PI_2)
                .cos()
                .powi(2)
        };
        let betas: Vec<f64> = (0..steps)
            .map(|i| (1.0 - f(i as f64 + 1.0) / f(i as f64)).min(0.999))
            .collect();
        let mut alpha_bars = Vec::with_capacity(steps);
        let mut product = 1.0;
        for beta in &betas {
            product *= 1.0 - beta;
            alpha_bars.push(product);
        }
        DdpmSchedule {
            betas,
            alpha_bars,
            parametrization: EpsParametrization::Direct,
        }
    }

    /// The same schedule with another parametrization.
    pub fn with_parametrization(mut self, parametrization: EpsParametrization) -> Self {
        self.parametrization = parametrization;
        self
    }

    pub fn steps(&self) -> usize {
        self.betas.len()
    }

    /// c_noise = ln(sqrt((1 - abar) / abar)) / 4 for each timestep.
    pub fn c_noise(&self, timesteps: &[usize]) -> Vec<f64> {
        timesteps
            .iter()
            .map(|&t| {
                let abar = self.alpha_bars[t];
                ((1.0 - abar) / abar).sqrt().ln() / 4.0
            })
            .collect()
    }

    /// Per-timestep (input scale, skip, output) coefficients: eps = skip x_t + out F(in x_t).
    fn coefficients(&self, timesteps: &[usize]) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let sigma_data = SigmaConfig::default().sigma_data;
        let mut scale_in = Vec::with_capacity(timesteps.len());
        let mut skip = Vec::with_capacity(timesteps.len());
        let mut out = Vec::with_capacity(timesteps.len());
        for &t in timesteps {
            let abar = self.alpha_bars[t];
            match self.parametrization {
                EpsParametrization::Direct => {
                    scale_in.push(1.0);
                    skip.push(0.0);
                    out.push(1.0);
                }
                EpsParametrization::Preconditioned => {
                    let s2 = (1.0 - abar) + abar * sigma_data * sigma_data;
                    scale_in.push(1.0 / s2.sqrt());
                    skip.push((1.0 - abar).sqrt() / s2);
                    out.push(-sigma_data * abar.sqrt() / s2.sqrt());
                }
            }
        }
        (scale_in, skip, out)
    }
}

/// Predicted noise eps(x_t, o, t) [B, n k].
pub fn predict_noise(
    net: &Network,
    sched: &DdpmSchedule,
    x: &Tensor,
    cond: &Condition,
    timesteps: &[usize],
) -> anyhow::Result<Tensor> {
    let device = x.device();
    let emb = embedding(&sched.c_noise(timesteps), net.config().embed_dim, device)?;
    match sched.parametrization {
        EpsParametrization::Direct => net.predict(x, cond, &emb),
        EpsParametrization::Preconditioned => {
            let (scale_in, skip, out) = sched.coefficients(timesteps);
            let f = net.predict(&x.broadcast_mul(&column(&scale_in, device)?)?, cond, &emb)?;
            Ok((x.broadcast_mul(&column(&skip, device)?)?
                + f.broadcast_mul(&column(&out, device)?)?)?)
        }
    }
}

/// Training loss: mean squared error of the predicted noise at uniformly drawn timesteps.
pub fn dp_loss(
    net: &Network,
    sched: &DdpmSchedule,
    x0: &Tensor,
    cond: &Condition,
    rng: &mut HostRng,
) -> anyhow::Result<Tensor> {
    let (batch, dim) = x0.dims2()?;
    let device = x0.device();
    let timesteps: Vec<usize> = (0..batch).map(|_| rng.below(sched.steps())).collect();
    let signal: Vec<f64> = timesteps
        .iter()
        .map(|&t| sched.alpha_bars[t].sqrt())
        .collect();
    let noise_scale: Vec<f64> = timesteps
        .iter()
        .map(|&t| (1.0 - sched.alpha_bars[t]).sqrt())
        .collect();
    let eps = gaussian(rng, batch, dim, device)?;
    let noisy = (x0.broadcast_mul(&column(&signal, device)?)?
        + eps.broadcast_mul(&column(&noise_scale, device)?)?)?;
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

/// The forward process at `abar`: `x_t = sqrt(abar) x0 + sqrt(1 - abar) eps`.
pub fn noised(x0: &Tensor, eps: &Tensor, abar: f64) -> candle_core::Result<Tensor> {
    (x0 * abar.sqrt())? + (eps * (1.0 - abar).sqrt())?
}

/// The clean trajectory that `x_t` and the noise `eps` imply at `abar` (not clipped).
pub fn implied_clean(x: &Tensor, eps: &Tensor, abar: f64) -> candle_core::Result<Tensor> {
    (x - (eps * (1.0 - abar).sqrt())?)? / abar.sqrt()
}

/// One deterministic DDIM step of `x` from `abar` to `abar_prev` towards the clean estimate
/// `x0`; the direction is recomputed from `x0` (as diffusers does after clipping it).
pub fn ddim_step(x: &Tensor, x0: Tensor, abar: f64, abar_prev: f64) -> candle_core::Result<Tensor> {
    let eps = ((x - (&x0 * abar.sqrt())?)? / (1.0 - abar).sqrt())?;
    (x0 * abar_prev.sqrt())? + (eps * (1.0 - abar_prev).sqrt())?
}

fn clean_estimate(x: &Tensor, eps: &Tensor, abar: f64) -> anyhow::Result<Tensor> {
    Ok(implied_clean(x, eps, abar)?.clamp(-1f32, 1f32)?)
}

/// Samples the DP baseline from standard-normal `x` [B, n k]. DDPM uses all T steps (`steps`
/// must be T); DDIM uses `steps` timesteps t = (steps-1) s, .., s, 0 with s = T / steps.
pub fn sample_dp(
    net: &Network,
    sched: &DdpmSchedule,
    cond: &Condition,
    x: Tensor,
    sampler: DpSampler,
    steps: usize,
    rng: &mut dyn super::samplers::NoiseSource,
) -> anyhow::Result<Tensor> {
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
                let abar_prev = if i > 0 {
                    sched.alpha_bars[t - stride]
                } else {
                    1.0
                };
                let x0 = clean_estimate(&x, &eps, abar)?;
                x = ddim_step(&x, x0, abar, abar_prev)?;
            }
        }
    }
    Ok(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::toy::toy_config;
    use crate::models::{HeadConfig, OwnedNetwork};
    use candle_core::Device;

    fn zero_network() -> OwnedNetwork {
        let net = OwnedNetwork::new_seeded(&toy_config(HeadConfig::Raw), 1, &Device::Cpu).unwrap();
        for var in net.varmap.all_vars() {
            var.set(&var.as_tensor().zeros_like().unwrap()).unwrap();
        }
        net
    }

    fn toy_cond(batch: usize) -> Condition {
        let zeros = Tensor::zeros((batch, 1), candle_core::DType::F32, &Device::Cpu).unwrap();
        Condition::new(&zeros, zeros.clone(), zeros.clone(), 0.1).unwrap()
    }

    /// With F = 0 the preconditioned estimate is the skip term alone, which is the exact
    /// posterior-mean noise for data ~ N(0, sigma_data^2): its mean squared error on such data
    /// is 1 - (1 - abar) / s2 at every timestep, while the direct form with F = 0 predicts 0
    /// (error 1). Checks the coefficients and that the skip term is wired to x_t.
    #[test]
    fn preconditioned_skip_is_the_gaussian_posterior_noise() -> anyhow::Result<()> {
        let net = zero_network();
        let sched =
            DdpmSchedule::cosine(100).with_parametrization(EpsParametrization::Preconditioned);
        let direct_sched = sched
            .clone()
            .with_parametrization(EpsParametrization::Direct);
        let sigma_data = SigmaConfig::default().sigma_data;
        let (batch, dim) = (4000, 4);
        let mut rng = HostRng::new(3);
        for t in [0usize, 10, 50, 90, 99] {
            let abar = sched.alpha_bars[t];
            let x0 = (gaussian(&mut rng, batch, dim, &Device::Cpu)? * sigma_data)?;
            let eps = gaussian(&mut rng, batch, dim, &Device::Cpu)?;
            let x = noised(&x0, &eps, abar)?;
            let timesteps = vec![t; batch];
            let predicted = predict_noise(&net.net, &sched, &x, &toy_cond(batch), &timesteps)?;
            let mse = (&predicted - &eps)?.sqr()?.mean_all()?.to_scalar::<f32>()? as f64;
            let s2 = (1.0 - abar) + abar * sigma_data * sigma_data;
            let expected = 1.0 - (1.0 - abar) / s2;
            assert!(
                (mse - expected).abs() < 0.03 + 0.05 * expected,
                "t {t}: mse {mse} vs {expected}"
            );
            let direct = predict_noise(&net.net, &direct_sched, &x, &toy_cond(batch), &timesteps)?;
            assert_eq!(direct.abs()?.max_all()?.to_scalar::<f32>()?, 0.0);
        }
        Ok(())
    }

    #[test]
    fn parametrization_names_round_trip() {
        for p in [
            EpsParametrization::Direct,
            EpsParametrization::Preconditioned,
        ] {
            let name = serde_json::to_value(p).unwrap();
            assert_eq!(
                EpsParametrization::parse(name.as_str().unwrap()).unwrap(),
                p
            );
        }
        assert!(EpsParametrization::parse("x0").is_err());
    }
}
