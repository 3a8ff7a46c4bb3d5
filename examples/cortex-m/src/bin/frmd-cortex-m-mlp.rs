//! Firmware: synthetic int8 MLP + baked ProDMP decoder on a fixed list of observations (see the
//! crate docs and `frmd_firmware_support::mlp_workload`).
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_cortex_m::report::exit_failure;
use frmd_cortex_m::{baked_mlp, bench, BAKED_PRODMP};
use frmd_firmware_support::mlp_workload::{MlpWorkload, CASES};

#[entry]
fn main() -> ! {
    let stack = bench::start();
    let Some(hidden) = baked_mlp::hidden_layers() else {
        exit_failure(&"baked MLP: hidden layer weights outside the weight blob");
    };
    let Some(mlp) = baked_mlp::mlp(&hidden) else {
        exit_failure(&"baked MLP: output layer does not match the policy shape");
    };
    let mut workload = MlpWorkload::new(mlp, &BAKED_PRODMP);
    bench::run::<_, { CASES * 5 }>(&mut workload, stack)
}
