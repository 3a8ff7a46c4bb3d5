//! Firmware: processor in the loop. A baked one-step MLP policy (the checked-in student, or the
//! module of `frmd export --out DIR` built with `FRMD_PIL_BAKED=DIR`) answers the host's HELLO,
//! RESET, ACT and EXIT frames over semihosting (`frmd_firmware_support::pil` defines them,
//! src/pil.rs serves them), each chunk with the instructions it took. The host side is
//! `frmd_host::firmware` (`frmd eval --firmware m4`).
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_cortex_m::pil::Server;
use frmd_cortex_m::report::exit_failure;
use frmd_firmware_support::pil::{act_len, chunk_len, HEADER_LEN, RESET_LEN, TRAILER_LEN};

/// The module frmd-export generated (`OUT_DIR/pil`, see build.rs).
#[allow(dead_code)]
mod baked {
    include!(concat!(env!("OUT_DIR"), "/pil/policy.rs"));
}

/// Request payload capacity: the larger of ACT and RESET.
const REQUEST: usize = max(
    act_len(baked::HISTORY, baked::OBS_DIM, baked::ACTION_DIM),
    RESET_LEN,
);
/// Reply frame capacity: the larger of CHUNK and the INFO / ERROR payloads, framed.
const REPLY: usize =
    max(chunk_len(baked::HORIZON, baked::ACTION_DIM), 128) + HEADER_LEN + TRAILER_LEN;

const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

#[entry]
fn main() -> ! {
    let policy = match baked::policy(&mut baked::Storage::new()) {
        Ok(policy) => policy,
        Err(error) => exit_failure(&error),
    };
    // The policy's sizes come from its type; the frame capacities are this image's.
    Server::<_, _, _, _, _, _, _, REQUEST, REPLY>::new(policy).run()
}
