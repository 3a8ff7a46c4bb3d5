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
use frmd_cortex_m::images;
use frmd_firmware_support::policy_workload::CASES;

#[entry]
fn main() -> ! {
    images::transformer_image(|workload, stack| bench::run::<_, { CASES }>(workload, stack))
}
