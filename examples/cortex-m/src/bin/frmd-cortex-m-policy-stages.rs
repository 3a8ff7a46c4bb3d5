//! Firmware: the per-stage breakdown of the policy image (src/bin/frmd-cortex-m-policy.rs). It
//! first measures `Policy::act` of the same baked trained student exactly as that image does (same
//! inputs, seeds and report lines, so the same digest), then runs the student's baked network
//! through frmd-core's staged forward pass and prints `stage` lines (src/stage_report.rs). The
//! breakdown lives in its own image because its second policy instance changes how the compiler
//! inlines the shared code: the totals of the two images differ slightly; the policy image's
//! `instructions:` is the reference, the stage lines show where the time goes.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_cortex_m::baked_student as baked;
use frmd_cortex_m::images;
use frmd_firmware_support::policy_workload::STUDENT_NAME;

#[entry]
fn main() -> ! {
    let network = baked::network::<{ baked::SCRATCH_WIDTH }>;
    images::student_stages(images::student_workload, network, STUDENT_NAME)
}
