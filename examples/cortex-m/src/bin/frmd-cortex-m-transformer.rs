//! Firmware: the synthetic one-step policy configuration baked by frmd-export (normalization,
//! step constants, decoder, input layout) with a synthetic int8 transformer-lite backbone
//! (`frmd_firmware_support::synthetic::transformer`) as its network; `Policy::act` on the fixed
//! observation histories of `frmd_firmware_support::policy_workload`. The per-stage breakdown is a
//! separate image (src/bin/frmd-cortex-m-transformer-stages.rs), so that its code does not change
//! this one's inlining or size.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_cortex_m::bench;
use frmd_cortex_m::images::{self, Scratch, TRANSFORMER_NAME};
use frmd_firmware_support::policy_workload::{PolicyWorkload, CASES};

#[entry]
fn main() -> ! {
    let stack = bench::start();
    let blocks = images::transformer_blocks();
    let mut scratch = Scratch::new();
    let policy = images::transformer_policy(images::transformer_network(&blocks, &mut scratch));
    let mut workload = PolicyWorkload::with_name(policy, TRANSFORMER_NAME);
    bench::run::<_, { CASES }>(&mut workload, stack)
}
