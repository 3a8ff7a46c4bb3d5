//! Host side of the firmware checks (std): [`qemu`] runs an image under QEMU for a test;
//! [`student`] (feature `export`) exports the checked-in trained student as build.rs does.

pub mod qemu;
#[cfg(feature = "export")]
pub mod student;
