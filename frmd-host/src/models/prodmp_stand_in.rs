//! TEMPORARY STAND-IN for `frmd_core::prodmp` (contracts.md) until the prodmp branch is merged.
//! NOT a ProDMP: a smooth linear map with the same signature so the candle side compiles and
//! trains. Delete this file and switch `decoder.rs` to `frmd_core::prodmp` after the merge.
#![allow(dead_code)]

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProDmpConfig {
    pub num_dof: usize,
    pub num_basis: usize,
    pub tau: f64,
    pub delay: f64,
    pub alpha: f64,
    pub alpha_phase: f64,
    pub bandwidth_factor: f64,
    pub num_basis_outside: usize,
    pub dt: f64,
    pub weights_scale: f64,
    pub goal_scale: f64,
    pub relative_goal: bool,
    pub auto_scale_basis: bool,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ProDmpError {
    BadConfig,
    BadLength,
}

pub struct BoundaryCoefficients {
    pub pos_y0: f64,
    pub pos_v0: f64,
    pub vel_y0: f64,
    pub vel_v0: f64,
}

impl ProDmpConfig {
    pub fn policy(num_dof: usize, num_basis: usize, horizon: usize, control_dt: f64) -> Self {
        ProDmpConfig {
            num_dof,
            num_basis,
            tau: horizon as f64 * control_dt,
            delay: 0.0,
            alpha: 25.0,
            alpha_phase: 2.0,
            bandwidth_factor: 3.0,
            num_basis_outside: 0,
            dt: 0.01,
            weights_scale: 1.0,
            goal_scale: 1.0,
            relative_goal: true,
            auto_scale_basis: false,
        }
    }
    pub fn validate(&self) -> Result<(), ProDmpError> {
        if self.num_basis >= 1 && self.tau > 0.0 { Ok(()) } else { Err(ProDmpError::BadConfig) }
    }
    pub fn num_params_per_dof(&self) -> usize {
        self.num_basis + 1
    }
}

pub fn linear_row(
    cfg: &ProDmpConfig,
    _init_time: f64,
    time: f64,
    pos_params: &mut [f64],
    vel_params: &mut [f64],
) -> Result<BoundaryCoefficients, ProDmpError> {
    cfg.validate()?;
    let p = cfg.num_params_per_dof();
    if pos_params.len() != p || vel_params.len() != p {
        return Err(ProDmpError::BadLength);
    }
    let s = (time / cfg.tau).clamp(0.0, 1.0);
    let smooth = s * s * (3.0 - 2.0 * s);
    let b = cfg.num_basis;
    let width = 1.0 / b as f64;
    let mut total = 0.0;
    for j in 0..b {
        let centre = (j as f64 + 0.5) * width;
        let phi = (-(s - centre).powi(2) / (2.0 * width * width)).exp();
        pos_params[j] = phi;
        total += phi;
    }
    for value in pos_params.iter_mut().take(b) {
        *value = *value / total * s * (1.0 - s) * 4.0;
    }
    pos_params[b] = smooth;
    vel_params.iter_mut().for_each(|v| *v = 0.0);
    Ok(BoundaryCoefficients { pos_y0: 1.0 - smooth + smooth, pos_v0: time * (1.0 - s).powi(2), vel_y0: 0.0, vel_v0: 0.0 })
}
