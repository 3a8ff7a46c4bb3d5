//! Firmware: frmd-core's fully connected kernels on random shapes (see
//! `frmd_firmware_support::kernel_workload`), so that the host test can compare every path of
//! this core's kernels with the host's, bit for bit.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_cortex_m::bench;
use frmd_firmware_support::kernel_workload::{KernelWorkload, CASES};

#[entry]
fn main() -> ! {
    let stack = bench::start();
    let mut workload = KernelWorkload::new();
    bench::run::<_, CASES>(&mut workload, stack)
}
