//! Firmware: the per-stage breakdown of the transformer image
//! (src/bin/frmd-cortex-m-transformer.rs). It first measures `Policy::act` exactly as that image
//! does (same report lines), then re-runs the same policy with the network's entry and exit marked
//! and times the backbone's parts (src/stage_report.rs). Kept separate so that the breakdown's
//! code does not change the transformer image's inlining or size.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_core::model::transformer::Int8Transformer;
use frmd_core::policy::PolicyError;
use frmd_cortex_m::images::{self, Scratch};
use frmd_cortex_m::report::exit_failure;
use frmd_cortex_m::timer::Calibration;
use frmd_cortex_m::{bench, stage_report};
use frmd_firmware_support::policy_workload::CASES;
use frmd_firmware_support::shape::TRANSFORMER_SHAPE;
use frmd_firmware_support::stages::MarkedNetwork;

#[entry]
fn main() -> ! {
    images::transformer_image(|workload, stack| {
        bench::run_then::<_, { CASES }>(workload, stack, |workload, calibration, digest| {
            let model = *workload.policy().network().model();
            if let Err(error) = breakdown(model, calibration, digest) {
                exit_failure(&error);
            }
        })
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
    let mut policy_scratch = Scratch::new();
    let network = MarkedNetwork::new(
        images::network_of(model, &mut policy_scratch),
        stage_report::systick,
    );
    let mut staged = images::transformer_workload(network);
    let mut scratch = Scratch::new();
    // The token, width and output sizes are not in the arguments' types; the rest is inferred.
    stage_report::transformer_policy::<
        _,
        _,
        _,
        { TRANSFORMER_SHAPE.token_values() },
        { TRANSFORMER_SHAPE.width },
        { TRANSFORMER_SHAPE.output },
        _,
        _,
        _,
        _,
        _,
        _,
    >(&mut staged, &mut scratch, calibration, digest)
}
