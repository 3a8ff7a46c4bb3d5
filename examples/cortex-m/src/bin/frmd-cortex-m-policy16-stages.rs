//! Firmware: the per-stage breakdown of the policy16 image (the student with int16 activations,
//! src/bin/frmd-cortex-m-policy16.rs), as frmd-cortex-m-policy-stages is of the policy image.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_cortex_m::baked_student16 as baked;
use frmd_cortex_m::images;
use frmd_firmware_support::policy_workload::STUDENT16_NAME;

#[entry]
fn main() -> ! {
    let network = baked::network::<{ baked::SCRATCH_WIDTH }>;
    images::student_stages(images::student16_workload, network, STUDENT16_NAME)
}
