//! EDM preconditioning of the teacher D and the consistency parametrization of the student f.
//!
//! Teacher: D(x, o, sigma) = G(E(c_in(sigma) x, o, c_noise(sigma))) — the decoded ProDMP
//! trajectory is the denoised estimate.
//!
//! Student: the first parametrization of Song et al. (2023), f(x, sigma_min) = x and
//! f(x, sigma) = G(E(c_in x, o, c_noise)) for sigma > sigma_min, with the same network shape as the
//! teacher (so it starts equal to the teacher's D).
//!
//! Deviation from DESIGN.md section 3 (f = c_skip x + c_out G with the smooth c_skip/c_out of
//! `frmd_core::sigma`, kept there): with a trajectory-space skip term, f carries c_skip(sigma) x,
//! i.e. white noise on every action, which a ProDMP output can only cancel with wild, ill-conditioned
//! parameters (H(t) vanishes with its slope at t = 0). Measured on reach (MLP teacher 100 %
//! success): distilling with c_out G scaled the chunk start by c_out and gave 5 % success; with
//! (1 - c_skip) G the student's chunks became jerky (RMS jerk 74 m/s^3 vs 9) and 0 % success.
//! With this form every output, one-step or multistep, is an exact ProDMP trajectory.
use super::sigma_err;
use crate::models::{Condition, Network};
use candle_core::{Device, Tensor};
use frmd_core::sigma::{noise_embedding, SigmaConfig};

/// A [B, 1] f32 column from per-sample values.
pub fn column(values: &[f64], device: &Device) -> anyhow::Result<Tensor> {
    let data: Vec<f32> = values.iter().map(|&v| v as f32).collect();
    Ok(Tensor::from_vec(data, (values.len(), 1), device)?)
}

/// Noise embedding [B, embed_dim] of per-sample noise conditioning values `c_noise`.
pub fn embedding(c_noise: &[f64], embed_dim: usize, device: &Device) -> anyhow::Result<Tensor> {
    let mut data = Vec::with_capacity(c_noise.len() * embed_dim);
    let mut row = vec![0.0f64; embed_dim];
    for &c in c_noise {
        noise_embedding(c, &mut row).map_err(sigma_err("noise embedding"))?;
        data.extend(row.iter().map(|&v| v as f32));
    }
    Ok(Tensor::from_vec(data, (c_noise.len(), embed_dim), device)?)
}

/// Per-sample network inputs for noise levels `sigmas`: (c_in column, embedding).
pub fn noise_inputs(sig: &SigmaConfig, sigmas: &[f64], embed_dim: usize, device: &Device) -> anyhow::Result<(Tensor, Tensor)> {
    let c_in = sigmas.iter().map(|&s| sig.c_in(s)).collect::<Result<Vec<_>, _>>().map_err(sigma_err("c_in"))?;
    let c_noise = sigmas.iter().map(|&s| sig.c_noise(s)).collect::<Result<Vec<_>, _>>().map_err(sigma_err("c_noise"))?;
    Ok((column(&c_in, device)?, embedding(&c_noise, embed_dim, device)?))
}

/// The teacher's denoised estimate D(x, o, sigma) [B, n k]; `sigmas` has one level per row.
pub fn teacher_denoise(net: &Network, sig: &SigmaConfig, x: &Tensor, cond: &Condition, sigmas: &[f64]) -> anyhow::Result<Tensor> {
    let (c_in, emb) = noise_inputs(sig, sigmas, net.config().embed_dim, x.device())?;
    net.predict(&x.broadcast_mul(&c_in)?, cond, &emb)
}

/// The consistency function: f(x, o, sigma_min) = x exactly, f(x, o, sigma) = G(E(c_in x, o,
/// c_noise)) above sigma_min. Levels below sigma_min are an error.
pub fn consistency(net: &Network, sig: &SigmaConfig, x: &Tensor, cond: &Condition, sigmas: &[f64]) -> anyhow::Result<Tensor> {
    if let Some(bad) = sigmas.iter().find(|&&s| s.is_nan() || s < sig.sigma_min) {
        anyhow::bail!("consistency function: noise level {bad} is below sigma_min {}", sig.sigma_min);
    }
    let at_boundary: Vec<f64> = sigmas.iter().map(|&s| if s <= sig.sigma_min { 1.0 } else { 0.0 }).collect();
    if at_boundary.iter().all(|&m| m == 1.0) {
        return Ok(x.clone());
    }
    let inner = teacher_denoise(net, sig, x, cond, sigmas)?;
    if at_boundary.iter().all(|&m| m == 0.0) {
        return Ok(inner);
    }
    let keep = column(&at_boundary, x.device())?;
    let inner_weight = column(&at_boundary.iter().map(|m| 1.0 - m).collect::<Vec<_>>(), x.device())?;
    Ok((x.broadcast_mul(&keep)? + inner.broadcast_mul(&inner_weight)?)?)
}
