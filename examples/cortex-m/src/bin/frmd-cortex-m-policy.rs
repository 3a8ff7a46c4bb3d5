//! Firmware: a synthetic one-step policy baked by frmd-export (build.rs), `Policy::act` on a fixed
//! list of observation histories (see the crate docs and src/policy_workload.rs). The per-stage
//! breakdown is a separate image (src/bin/frmd-cortex-m-policy-stages.rs), so that its code does
//! not change this one's inlining or size.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_cortex_m::policy_workload::{PolicyWorkload, CASES};
use frmd_cortex_m::report::exit_failure;
use frmd_cortex_m::bench;

/// The module frmd-export generated (policy.rs + weights.bin in OUT_DIR/policy).
#[allow(dead_code)]
mod baked {
    include!(concat!(env!("OUT_DIR"), "/policy/policy.rs"));
}

#[entry]
fn main() -> ! {
    let stack = bench::start();
    let policy = match baked::policy() {
        Ok(policy) => policy,
        Err(error) => exit_failure(&error),
    };
    let mut workload = PolicyWorkload::new(policy);
    bench::run::<_, { CASES * 5 }>(&mut workload, stack)
}
