//! Samplers. Teacher: Euler, Heun (EDM Algorithm 1) and DPM-Solver++(2M) on the probability-flow
//! ODE dx/dsigma = (x - D(x, sigma)) / sigma over a Karras schedule followed by sigma = 0.
//! Student: one-step and multistep consistency sampling.
use super::precond::{column, consistency, teacher_denoise};
use super::sigma_err;
use crate::models::{Condition, Network};
use crate::rng::HostRng;
use anyhow::bail;
use candle_core::Tensor;
use frmd_core::sigma::SigmaConfig;
use serde::{Deserialize, Serialize};

/// ODE solver of the teacher.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Solver {
    Euler,
    Heun,
    /// DPM-Solver++(2M) (Lu et al. 2022), multistep second order in log-sigma.
    DpmPp2m,
}

variant_names!(Solver, "solver", { Euler = "euler", Heun = "heun", DpmPp2m = "dpm++2m" | "dpmpp2m" | "dpm-pp-2m" });

impl Solver {
    /// Network evaluations for `steps` steps ending at sigma = 0.
    pub fn evaluations(self, steps: usize) -> usize {
        match self {
            Solver::Heun => (2 * steps).saturating_sub(1),
            _ => steps,
        }
    }
}

/// A source of standard-normal f32 samples (the host training generator, or frmd-core's
/// firmware generator so float and firmware policies can share noise streams).
pub trait NoiseSource {
    fn fill_normal(&mut self, out: &mut [f32]);
}

impl NoiseSource for HostRng {
    fn fill_normal(&mut self, out: &mut [f32]) {
        out.iter_mut().for_each(|v| *v = self.normal() as f32);
    }
}

impl NoiseSource for frmd_core::rng::Rng {
    fn fill_normal(&mut self, out: &mut [f32]) {
        self.fill_gaussian(out);
    }
}

/// Standard normal noise [B, dim] from a seeded source.
pub fn gaussian(
    rng: &mut dyn NoiseSource,
    batch: usize,
    dim: usize,
    device: &candle_core::Device,
) -> anyhow::Result<Tensor> {
    let mut data = vec![0f32; batch * dim];
    rng.fill_normal(&mut data);
    Ok(Tensor::from_vec(data, (batch, dim), device)?)
}

/// `steps` Karras levels from sigma_max down to sigma_min, then 0.
pub fn karras_schedule(sig: &SigmaConfig, steps: usize) -> anyhow::Result<Vec<f64>> {
    let mut levels = (0..steps)
        .map(|i| sig.karras_sigma(i, steps))
        .collect::<Result<Vec<_>, _>>()
        .map_err(sigma_err("karras schedule"))?;
    levels.push(0.0);
    Ok(levels)
}

/// One Euler or Heun step of the teacher ODE from per-row levels `from` to `to` (`to` may be 0).
pub fn ode_step(
    net: &Network,
    sig: &SigmaConfig,
    x: &Tensor,
    cond: &Condition,
    from: &[f64],
    to: &[f64],
    heun: bool,
) -> anyhow::Result<Tensor> {
    let device = x.device();
    let denoised = teacher_denoise(net, sig, x, cond, from)?;
    let inv_from: Vec<f64> = from.iter().map(|s| 1.0 / s).collect();
    let slope = (x - &denoised)?.broadcast_mul(&column(&inv_from, device)?)?;
    let delta: Vec<f64> = from.iter().zip(to).map(|(a, b)| b - a).collect();
    let delta = column(&delta, device)?;
    let euler = (x + slope.broadcast_mul(&delta)?)?;
    if !heun || to.iter().any(|&s| s <= 0.0) {
        return Ok(euler);
    }
    let denoised2 = teacher_denoise(net, sig, &euler, cond, to)?;
    let inv_to: Vec<f64> = to.iter().map(|s| 1.0 / s).collect();
    let slope2 = (&euler - &denoised2)?.broadcast_mul(&column(&inv_to, device)?)?;
    Ok((x + ((slope + slope2)? * 0.5)?.broadcast_mul(&delta)?)?)
}

/// Integrates the teacher ODE from `x` (already scaled to sigma_max) to sigma = 0 in `steps` steps.
pub fn sample_teacher(
    net: &Network,
    sig: &SigmaConfig,
    cond: &Condition,
    x: Tensor,
    steps: usize,
    solver: Solver,
) -> anyhow::Result<Tensor> {
    if steps == 0 {
        bail!("teacher sampling needs at least one step");
    }
    let batch = x.dim(0)?;
    let levels = karras_schedule(sig, steps)?;
    let mut x = x;
    let mut previous: Option<Tensor> = None;
    for (i, pair) in levels.windows(2).enumerate() {
        let (from, to) = (pair[0], pair[1]);
        match solver {
            Solver::Euler | Solver::Heun => {
                x = ode_step(
                    net,
                    sig,
                    &x,
                    cond,
                    &vec![from; batch],
                    &vec![to; batch],
                    solver == Solver::Heun,
                )?;
            }
            Solver::DpmPp2m => {
                let denoised = teacher_denoise(net, sig, &x, cond, &vec![from; batch])?;
                if to <= 0.0 {
                    x = denoised;
                    break;
                }
                let h = from.ln() - to.ln(); // t = -ln(sigma); h = t_next - t
                let target = match (&previous, i) {
                    (Some(old), i) if i >= 1 => {
                        let h_last = levels[i - 1].ln() - from.ln();
                        let r = h_last / h;
                        ((&denoised * (1.0 + 1.0 / (2.0 * r)))? - (old * (1.0 / (2.0 * r)))?)?
                    }
                    _ => denoised.clone(),
                };
                x = ((&x * (to / from))? - (target * (-h).exp_m1())?)?;
                previous = Some(denoised);
            }
        }
    }
    Ok(x)
}

/// Noise levels of `steps`-step consistency sampling: sigma_max, then the low re-noising levels
/// of [`SigmaConfig::consistency_sampling_sigma`].
pub fn consistency_levels(sig: &SigmaConfig, steps: usize) -> anyhow::Result<Vec<f64>> {
    if steps == 0 {
        bail!("consistency sampling needs at least one step");
    }
    (0..steps)
        .map(|i| sig.consistency_sampling_sigma(i, steps))
        .collect::<Result<Vec<_>, _>>()
        .map_err(sigma_err("consistency levels"))
}

/// Consistency sampling: x0 = f(sigma_max z); for each further level tau,
/// x0 = f(x0 + sqrt(tau^2 - sigma_min^2) z', tau). `z` is the initial standard-normal noise.
pub fn sample_consistency(
    net: &Network,
    sig: &SigmaConfig,
    cond: &Condition,
    z: &Tensor,
    steps: usize,
    rng: &mut dyn NoiseSource,
) -> anyhow::Result<Tensor> {
    let batch = z.dim(0)?;
    let levels = consistency_levels(sig, steps)?;
    let start = (z * sig.sigma_max)?;
    let mut out = consistency(net, sig, &start, cond, &vec![sig.sigma_max; batch])?;
    for &level in levels.iter().skip(1) {
        let scale = (level * level - sig.sigma_min * sig.sigma_min)
            .max(0.0)
            .sqrt();
        let noise = gaussian(rng, batch, z.dim(1)?, z.device())?;
        let noisy = (&out + (noise * scale)?)?;
        out = consistency(net, sig, &noisy, cond, &vec![level; batch])?;
    }
    Ok(out)
}
