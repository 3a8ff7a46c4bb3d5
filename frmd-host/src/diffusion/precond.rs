//! EDM preconditioning of the teacher D and the consistency parametrization of the student f, in
//! the two output forms of [`ProDmpOutput`] (docs/design.md, "Parametrization").
//!
//! With `g = G(E(c_in x, o, c_noise))` the decoded network output and `b = G(0; y0, v0)` the part
//! of every chunk fixed by the initial condition:
//! - `Direct` (MPD): D = g; the student is Song et al.'s first parametrization, f(x, sigma_min) = x
//!   and f = g above sigma_min (so the student starts equal to the teacher's D).
//! - `BoundarySkip`: D = b + c_skip (x - b) + c_out (g - b) with EDM's c_skip/c_out for the
//!   teacher and the consistency ones (identity at sigma_min) for the student. The skip acts on the
//!   free part only: scaling the whole of g by c_out would also scale the y0/v0 terms (measured:
//!   5 % success on reach, session 1).
use super::sigma_err;
use crate::models::{Condition, Network, ProDmpOutput};
use candle_core::{Device, Tensor};
use frmd_core::sigma::{noise_embedding, SigmaConfig, SigmaError};

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

/// `coefficient` at every level of `sigmas`; the error names `what`.
fn per_level(
    sigmas: &[f64],
    what: &str,
    coefficient: impl Fn(f64) -> Result<f64, SigmaError>,
) -> anyhow::Result<Vec<f64>> {
    sigmas
        .iter()
        .map(|&s| coefficient(s))
        .collect::<Result<Vec<_>, _>>()
        .map_err(sigma_err(what))
}

/// Per-sample network inputs for noise levels `sigmas`: (c_in column, embedding).
pub fn noise_inputs(
    sig: &SigmaConfig,
    sigmas: &[f64],
    embed_dim: usize,
    device: &Device,
) -> anyhow::Result<(Tensor, Tensor)> {
    let c_in = per_level(sigmas, "c_in", |s| sig.c_in(s))?;
    let c_noise = per_level(sigmas, "c_noise", |s| sig.c_noise(s))?;
    Ok((
        column(&c_in, device)?,
        embedding(&c_noise, embed_dim, device)?,
    ))
}

/// The network's decoded output g = G(E(c_in x, o, c_noise)) [B, n k] at per-row levels `sigmas`.
fn decoded(
    net: &Network,
    sig: &SigmaConfig,
    x: &Tensor,
    cond: &Condition,
    sigmas: &[f64],
) -> anyhow::Result<Tensor> {
    let (c_in, emb) = noise_inputs(sig, sigmas, net.config().embed_dim, x.device())?;
    net.predict(&x.broadcast_mul(&c_in)?, cond, &emb)
}

/// `b + c_skip (x - b) + c_out (g - b)` with per-row coefficients, computed as
/// `c_skip x + c_out g + (1 - c_skip - c_out) b` (the runtime's `frmd_core::policy::skip_output`).
fn skip_combine(
    net: &Network,
    cond: &Condition,
    x: &Tensor,
    g: &Tensor,
    c_skip: &[f64],
    c_out: &[f64],
) -> anyhow::Result<Tensor> {
    let device = x.device();
    let rest: Vec<f64> = c_skip.iter().zip(c_out).map(|(s, o)| 1.0 - s - o).collect();
    let b = net.boundary(cond)?;
    let out =
        (x.broadcast_mul(&column(c_skip, device)?)? + g.broadcast_mul(&column(c_out, device)?)?)?;
    Ok((out + b.broadcast_mul(&column(&rest, device)?)?)?)
}

/// The teacher's denoised estimate D(x, o, sigma) [B, n k]; `sigmas` has one level per row.
pub fn teacher_denoise(
    net: &Network,
    sig: &SigmaConfig,
    x: &Tensor,
    cond: &Condition,
    sigmas: &[f64],
) -> anyhow::Result<Tensor> {
    let g = decoded(net, sig, x, cond, sigmas)?;
    match net.config().prodmp_output() {
        Some(ProDmpOutput::BoundarySkip) => {
            let c_skip = per_level(sigmas, "c_skip", |s| sig.edm_c_skip(s))?;
            let c_out = per_level(sigmas, "c_out", |s| sig.edm_c_out(s))?;
            skip_combine(net, cond, x, &g, &c_skip, &c_out)
        }
        Some(ProDmpOutput::Direct) | None => Ok(g),
    }
}

/// The consistency function f(x, o, sigma); f(x, o, sigma_min) = x in both output forms. Levels
/// below sigma_min are an error.
pub fn consistency(
    net: &Network,
    sig: &SigmaConfig,
    x: &Tensor,
    cond: &Condition,
    sigmas: &[f64],
) -> anyhow::Result<Tensor> {
    if let Some(bad) = sigmas.iter().find(|&&s| s.is_nan() || s < sig.sigma_min) {
        anyhow::bail!(
            "consistency function: noise level {bad} is below sigma_min {}",
            sig.sigma_min
        );
    }
    if net.config().prodmp_output() == Some(ProDmpOutput::BoundarySkip) {
        let g = decoded(net, sig, x, cond, sigmas)?;
        let c_skip = per_level(sigmas, "c_skip", |s| sig.c_skip(s))?;
        let c_out = per_level(sigmas, "c_out", |s| sig.c_out(s))?;
        return skip_combine(net, cond, x, &g, &c_skip, &c_out);
    }
    let at_boundary: Vec<f64> = sigmas
        .iter()
        .map(|&s| if s <= sig.sigma_min { 1.0 } else { 0.0 })
        .collect();
    if at_boundary.iter().all(|&m| m == 1.0) {
        return Ok(x.clone());
    }
    let inner = decoded(net, sig, x, cond, sigmas)?;
    if at_boundary.iter().all(|&m| m == 0.0) {
        return Ok(inner);
    }
    let keep = column(&at_boundary, x.device())?;
    let inner_weight = column(
        &at_boundary.iter().map(|m| 1.0 - m).collect::<Vec<_>>(),
        x.device(),
    )?;
    Ok((x.broadcast_mul(&keep)? + inner.broadcast_mul(&inner_weight)?)?)
}

#[cfg(test)]
mod tests;
