//! Firmware: the checked-in trained student (`policy/reach/`) exported with int16 activations
//! (`frmd export --activations int16`) and baked by frmd-export in build.rs, `Policy::act` on the
//! same fixed observation histories as the `policy` image, so the two are compared side by side.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_cortex_m::{bench, images};
use frmd_firmware_support::policy_workload::CASES;

#[entry]
fn main() -> ! {
    let stack = bench::start();
    let mut workload = images::student16_workload();
    bench::run::<_, { CASES * 5 }>(&mut workload, stack)
}
