//! The ProDMP decoder inside the candle graph: a fixed linear map of (theta, y0, v0) whose
//! coefficients come from `frmd_core::prodmp::linear_row` (the one ProDMP implementation), at
//! query times tau/n, 2 tau/n, .., tau (tau = n dt) with initial time 0 (docs/design.md section 2, policy case).
use anyhow::Context;
use candle_core::{Device, Tensor};
use frmd_core::prodmp::{ProDmp, ProDmpConfig};

/// The decoder's coefficient tables in f64, as produced by frmd-core.
#[derive(Clone, Debug)]
pub struct DecoderRows {
    pub horizon: usize,
    pub num_params: usize,
    /// [horizon, num_params], row t = coefficients of theta for position at time (t+1) dt.
    pub pos_params: Vec<f64>,
    /// \[horizon\] coefficients of y0 and v0 (v0 in units per second).
    pub pos_y0: Vec<f64>,
    pub pos_v0: Vec<f64>,
}

impl DecoderRows {
    pub fn new(cfg: &ProDmpConfig, horizon: usize) -> anyhow::Result<Self> {
        let decoder = ProDmp::new(cfg).context("invalid ProDMP config")?;
        let num_params = cfg.num_params_per_dof();
        let mut pos_params = vec![0.0; horizon * num_params];
        let mut vel_params = vec![0.0; num_params];
        let mut pos_y0 = Vec::with_capacity(horizon);
        let mut pos_v0 = Vec::with_capacity(horizon);
        for (t, row) in pos_params.chunks_exact_mut(num_params).enumerate() {
            // Same query times as frmd_core::prodmp::BakedProDmp: (t + 1) tau / n.
            let time = (t + 1) as f64 * (cfg.tau / horizon as f64);
            let coeffs = decoder
                .linear_row(0.0, time, row, &mut vel_params)
                .with_context(|| format!("ProDMP row at t = {time}"))?;
            pos_y0.push(coeffs.pos_y0);
            pos_v0.push(coeffs.pos_v0);
        }
        Ok(DecoderRows {
            horizon,
            num_params,
            pos_params,
            pos_y0,
            pos_v0,
        })
    }
}

/// Decodes DoF-major ProDMP parameters to a step-major position trajectory.
#[derive(Clone, Debug)]
pub struct ProDmpDecoder {
    num_dof: usize,
    num_params: usize,
    horizon: usize,
    /// [num_params, horizon] (transposed rows, f32).
    params_to_pos: Tensor,
    /// [1, horizon, 1]
    y0_to_pos: Tensor,
    /// [1, horizon, 1]
    v0_to_pos: Tensor,
}

impl ProDmpDecoder {
    pub fn new(cfg: &ProDmpConfig, horizon: usize, device: &Device) -> anyhow::Result<Self> {
        let rows = DecoderRows::new(cfg, horizon)?;
        let pos: Vec<f32> = rows.pos_params.iter().map(|&v| v as f32).collect();
        let params_to_pos = Tensor::from_vec(pos, (horizon, rows.num_params), device)?
            .t()?
            .contiguous()?;
        let y0: Vec<f32> = rows.pos_y0.iter().map(|&v| v as f32).collect();
        let v0: Vec<f32> = rows.pos_v0.iter().map(|&v| v as f32).collect();
        Ok(ProDmpDecoder {
            num_dof: cfg.num_dof,
            num_params: rows.num_params,
            horizon,
            params_to_pos,
            y0_to_pos: Tensor::from_vec(y0, (1, horizon, 1), device)?,
            v0_to_pos: Tensor::from_vec(v0, (1, horizon, 1), device)?,
        })
    }

    /// Number of network outputs the decoder consumes: k (b + 1).
    pub fn num_inputs(&self) -> usize {
        self.num_dof * self.num_params
    }

    /// `theta` [B, k (b+1)] (DoF-major: params\[d\] = [w_0 .. w_{b-1}, g]), `y0` [B, k],
    /// `v0` [B, k] (units per second) -> positions [B, n k], step-major.
    pub fn decode(&self, theta: &Tensor, y0: &Tensor, v0: &Tensor) -> anyhow::Result<Tensor> {
        let batch = theta.dim(0)?;
        let (k, n) = (self.num_dof, self.horizon);
        let from_params = theta
            .reshape((batch * k, self.num_params))?
            .matmul(&self.params_to_pos)
            .context("ProDMP decode")?
            .reshape((batch, k, n))?
            .transpose(1, 2)?; // [B, n, k]
        let (y0, v0) = self.boundary_parts(y0, v0)?;
        Ok((from_params + y0 + v0)?.reshape((batch, n * k))?)
    }

    /// The initial-condition part of every decoded chunk, `decode(0, y0, v0)` [B, n k].
    pub fn boundary(&self, y0: &Tensor, v0: &Tensor) -> anyhow::Result<Tensor> {
        let (batch, k) = y0.dims2()?;
        let (y0, v0) = self.boundary_parts(y0, v0)?;
        Ok((y0 + v0)?.reshape((batch, self.horizon * k))?)
    }

    /// The y0 and v0 terms [B, n, k] of the decoded positions.
    fn boundary_parts(&self, y0: &Tensor, v0: &Tensor) -> anyhow::Result<(Tensor, Tensor)> {
        let (batch, k) = y0.dims2()?;
        let y0 = y0.reshape((batch, 1, k))?.broadcast_mul(&self.y0_to_pos)?;
        let v0 = v0.reshape((batch, 1, k))?.broadcast_mul(&self.v0_to_pos)?;
        Ok((y0, v0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::HostRng;
    use frmd_core::prodmp::BakedProDmp;

    /// The candle decode layer equals frmd-core's baked f32 decoder (the firmware path).
    #[test]
    fn candle_decode_matches_frmd_core() {
        const N: usize = 12;
        const P: usize = 21;
        const K: usize = 2;
        let cfg = ProDmpConfig::policy(K, P - 1, N, 0.1);
        let decoder = ProDmpDecoder::new(&cfg, N, &Device::Cpu).unwrap();
        let baked = BakedProDmp::<N, P>::from_config(&cfg).unwrap();
        let mut rng = HostRng::new(3);
        for _ in 0..5 {
            let mut params = [[0f32; P]; K];
            params
                .iter_mut()
                .flatten()
                .for_each(|v| *v = rng.normal() as f32);
            let y0 = [rng.normal() as f32, rng.normal() as f32];
            let v0 = [rng.normal() as f32, rng.normal() as f32];
            let (mut pos, mut vel) = ([[0f32; K]; N], [[0f32; K]; N]);
            baked.decode(&params, &y0, &v0, &mut pos, &mut vel).unwrap();
            let theta = Tensor::from_vec(
                params.iter().flatten().copied().collect::<Vec<_>>(),
                (1, K * P),
                &Device::Cpu,
            )
            .unwrap();
            let y0t = Tensor::from_slice(&y0, (1, K), &Device::Cpu).unwrap();
            let v0t = Tensor::from_slice(&v0, (1, K), &Device::Cpu).unwrap();
            let out = decoder
                .decode(&theta, &y0t, &v0t)
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1::<f32>()
                .unwrap();
            let reference: Vec<f32> = pos.iter().flatten().copied().collect();
            let scale = reference.iter().fold(0f32, |m, v| m.max(v.abs()));
            for (a, b) in out.iter().zip(&reference) {
                assert!(
                    (a - b).abs() <= 1e-5 * scale.max(1.0),
                    "candle {a} vs frmd-core {b}"
                );
            }
        }
    }
}
