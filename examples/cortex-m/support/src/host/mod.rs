//! Host side of the firmware checks (std): [`qemu`] runs an image under QEMU for a test;
//! [`student`] (feature `export`) exports the checked-in trained student as build.rs does and
//! [`transformer_student`] the random transformer-lite student of the blob images;
//! [`board_memory_map`] picks the QEMU board's memory map for the build scripts.

pub mod qemu;

/// The memory map (`examples/cortex-m/memory/*.x`, relative to `examples/cortex-m`) of the QEMU
/// board `run-qemu.sh` boots a target on: Armv7E-M on mps2-an386 / mps2-an500 (M4F, M7),
/// Armv8-M Mainline on mps2-an505 (M33), Armv6-M on microbit (M0). `FRMD_CM_MEMORY_MAP=an547`
/// (set by `run-qemu.sh m55`) links an Armv8-M Mainline build for mps3-an547 instead: the M55
/// runs the M33's code, since this toolchain has no Armv8.1-M target.
pub fn board_memory_map(target: &str) -> &'static str {
    if std::env::var("FRMD_CM_MEMORY_MAP").as_deref() == Ok("an547") {
        "memory/an547.x"
    } else if target.starts_with("thumbv8m.main-") {
        "memory/an505.x"
    } else if target.starts_with("thumbv6m-") {
        "memory/microbit.x"
    } else {
        "memory/mps2.x"
    }
}
#[cfg(feature = "export")]
pub mod student;
#[cfg(feature = "export")]
pub mod transformer_student;
