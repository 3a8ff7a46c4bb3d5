//! The measured workload of the policy firmware: an int8 MLP maps an observation vector to ProDMP
//! parameters (dequantized f32), which the baked decoder turns into a 12-step trajectory. This is
//! the one-step student's path without the sampler's noise and normalization.
//!
//! `core` + frmd-core only; the host test runs it on the same synthetic network (rebuilt in memory
//! by `synthetic::mlp`) and must reproduce the firmware's digest.
//!
//! Inputs: case `c` draws from `Rng::new(OBS_SEED + c)` the observation (`MLP_INPUT` values
//! `2u - 1`) and then the decoder's `y0` (`u - 0.5`) and `v0` (`0.5 u - 0.25`) per DoF. Digest per
//! case: the MLP outputs (ProDMP parameters, DoF-major), then `pos` and `vel` as in
//! [`crate::prodmp_workload`].

use crate::prodmp_workload::{digest_trajectory, Baked};
use crate::shape::{DOF, HORIZON, MLP_INPUT, MLP_WIDTH, PARAMS};
use crate::workload::Workload;
use frmd_core::hash::Fnv1a64;
use frmd_core::model::mlp::{Int8Mlp, Int8Scratch, ModelError};
use frmd_core::prodmp::ProDmpError;
use frmd_core::rng::Rng;

pub const NAME: &str = "int8-mlp 40-256-256-256-42 + prodmp-decode (synthetic weights)";
/// Distinct inputs.
pub const CASES: usize = 8;
/// Seed of case 0; case `c` uses `OBS_SEED + c`.
pub const OBS_SEED: u64 = 0x4652_4D44_4F42_5300;

/// Why a policy call failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PolicyCallError {
    Network(ModelError),
    Decode(ProDmpError),
}

impl core::fmt::Display for PolicyCallError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Network(error) => write!(f, "int8 MLP: {error}"),
            Self::Decode(error) => write!(f, "ProDMP decode: {error}"),
        }
    }
}

/// Network, decoder, scratch, current input and outputs.
pub struct MlpWorkload<'a> {
    mlp: Int8Mlp<'a>,
    baked: &'a Baked,
    scratch: Int8Scratch<MLP_WIDTH>,
    obs: [f32; MLP_INPUT],
    y0: [f32; DOF],
    v0: [f32; DOF],
    params: [[f32; PARAMS]; DOF],
    pos: [[f32; DOF]; HORIZON],
    vel: [[f32; DOF]; HORIZON],
}

impl<'a> MlpWorkload<'a> {
    pub fn new(mlp: Int8Mlp<'a>, baked: &'a Baked) -> Self {
        Self {
            mlp,
            baked,
            scratch: Int8Scratch::new(),
            obs: [0.0; MLP_INPUT],
            y0: [0.0; DOF],
            v0: [0.0; DOF],
            params: [[0.0; PARAMS]; DOF],
            pos: [[0.0; DOF]; HORIZON],
            vel: [[0.0; DOF]; HORIZON],
        }
    }
}

impl Workload for MlpWorkload<'_> {
    type Error = PolicyCallError;

    fn name(&self) -> &'static str {
        NAME
    }

    fn cases(&self) -> usize {
        CASES
    }

    fn prepare(&mut self, case: usize) -> Result<(), Self::Error> {
        let mut rng = Rng::new(OBS_SEED.wrapping_add(case as u64));
        for value in self.obs.iter_mut() {
            *value = 2.0 * rng.uniform() - 1.0;
        }
        for (y0, v0) in self.y0.iter_mut().zip(self.v0.iter_mut()) {
            *y0 = rng.uniform() - 0.5;
            *v0 = 0.5 * rng.uniform() - 0.25;
        }
        Ok(())
    }

    /// Network forward pass, then decode.
    fn run(&mut self) -> Result<(), PolicyCallError> {
        let obs = core::hint::black_box(&self.obs);
        self.mlp
            .forward(obs, self.params.as_flattened_mut(), &mut self.scratch)
            .map_err(PolicyCallError::Network)?;
        self.baked
            .decode(
                &self.params,
                &self.y0,
                &self.v0,
                &mut self.pos,
                &mut self.vel,
            )
            .map_err(PolicyCallError::Decode)
    }

    /// MLP outputs, then `pos` and `vel`.
    fn digest_outputs(&self, digest: &mut Fnv1a64) {
        digest.f32s(self.params.as_flattened());
        digest_trajectory(&self.pos, &self.vel, digest);
    }

    /// The network's layers (`in_features * out_features` each), then the decode.
    fn macs(&self) -> u64 {
        let layers = self
            .mlp
            .hidden
            .iter()
            .map(|layer| &layer.fc)
            .chain([&self.mlp.output.fc]);
        let network: usize = layers.map(|fc| fc.in_features * fc.out_features).sum();
        network as u64 + crate::workload::prodmp_decode_macs(HORIZON, DOF, PARAMS)
    }
}
