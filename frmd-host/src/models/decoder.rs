//! The ProDMP decoder inside the candle graph: a fixed linear map of (theta, y0, v0) whose
//! coefficients come from `frmd_core::prodmp::linear_row` (the one ProDMP implementation), at
//! query times dt, 2 dt, .., n dt with initial time 0 (DESIGN.md section 2, policy case).
use super::prodmp_stand_in as prodmp;
use anyhow::{anyhow, Context};
use candle_core::{Device, Tensor};
use prodmp::ProDmpConfig;

/// The decoder's coefficient tables in f64, as produced by frmd-core.
#[derive(Clone, Debug)]
pub struct DecoderRows {
    pub horizon: usize,
    pub num_params: usize,
    /// [horizon, num_params], row t = coefficients of theta for position at time (t+1) dt.
    pub pos_params: Vec<f64>,
    /// [horizon] coefficients of y0 and v0 (v0 in units per second).
    pub pos_y0: Vec<f64>,
    pub pos_v0: Vec<f64>,
}

impl DecoderRows {
    pub fn new(cfg: &ProDmpConfig, horizon: usize, control_dt: f64) -> anyhow::Result<Self> {
        cfg.validate().map_err(|e| anyhow!("invalid ProDMP config: {e:?}"))?;
        let num_params = cfg.num_params_per_dof();
        let mut pos_params = vec![0.0; horizon * num_params];
        let mut vel_params = vec![0.0; num_params];
        let mut pos_y0 = Vec::with_capacity(horizon);
        let mut pos_v0 = Vec::with_capacity(horizon);
        for (t, row) in pos_params.chunks_exact_mut(num_params).enumerate() {
            let time = (t + 1) as f64 * control_dt;
            let coeffs = prodmp::linear_row(cfg, 0.0, time, row, &mut vel_params)
                .map_err(|e| anyhow!("ProDMP row at t = {time}: {e:?}"))?;
            pos_y0.push(coeffs.pos_y0);
            pos_v0.push(coeffs.pos_v0);
        }
        Ok(DecoderRows { horizon, num_params, pos_params, pos_y0, pos_v0 })
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
    pub fn new(cfg: &ProDmpConfig, horizon: usize, control_dt: f64, device: &Device) -> anyhow::Result<Self> {
        let rows = DecoderRows::new(cfg, horizon, control_dt)?;
        let pos: Vec<f32> = rows.pos_params.iter().map(|&v| v as f32).collect();
        let params_to_pos = Tensor::from_vec(pos, (horizon, rows.num_params), device)?.t()?.contiguous()?;
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

    /// `theta` [B, k (b+1)] (DoF-major: params[d] = [w_0 .. w_{b-1}, g]), `y0` [B, k],
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
        let y0 = y0.reshape((batch, 1, k))?.broadcast_mul(&self.y0_to_pos)?;
        let v0 = v0.reshape((batch, 1, k))?.broadcast_mul(&self.v0_to_pos)?;
        Ok((from_params + y0 + v0)?.reshape((batch, n * k))?)
    }
}
