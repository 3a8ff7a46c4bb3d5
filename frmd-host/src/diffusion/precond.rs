//! EDM preconditioning of the teacher D and the consistency parametrization of the student f.
//!
//! Teacher: D(x, o, sigma) = G(E(c_in(sigma) x, o, c_noise(sigma))) — the decoded ProDMP
//! trajectory is the denoised estimate. Student: f = c_skip(sigma) x + c_out_blend(sigma) G(E(..))
//! with c_out_blend = 1 - c_skip, so f(x, sigma_min) = x exactly.
//!
//! Deviation from DESIGN.md section 3 (which scales G by the consistency c_out =
//! (sigma - sigma_min) sigma_data / sqrt(sigma^2 + sigma_data^2)): G contains the boundary terms
//! xi1(t) y0 + xi2(t) v0, and ProDMP's H(t) vanishes with its slope at t = 0, so scaling G by
//! c_out (~0.5 at sigma_max) halves the start of every chunk and no theta can undo it (measured on
//! reach: first action off by ~0.2 m, 5 % success). With 1 - c_skip the output is a convex blend
//! of the noisy input and a ProDMP trajectory, the boundary conditions hold, and the student
//! starts equal to the teacher for large sigma.
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

/// The consistency function f(x, o, sigma) = c_skip x + (1 - c_skip) G(E(c_in x, o, c_noise)).
pub fn consistency(net: &Network, sig: &SigmaConfig, x: &Tensor, cond: &Condition, sigmas: &[f64]) -> anyhow::Result<Tensor> {
    let device = x.device();
    let c_skip = sigmas.iter().map(|&s| sig.c_skip(s)).collect::<Result<Vec<_>, _>>().map_err(sigma_err("c_skip"))?;
    let c_out = sigmas.iter().map(|&s| sig.c_out_blend(s)).collect::<Result<Vec<_>, _>>().map_err(sigma_err("c_out"))?;
    let inner = teacher_denoise(net, sig, x, cond, sigmas)?;
    Ok((x.broadcast_mul(&column(&c_skip, device)?)? + inner.broadcast_mul(&column(&c_out, device)?)?)?)
}
