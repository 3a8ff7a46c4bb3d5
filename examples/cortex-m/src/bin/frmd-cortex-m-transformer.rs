//! Firmware: the synthetic one-step policy configuration baked by frmd-export (normalization,
//! step constants, decoder, input layout) with a synthetic int8 transformer-lite backbone
//! (`frmd_firmware_support::synthetic::transformer`) as its network; `Policy::act` on the fixed observation
//! histories of `frmd_firmware_support::policy_workload`. The per-stage breakdown is a separate image
//! (src/bin/frmd-cortex-m-transformer-stages.rs), so that its code does not change this one's
//! inlining or size.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_core::model::transformer::TransformerScratch;
use frmd_core::policy::Policy;
use frmd_firmware_support::policy_workload::{PolicyWorkload, CASES};
use frmd_cortex_m::report::exit_failure;
use frmd_firmware_support::shape::{
    DOF, HORIZON, PARAMS, POLICY_HISTORY, POLICY_INPUT, POLICY_OBS_DIM, TRANSFORMER_SCRATCH,
};
use frmd_firmware_support::transformer_network::TransformerNetwork;
use frmd_cortex_m::{baked_transformer, bench};

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
    bench::run::<_, { CASES }>(&mut workload, stack)
}
