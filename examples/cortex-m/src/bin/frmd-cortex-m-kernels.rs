//! Firmware: frmd-core's fully connected kernels on random shapes (see
//! `frmd_firmware_support::kernel_workload`), so that the host test can compare every path of
//! this core's kernels with the host's, bit for bit; then, except on the M0 (no RAM to spare),
//! the instructions of fixed int8 and int16 layer shapes (`layer` and `loop_per_mac` lines, see
//! src/layer_report.rs), which do not enter the digest.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_cortex_m::bench;
use frmd_firmware_support::kernel_workload::{KernelWorkload, CASES};

#[entry]
fn main() -> ! {
    let stack = bench::start();
    let mut workload = KernelWorkload::new();
    bench::run_then::<_, CASES>(&mut workload, stack, |_, _calibration, _| {
        #[cfg(not(frmd_armv6m))]
        if let Err(error) = frmd_cortex_m::layer_report::layers(_calibration) {
            frmd_cortex_m::report::exit_failure(&error);
        }
    })
}
