//! The measured workload: the baked ProDMP policy decoder on a fixed list of inputs.
//!
//! Uses only `core` and frmd-core, so the host-side check (`frmd-core/tests/cortex_m_qemu.rs`) runs
//! the same code and must reproduce the firmware's digest bit for bit.
//!
//! Inputs: case `c` (0-based) draws from `frmd_core::rng::Rng::new(INPUT_SEED + c)`, in order,
//! `uniform()` values mapped by `2u - 1` to the DoF-major parameters `[w_0 .. w_19, g]` (DoF 0
//! first), then `y0` (`u - 0.5`, metres) and `v0` (`0.5 u - 0.25`, m/s) per DoF. Digest: FNV-1a 64
//! over the little-endian bytes of `pos` then `vel` (`[time][dof]`, row-major) of every case in
//! order, each case decoded once for the digest (repeats give identical outputs).

use crate::shape::{DOF, HORIZON, PARAMS};
use crate::workload::Workload;
use frmd_core::hash::Fnv1a64;
use frmd_core::prodmp::{BakedProDmp, ProDmpError};
use frmd_core::rng::Rng;

pub const NAME: &str = "prodmp-decode dof=2 horizon=12 basis=20";
/// Distinct inputs.
pub const CASES: usize = 16;
/// Seed of case 0; case `c` uses `INPUT_SEED + c`.
pub const INPUT_SEED: u64 = 0x4652_4D44_0000_0000;

/// The baked decoder of [`crate::shape::config`].
pub type Baked = BakedProDmp<HORIZON, PARAMS>;

/// One decoder input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inputs {
    pub params: [[f32; PARAMS]; DOF],
    pub y0: [f32; DOF],
    pub v0: [f32; DOF],
}

impl Inputs {
    /// Input number `case` of the fixed list (see the module docs).
    pub fn fixed(case: usize) -> Self {
        let mut rng = Rng::new(INPUT_SEED.wrapping_add(case as u64));
        let mut inputs = Self {
            params: [[0.0; PARAMS]; DOF],
            y0: [0.0; DOF],
            v0: [0.0; DOF],
        };
        for value in inputs.params.iter_mut().flatten() {
            *value = 2.0 * rng.uniform() - 1.0;
        }
        for (y0, v0) in inputs.y0.iter_mut().zip(inputs.v0.iter_mut()) {
            *y0 = rng.uniform() - 0.5;
            *v0 = 0.5 * rng.uniform() - 0.25;
        }
        inputs
    }
}

/// Decoder, current input and outputs.
pub struct ProDmpWorkload<'a> {
    baked: &'a Baked,
    inputs: Inputs,
    pos: [[f32; DOF]; HORIZON],
    vel: [[f32; DOF]; HORIZON],
}

impl<'a> ProDmpWorkload<'a> {
    pub fn new(baked: &'a Baked) -> Self {
        Self {
            baked,
            inputs: Inputs::fixed(0),
            pos: [[0.0; DOF]; HORIZON],
            vel: [[0.0; DOF]; HORIZON],
        }
    }
}

impl Workload for ProDmpWorkload<'_> {
    type Error = ProDmpError;

    fn name(&self) -> &'static str {
        NAME
    }

    fn cases(&self) -> usize {
        CASES
    }

    fn prepare(&mut self, case: usize) -> Result<(), Self::Error> {
        self.inputs = Inputs::fixed(case);
        Ok(())
    }

    /// One chunk decode.
    fn run(&mut self) -> Result<(), ProDmpError> {
        let inputs = core::hint::black_box(&self.inputs);
        self.baked.decode(
            &inputs.params,
            &inputs.y0,
            &inputs.v0,
            &mut self.pos,
            &mut self.vel,
        )
    }

    /// `pos`, then `vel`.
    fn digest_outputs(&self, digest: &mut Fnv1a64) {
        digest_trajectory(&self.pos, &self.vel, digest);
    }

    fn macs(&self) -> u64 {
        crate::workload::prodmp_decode_macs(HORIZON, DOF, PARAMS)
    }
}

/// Feeds `pos` then `vel` (`[time][dof]`, row-major) to `digest`.
pub fn digest_trajectory(
    pos: &[[f32; DOF]; HORIZON],
    vel: &[[f32; DOF]; HORIZON],
    digest: &mut Fnv1a64,
) {
    for row in pos.iter().chain(vel.iter()) {
        digest.f32s(row);
    }
}
