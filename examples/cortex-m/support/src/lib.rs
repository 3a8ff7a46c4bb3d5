//! Support library of the FRMD Cortex-M firmware (`examples/cortex-m`): everything the firmware
//! images share with their build script and with the host tests that check them.
//!
//! - no_std (the firmware links these): [`shape`] (the policy shapes the images bake),
//!   [`workload`] (the [`workload::Workload`] trait and the digest over a workload's cases),
//!   the workloads [`prodmp_workload`], [`mlp_workload`], [`policy_workload`] and
//!   [`kernel_workload`] (the fully connected kernels on random shapes),
//!   and [`stages`] (the layer-marking MLP network and the entry/exit-marking wrapper of the
//!   per-stage breakdown), [`pil`] (the processor-in-the-loop frame format, used by the `pil`
//!   image and the host driver in frmd-host), [`cpuid`] (the core a CPUID value names);
//! - `std` feature (host only): [`synthetic`] (the deterministic synthetic MLP and
//!   transformer-lite, which build.rs bakes and the tests rebuild in memory) and [`host`] (running
//!   the images under QEMU from a test);
//! - `export` feature (host only, with frmd-export): the synthetic one-step policy and the export
//!   of the checked-in trained student, exactly as build.rs exports it.
//!
//! A digest is FNV-1a 64 ([`frmd_core::hash::Fnv1a64`]) over the little-endian bytes of every
//! output, in order: the firmware prints it, the host tests recompute it with the same workload
//! code and require equality.
#![cfg_attr(not(feature = "std"), no_std)]

pub mod cpuid;
pub mod kernel_workload;
pub mod mlp_workload;
pub mod pil;
pub mod policy_workload;
pub mod prodmp_workload;
pub mod shape;
pub mod stages;
pub mod workload;

#[cfg(feature = "std")]
pub mod host;
#[cfg(feature = "std")]
pub mod synthetic;
