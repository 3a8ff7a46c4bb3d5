//! Firmware: a random transformer-lite student (`frmd_firmware_support::host::transformer_student`)
//! exported by frmd-export with int16 activations and baked as its blob by build.rs; its
//! `policy()` loads and checks the blob (as a user's firmware does) and `Policy::act` runs on
//! the fixed observation histories, so the int8 and int16 images compare one network.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_cortex_m::baked_transformer_student16 as baked;
use frmd_cortex_m::{bench, images};

#[entry]
fn main() -> ! {
    let stack = bench::start();
    let mut storage = baked::Storage::new();
    images::transformer_student_image(
        stack,
        baked::policy(&mut storage),
        images::TRANSFORMER_STUDENT16_NAME,
    )
}
