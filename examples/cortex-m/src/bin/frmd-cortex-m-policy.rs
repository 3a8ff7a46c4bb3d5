//! Firmware: the checked-in trained student (`policy/reach/`, one-step MLP-256 for the built-in
//! `reach` task) exported and baked by frmd-export in build.rs, `Policy::act` on a fixed
//! list of observation histories (see the crate docs and `frmd_firmware_support::policy_workload`). The per-stage
//! breakdown is a separate image (src/bin/frmd-cortex-m-policy-stages.rs), so that its code does
//! not change this one's inlining or size.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_firmware_support::policy_workload::{policy_act_macs, PolicyWorkload, CASES, STUDENT_NAME};
use frmd_cortex_m::report::exit_failure;
use frmd_cortex_m::bench;

/// The module frmd-export generated from the student (policy.rs + weights.bin in OUT_DIR/student).
#[allow(dead_code)]
mod baked {
    include!(concat!(env!("OUT_DIR"), "/student/policy.rs"));
    include!(concat!(env!("OUT_DIR"), "/student/network_macs.rs"));
}

#[entry]
fn main() -> ! {
    let stack = bench::start();
    let policy = match baked::policy() {
        Ok(policy) => policy,
        Err(error) => exit_failure(&error),
    };
    let macs = policy_act_macs(baked::NETWORK_MACS, baked::HORIZON, baked::ACTION_DIM, baked::PARAMS_PER_DOF);
    let mut workload = PolicyWorkload::with_name(policy, STUDENT_NAME).with_macs(macs);
    bench::run::<_, { CASES * 5 }>(&mut workload, stack)
}
