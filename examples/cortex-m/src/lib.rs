//! FRMD on a Cortex-M4F / Cortex-M7 (QEMU mps2-an386 / mps2-an500, or a real board with `defmt`):
//! the measurement harness and the baked data of the firmware binaries. The workloads, shapes and
//! staged networks they run live in the `frmd-firmware-support` crate (`support/`), which the
//! build script and the host digest tests use too.
//!
//! - `frmd-cortex-m` (src/main.rs): the baked ProDMP policy decoder on fixed inputs.
//! - `frmd-cortex-m-mlp` (src/bin/frmd-cortex-m-mlp.rs): a synthetic int8 MLP (40-256-256-256-42,
//!   SiLU LUTs) feeding the decoder, i.e. the one-step student's network + decode path.
//! - `frmd-cortex-m-policy` (src/bin/frmd-cortex-m-policy.rs): the checked-in trained student
//!   (`policy/reach/`) exported and baked by frmd-export, measured as `Policy::act` (observations
//!   in, action chunk out).
//! - `frmd-cortex-m-transformer` (src/bin/frmd-cortex-m-transformer.rs): a synthetic one-step
//!   policy configuration with a synthetic int8 transformer-lite backbone instead of the MLP.
//! - `frmd-cortex-m-transformer-student`, `frmd-cortex-m-transformer-student16`: a random
//!   transformer-lite student (the synthetic policy's sizes) exported by frmd-export with int8 /
//!   int16 activations and run from its blob (`LoadedTransformer[16]`), as a user's firmware
//!   runs a transformer student: the two precisions of the same network side by side.
//! - `frmd-cortex-m-pil` (src/bin/frmd-cortex-m-pil.rs): processor in the loop, a baked policy
//!   answering act requests from the host over semihosting (see [`pil`]).
//! - `frmd-cortex-m-kernels` (src/bin/frmd-cortex-m-kernels.rs): frmd-core's fully connected
//!   kernels on random shapes (int8 and int16 activations) for the host's digest comparison, then
//!   (not on the M0) instructions per layer at fixed shapes (src/layer_report.rs).
//! - `frmd-cortex-m-policy-stages`, `frmd-cortex-m-transformer-stages`: the policy (same baked
//!   student) and the transformer measurements followed by a per-stage breakdown
//!   (`stage <name>: <instructions>` lines, see src/stage_report.rs).
//!
//! Each prints `digest: <16 hex>` (FNV-1a 64 over the little-endian bytes of every output, in
//! order), `instructions: <n>` (median per call, from SysTick under QEMU `-icount shift=0`),
//! `flash: <bytes>` and `ram: <bytes>` (static RAM + peak stack), plus supporting lines.
#![no_std]
#![deny(unsafe_op_in_unsafe_fn)]

#[cfg(feature = "defmt")]
use defmt_rtt as _;

pub mod baked_mlp;
pub mod baked_transformer;
pub mod bench;
pub mod images;
#[cfg(not(frmd_armv6m))]
pub mod layer_report;
pub mod memory;
pub mod pil;
pub mod report;
pub mod stage_report;
pub mod timer;

use frmd_core::prodmp::BakedProDmp;

/// The ProDMP decoder tables of `shape::config`, baked on the host by build.rs.
pub static BAKED_PRODMP: frmd_firmware_support::prodmp_workload::Baked =
    include!(concat!(env!("OUT_DIR"), "/baked_prodmp.rs"));

/// The module frmd-export generated from the checked-in student (`policy.rs` + `weights.bin` in
/// `OUT_DIR/student`) and the MACs of its network (`network_macs.rs`): the `policy` images.
#[allow(dead_code)]
pub mod baked_student {
    include!(concat!(env!("OUT_DIR"), "/student/policy.rs"));
    include!(concat!(env!("OUT_DIR"), "/student/network_macs.rs"));
}

/// The same student exported with int16 activations (`OUT_DIR/student16`): the `policy16` image.
#[allow(dead_code)]
pub mod baked_student16 {
    include!(concat!(env!("OUT_DIR"), "/student16/policy.rs"));
    include!(concat!(env!("OUT_DIR"), "/student16/network_macs.rs"));
}

/// The random transformer-lite student exported with int8 activations (blob form,
/// `OUT_DIR/transformer_student8`): the `transformer-student` image.
#[allow(dead_code)]
pub mod baked_transformer_student8 {
    include!(concat!(env!("OUT_DIR"), "/transformer_student8/policy.rs"));
}

/// The same student exported with int16 activations (`OUT_DIR/transformer_student16`): the
/// `transformer-student16` image.
#[allow(dead_code)]
pub mod baked_transformer_student16 {
    include!(concat!(env!("OUT_DIR"), "/transformer_student16/policy.rs"));
}

/// The module frmd-export generated for the synthetic MLP policy
/// (`frmd_firmware_support::synthetic::policy`): the `transformer` images use its `config()`
/// (the MLP weights are not referenced, so the linker drops them).
#[allow(dead_code)]
pub mod baked_synthetic_policy {
    include!(concat!(env!("OUT_DIR"), "/synthetic_policy/policy.rs"));
}
