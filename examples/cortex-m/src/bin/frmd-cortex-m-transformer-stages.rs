//! Firmware: the per-stage breakdown of the transformer image
//! (src/bin/frmd-cortex-m-transformer.rs). It first measures `Policy::act` exactly as that image
//! does (same report lines), then re-runs the same policy with the network's entry and exit marked
//! and times the backbone's parts (src/stage_report.rs). Kept separate so that the breakdown's
//! code does not change the transformer image's inlining or size.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_core::policy::Policy;
use frmd_firmware_support::policy_workload::{PolicyWorkload, CASES};
use frmd_cortex_m::report::exit_failure;
use frmd_firmware_support::shape::{
    DOF, HORIZON, PARAMS, POLICY_HISTORY, POLICY_INPUT, POLICY_OBS_DIM, TRANSFORMER_SCRATCH,
    TRANSFORMER_SHAPE,
};
use frmd_core::model::transformer::{Int8Transformer, TransformerScratch};
use frmd_core::policy::PolicyError;
use frmd_cortex_m::timer::Calibration;
use frmd_firmware_support::transformer_network::TransformerNetwork;
use frmd_cortex_m::{baked_transformer, bench, stage_report};

/// The module frmd-export generated for the synthetic MLP policy (`frmd_firmware_support::synthetic::policy`); only
/// its `config()` is used here (the
/// MLP weights are not referenced, so the linker drops them).
#[allow(dead_code)]
mod baked {
    include!(concat!(env!("OUT_DIR"), "/synthetic_policy/policy.rs"));
}

/// Printed as the `workload:` line.
const NAME: &str = "policy act: one-step int8 transformer-lite (3 blocks, 2 heads, width 128, 14 tokens) + decode (synthetic weights)";

type Network<'a> = TransformerNetwork<
    'a,
    { TRANSFORMER_SCRATCH.floats },
    { TRANSFORMER_SCRATCH.bytes },
    { TRANSFORMER_SCRATCH.accumulators },
>;

type Scratch = TransformerScratch<
    { TRANSFORMER_SCRATCH.floats },
    { TRANSFORMER_SCRATCH.bytes },
    { TRANSFORMER_SCRATCH.accumulators },
>;

#[entry]
fn main() -> ! {
    let stack = bench::start();
    let Some(blocks) = baked_transformer::blocks() else {
        exit_failure(&"baked transformer: a block lies outside the generated data");
    };
    let Some(model) = baked_transformer::model(&blocks) else {
        exit_failure(&"baked transformer: a layer lies outside the generated data");
    };
    let config = baked::config();
    let mut scratch = Scratch::new();
    let network = match Network::new(model, &config.sampler.layout, &mut scratch) {
        Ok(network) => network,
        Err(error) => exit_failure(&error),
    };
    let policy = match Policy::<_, POLICY_HISTORY, POLICY_OBS_DIM, DOF, HORIZON, PARAMS, POLICY_INPUT>::new(
        config, network,
    ) {
        Ok(policy) => policy,
        Err(error) => exit_failure(&error),
    };
    let mut workload = PolicyWorkload::with_name(policy, NAME);
    bench::run_then::<_, { CASES }>(&mut workload, stack, |workload, calibration, digest| {
        let model = *workload.policy().network().model();
        if let Err(error) = breakdown(model, calibration, digest) {
            exit_failure(&error);
        }
    })
}

/// The per-stage breakdown: the same policy with the network's entry and exit marked. Not
/// inlined, so its frame (a second policy and scratch) is not part of the main measurement's stack.
#[inline(never)]
fn breakdown(
    model: Int8Transformer<'_>,
    calibration: &Calibration,
    digest: u64,
) -> Result<(), PolicyError> {
    let config = baked::config();
    let mut policy_scratch = Scratch::new();
    let mut network = match Network::new(model, &config.sampler.layout, &mut policy_scratch) {
        Ok(network) => network,
        Err(error) => exit_failure(&error),
    };
    network.set_clock(stage_report::systick);
    let policy =
        Policy::<_, POLICY_HISTORY, POLICY_OBS_DIM, DOF, HORIZON, PARAMS, POLICY_INPUT>::new(config, network)?;
    let mut staged = PolicyWorkload::with_name(policy, NAME);
    let mut scratch = Scratch::new();
    stage_report::transformer_policy::<
        _,
        _,
        _,
        { TRANSFORMER_SHAPE.token_values() },
        { TRANSFORMER_SHAPE.width },
        { TRANSFORMER_SHAPE.output },
        POLICY_HISTORY,
        POLICY_OBS_DIM,
        DOF,
        HORIZON,
        PARAMS,
        POLICY_INPUT,
    >(&mut staged, &mut scratch, calibration, digest)
}
