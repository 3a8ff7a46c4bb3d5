//! The per-stage breakdown the policy and transformer firmware print after their main measurement
//! (firmware only): `stage <name>: <instructions>` (mean per chunk) and `stage_macs <name>: <n>`
//! (multiply-accumulates of that stage) lines, in pipeline order, then `stage_calls` and
//! `stage_digest`.
//!
//! How each stage is measured (SysTick under `-icount shift=0`, 40 instructions a tick, averaged
//! over every call so the mean resolves single instructions):
//! - inside `Policy::act`: the network marks its entry and exit (and, for the MLP, the boundary of
//!   every layer, see [`frmd_firmware_support::stages::StagedMlpNetwork`]); `input` is `act`'s start to the
//!   network's entry; `noise` (`Rng::fill_gaussian` of the chunk) is timed on its own and `input`
//!   is the rest (checks, history copy, `sigma z`, sampler validation, input assembly with `c_in`);
//!   the rest of `act` after the network is decode + consistency output stage + denormalization;
//! - `decode` and `denormalize` are then timed on their own (same inputs, same frmd-core calls:
//!   `ProDmpTables::decode` on the last parameters, `RangeNormalizer::denormalize{,_rate}` on the
//!   last normalized chunk), and `output_stage` (`c_skip x + c_out decode`, the finiteness check,
//!   returning the chunk) is the rest of `act` after the network minus those two;
//! - transformer blocks: `Int8Transformer::forward` of the first 1, 2 and 3 blocks (same weights,
//!   fixed input); block `l >= 2` is the difference of consecutive prefixes, `embedding` and
//!   `head` are timed on their own from the same frmd-core calls the forward pass makes, and
//!   block 1 is the 1-block forward pass minus those two.
//!
//! Each clock reading costs a few instructions, which land in the neighbouring stages.

use cortex_m::peripheral::SYST;
use frmd_core::model::transformer::{
    Int8Transformer, TokenLinear, TransformerScratch, TransformerShape,
};
use frmd_core::policy::{Int8TransformerNetwork, Network, Policy, PolicyError};
use frmd_core::rng::Rng;

use crate::report::{self, exit_failure, report};
use crate::timer::{Calibration, TickCounter};
use frmd_core::hash::Fnv1a64;
use frmd_core::model::mlp::MlpPrecision;
use frmd_firmware_support::policy_workload::{PolicyWorkload, CASES, NOISE_SEED};
use frmd_firmware_support::stages::{MarkedNetwork, StagedMlpNetwork};
use frmd_firmware_support::workload::{prodmp_decode_macs, Workload};

mod transformer;
pub use transformer::transformer_policy;

/// Calls per case in the breakdown (and standalone repetitions per call).
pub const REPEATS: usize = 5;
const MAX_STAGES: usize = 16;

/// The SysTick counter (a [`frmd_firmware_support::stages::Clock`]); SysTick must be running.
pub fn systick() -> u32 {
    SYST::get_current()
}

fn elapsed(start: u32, end: u32) -> u64 {
    u64::from(TickCounter::elapsed(start, end))
}

/// SysTick readings around one `run` of a workload, and the first and last mark its network took.
struct TimedRun {
    start: u32,
    entry: u32,
    exit: u32,
    end: u32,
}

impl TimedRun {
    /// Runs `workload` once; `marks` reads the network's marks of that run from it.
    fn of<W: Workload<Error = PolicyError>>(
        workload: &mut W,
        marks: impl Fn(&W) -> &[u32],
    ) -> Result<Self, PolicyError> {
        let start = systick();
        workload.run()?;
        let end = systick();
        let marks = marks(workload);
        let (Some(&entry), Some(&exit)) = (marks.first(), marks.last()) else {
            return Err(PolicyError::OutputWidth);
        };
        Ok(Self {
            start,
            entry,
            exit,
            end,
        })
    }
}

/// The stages of every policy breakdown outside its network: `noise` and `input` before it,
/// `decode`, `output_stage` and `denormalize` after it.
#[derive(Clone, Copy)]
struct PolicyStages {
    noise: usize,
    input: usize,
    decode: usize,
    output_stage: usize,
    denormalize: usize,
}

/// Stage names, MAC counts and summed ticks.
struct Breakdown {
    names: [&'static str; MAX_STAGES],
    macs: [u64; MAX_STAGES],
    ticks: [u64; MAX_STAGES],
    count: usize,
}

impl Breakdown {
    const fn new() -> Self {
        Self {
            names: [""; MAX_STAGES],
            macs: [0; MAX_STAGES],
            ticks: [0; MAX_STAGES],
            count: 0,
        }
    }

    /// Declares the next stage; returns its index.
    fn stage(&mut self, name: &'static str, macs: u64) -> usize {
        let index = self.count;
        if let (Some(n), Some(m)) = (self.names.get_mut(index), self.macs.get_mut(index)) {
            *n = name;
            *m = macs;
            self.count += 1;
        }
        index
    }

    fn add(&mut self, index: usize, ticks: u64) {
        if let Some(total) = self.ticks.get_mut(index) {
            *total += ticks;
        }
    }

    fn sub(&mut self, index: usize, ticks: u64) {
        if let Some(total) = self.ticks.get_mut(index) {
            *total = total.saturating_sub(ticks);
        }
    }

    /// Declares the stages after the network (`decode`, `output_stage`, `denormalize`) for a
    /// horizon `n`, `k` DoFs and `p` parameters per DoF; `noise` and `input` are the first two.
    fn close_policy(
        &mut self,
        noise: usize,
        input: usize,
        (n, k, p): (usize, usize, usize),
    ) -> PolicyStages {
        PolicyStages {
            noise,
            input,
            decode: self.stage("decode", prodmp_decode_macs(n, k, p)),
            output_stage: self.stage("output_stage", (2 * n * k) as u64),
            denormalize: self.stage("denormalize", (2 * n * k) as u64),
        }
    }

    /// Moves the standalone timings out of the stages they were measured in: `noise_ticks` out of
    /// `input`, the decode and denormalize ticks out of `output_stage`.
    fn split_standalone(
        &mut self,
        s: PolicyStages,
        noise_ticks: u64,
        (decode, denormalize): (u64, u64),
    ) {
        self.add(s.noise, noise_ticks);
        self.sub(s.input, noise_ticks);
        self.add(s.decode, decode);
        self.add(s.denormalize, denormalize);
        self.sub(s.output_stage, decode + denormalize);
    }

    fn print(&self, calibration: &Calibration, calls: u64) {
        let stages = self
            .names
            .iter()
            .zip(&self.macs)
            .zip(&self.ticks)
            .take(self.count);
        let mut total = 0;
        for ((name, macs), ticks) in stages {
            let instructions = (calibration.instructions(*ticks) + calls / 2) / calls.max(1);
            total += instructions;
            report!("stage {}: {}", name, instructions);
            report!("stage_macs {}: {}", name, macs);
        }
        report!("stage_sum: {}", total);
        report!("stage_calls: {}", calls);
    }
}

/// Times `decode` and `denormalize` standalone on the policy's last inputs, `REPEATS` times each;
/// returns their summed ticks.
fn time_post_stages<
    Net: Network,
    const M: usize,
    const O: usize,
    const K: usize,
    const N: usize,
    const P: usize,
    const I: usize,
>(
    policy: &Policy<'_, Net, M, O, K, N, P, I>,
) -> Result<(u64, u64), PolicyError> {
    let (y0, v0) = policy
        .previous_action_normalized()
        .ok_or(PolicyError::NoPreviousAction)?;
    let config = policy.config();
    let (mut decode_ticks, mut denormalize_ticks) = (0, 0);
    for _ in 0..REPEATS {
        let mut positions = [[0.0_f32; K]; N];
        let mut velocities = [[0.0_f32; K]; N];
        let start = systick();
        let result = config.sampler.decoder.decode::<N, K, P>(
            core::hint::black_box(policy.last_params()).as_flattened(),
            &y0,
            &v0,
            positions.as_flattened_mut(),
            velocities.as_flattened_mut(),
        );
        let end = systick();
        result.map_err(PolicyError::Decode)?;
        core::hint::black_box((&positions, &velocities));
        decode_ticks += elapsed(start, end);

        let chunk = core::hint::black_box(policy.normalized_chunk());
        let start = systick();
        let rows = chunk
            .positions
            .iter()
            .zip(&chunk.velocities)
            .zip(positions.iter_mut().zip(velocities.iter_mut()));
        for ((pos, vel), (pos_out, vel_out)) in rows {
            config.action_norm.denormalize(pos, pos_out);
            config.action_norm.denormalize_rate(vel, vel_out);
        }
        let end = systick();
        core::hint::black_box((&positions, &velocities));
        denormalize_ticks += elapsed(start, end);
    }
    Ok((decode_ticks, denormalize_ticks))
}

/// Times the Gaussian noise of one chunk (`Rng::fill_gaussian` of `N K` values, as the sampler
/// draws it) standalone, `REPEATS` times with the case's seed; summed ticks.
fn time_noise<const N: usize, const K: usize>(case: usize) -> u64 {
    let mut ticks = 0;
    for _ in 0..REPEATS {
        let mut noise = [[0.0_f32; K]; N];
        let mut rng = Rng::new(NOISE_SEED.wrapping_add(case as u64));
        let start = systick();
        rng.fill_gaussian(noise.as_flattened_mut());
        let end = systick();
        core::hint::black_box(&noise);
        ticks += elapsed(start, end);
    }
    ticks
}

/// Ends the run with a failure if the breakdown's chunks differ from the main measurement's.
fn check_digest(digest: Fnv1a64, expected: u64) {
    report::hex64("stage_digest", digest.finish());
    if digest.finish() != expected {
        exit_failure(&"the per-stage breakdown computed different chunks than the measured policy");
    }
}

#[inline(never)]
/// Breakdown of the MLP policy: `workload` runs a [`StagedMlpNetwork`] whose clock is [`systick`];
/// its chunks must reproduce `expected_digest` (the main measurement's).
pub fn mlp_policy<
    Pr: MlpPrecision,
    const S: usize,
    const W: usize,
    const M: usize,
    const O: usize,
    const K: usize,
    const N: usize,
    const P: usize,
    const I: usize,
>(
    workload: &mut PolicyWorkload<'_, StagedMlpNetwork<'_, Pr, S, W>, M, O, K, N, P, I>,
    layer_macs: &[u64],
    output_macs: u64,
    calibration: &Calibration,
    expected_digest: u64,
) -> Result<(), PolicyError> {
    let mut stages = Breakdown::new();
    let noise = stages.stage("noise", 0);
    let input = stages.stage("input", 0);
    let quantize = stages.stage("quantize", 0);
    const LAYER_NAMES: [&str; 8] = [
        "layer1", "layer2", "layer3", "layer4", "layer5", "layer6", "layer7", "layer8",
    ];
    let first_layer = stages.count;
    for (name, macs) in LAYER_NAMES.iter().zip(layer_macs) {
        stages.stage(name, *macs);
    }
    let output_layer = stages.stage("output_layer", output_macs);
    let dequantize = stages.stage("dequantize", 0);
    let outer = stages.close_policy(noise, input, (N, K, P));
    let mut digest = Fnv1a64::new();
    for case in 0..CASES {
        workload.prepare(case)?;
        for _ in 0..REPEATS {
            let run = TimedRun::of(workload, |w| w.policy().network().marks().ticks())?;
            stages.add(outer.input, elapsed(run.start, run.entry));
            let marks = workload.policy().network().marks().ticks();
            for (index, pair) in marks.windows(2).enumerate() {
                if let [from, to] = pair {
                    stages.add(quantize + index, elapsed(*from, *to));
                }
            }
            stages.add(outer.output_stage, elapsed(run.exit, run.end));
        }
        workload.digest_outputs(&mut digest);
        stages.split_standalone(
            outer,
            time_noise::<N, K>(case),
            time_post_stages(workload.policy())?,
        );
    }
    debug_assert!(first_layer == quantize + 1 && output_layer + 1 == dequantize);
    check_digest(digest, expected_digest);
    stages.print(calibration, (CASES * REPEATS) as u64);
    Ok(())
}
