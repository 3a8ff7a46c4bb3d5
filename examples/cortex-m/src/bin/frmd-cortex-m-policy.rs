//! Firmware: the checked-in trained student (`policy/reach/`, one-step MLP-256 for the built-in
//! `reach` task) exported and baked by frmd-export in build.rs, `Policy::act` on a fixed
//! list of observation histories (see the crate docs and `frmd_firmware_support::policy_workload`).
//! The per-stage breakdown is a separate image (src/bin/frmd-cortex-m-policy-stages.rs), so that
//! its code does not change this one's inlining or size.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_cortex_m::{bench, images};
use frmd_firmware_support::policy_workload::CASES;

#[entry]
fn main() -> ! {
    let stack = bench::start();
    let mut workload = images::student_workload();
    bench::run::<_, { CASES * 5 }>(&mut workload, stack)
}
