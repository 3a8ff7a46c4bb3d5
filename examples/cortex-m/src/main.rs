//! Firmware: the baked ProDMP policy decoder on a fixed list of inputs (see the crate docs).
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_cortex_m::{bench, BAKED_PRODMP};
use frmd_firmware_support::prodmp_workload::{ProDmpWorkload, CASES};

#[entry]
fn main() -> ! {
    let stack = bench::start();
    let mut workload = ProDmpWorkload::new(&BAKED_PRODMP);
    bench::run::<_, { CASES * 5 }>(&mut workload, stack)
}
