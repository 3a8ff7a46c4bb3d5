//! The measured workload of the policy firmware: one `Policy::act` call of a baked one-step
//! policy, i.e. observation history in, action chunk (robot units) out: Gaussian noise from the
//! frmd-core PRNG, input assembly, int8 MLP, consistency output stage, ProDMP decode,
//! denormalization.
//!
//! `core` + frmd-core only and generic over the network, so the host test runs the same code on
//! the blob form of the same policy (`frmd_core::blob::LoadedMlp`) and must reproduce the
//! firmware's digest.
//!
//! Case `c`: `Rng::new(OBS_SEED + c)` draws the initial action (`0.6 u - 0.3` per DoF, passed to
//! `reset`) and then `M` observations (`2u - 1` each, passed to `observe` oldest first); the
//! measured call samples with `Noise::Rng(Rng::new(NOISE_SEED + c))`. Digest per case: the chunk's
//! positions, then velocities (`[time][dof]`, little-endian f32).

use crate::workload::Workload;
use frmd_core::hash::Fnv1a64;
use frmd_core::policy::{Network, Noise, Policy, PolicyError, Trajectory};
use frmd_core::rng::Rng;

/// Printed as the `workload:` line unless [`PolicyWorkload::with_name`] says otherwise.
pub const NAME: &str = "policy act: one-step int8 policy + decode";
/// The `workload:` line of the `policy` and `policy-stages` images (the same baked student).
pub const STUDENT_NAME: &str =
    "policy act: trained one-step int8 MLP student (reach, policy/reach) + decode";
/// The `workload:` line of the same student exported with int16 activations.
pub const STUDENT16_NAME: &str =
    "policy act: trained one-step MLP student, int16 activations (reach, policy/reach) + decode";
/// Distinct inputs.
pub const CASES: usize = 8;
pub const OBS_SEED: u64 = 0x4652_4D44_4F42_5301;
pub const NOISE_SEED: u64 = 0x4652_4D44_4E4F_4953;

/// Multiply-accumulates of one one-step `Policy::act` call whose network does `network_macs`:
/// the network, the ProDMP decode, the output stage (`c_skip x + c_out decode`, 2 per value) and
/// the denormalization (2 per value), counted as the per-stage breakdown (the firmware's src/stage_report.rs)
/// counts them.
pub const fn policy_act_macs(network_macs: u64, horizon: usize, dof: usize, params: usize) -> u64 {
    network_macs
        + crate::workload::prodmp_decode_macs(horizon, dof, params)
        + 2 * (2 * horizon * dof) as u64
}

/// A policy, the current case's noise seed and the last chunk.
pub struct PolicyWorkload<
    'a,
    Net,
    const M: usize,
    const O: usize,
    const K: usize,
    const N: usize,
    const P: usize,
    const I: usize,
> {
    policy: Policy<'a, Net, M, O, K, N, P, I>,
    name: &'static str,
    macs: u64,
    noise_seed: u64,
    chunk: Trajectory<N, K>,
}

impl<
        'a,
        Net: Network,
        const M: usize,
        const O: usize,
        const K: usize,
        const N: usize,
        const P: usize,
        const I: usize,
    > PolicyWorkload<'a, Net, M, O, K, N, P, I>
{
    pub fn new(policy: Policy<'a, Net, M, O, K, N, P, I>) -> Self {
        Self::with_name(policy, NAME)
    }

    /// The policy (for the per-stage breakdown, which reads its network's marks).
    pub fn policy(&self) -> &Policy<'a, Net, M, O, K, N, P, I> {
        &self.policy
    }

    /// States the multiply-accumulates of one `act` call (printed as the `macs:` line), e.g. from
    /// [`policy_act_macs`].
    pub fn with_macs(mut self, macs: u64) -> Self {
        self.macs = macs;
        self
    }

    /// As [`Self::new`], printed as `name` (another network behind the same policy).
    pub fn with_name(policy: Policy<'a, Net, M, O, K, N, P, I>, name: &'static str) -> Self {
        Self {
            policy,
            name,
            macs: 0,
            noise_seed: NOISE_SEED,
            chunk: Trajectory {
                positions: [[0.0; K]; N],
                velocities: [[0.0; K]; N],
            },
        }
    }
}

impl<
        Net: Network,
        const M: usize,
        const O: usize,
        const K: usize,
        const N: usize,
        const P: usize,
        const I: usize,
    > Workload for PolicyWorkload<'_, Net, M, O, K, N, P, I>
{
    type Error = PolicyError;

    fn name(&self) -> &'static str {
        self.name
    }

    fn cases(&self) -> usize {
        CASES
    }

    fn prepare(&mut self, case: usize) -> Result<(), PolicyError> {
        let mut rng = Rng::new(OBS_SEED.wrapping_add(case as u64));
        let mut initial_action = [0.0_f32; K];
        for value in initial_action.iter_mut() {
            *value = 0.6 * rng.uniform() - 0.3;
        }
        self.policy.reset(&initial_action)?;
        for _ in 0..M {
            let mut observation = [0.0_f32; O];
            for value in observation.iter_mut() {
                *value = 2.0 * rng.uniform() - 1.0;
            }
            self.policy.observe(&observation)?;
        }
        self.noise_seed = NOISE_SEED.wrapping_add(case as u64);
        Ok(())
    }

    /// One chunk: `act` with fresh noise from the case's seed (repeatable).
    fn run(&mut self) -> Result<(), PolicyError> {
        let mut rng = Rng::new(self.noise_seed);
        self.chunk = *self.policy.act(Noise::Rng(&mut rng))?;
        Ok(())
    }

    fn macs(&self) -> u64 {
        self.macs
    }

    fn digest_outputs(&self, digest: &mut Fnv1a64) {
        for row in self
            .chunk
            .positions
            .iter()
            .chain(self.chunk.velocities.iter())
        {
            digest.f32s(row);
        }
    }
}
