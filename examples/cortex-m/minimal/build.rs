//! Bakes the policy into `$OUT_DIR` and puts a memory map on the linker path.
//!
//! In your own firmware: point `CHECKPOINT` at your exported student (or call
//! `frmd_export::bake::write_module` on any `QuantizedPolicy`) and keep your chip's `memory.x`
//! next to Cargo.toml instead of `board_memory_map`.
use std::{
    env, fs,
    path::{Path, PathBuf},
};

/// The student checkpoint (`frmd.json`, `model.safetensors`, `calibration.safetensors`).
const CHECKPOINT: &str = "../policy/reach";

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let exported = frmd_export::export::export_checkpoint(
        Path::new(CHECKPOINT),
        frmd_export::export::ExportOptions::default(),
        None,
    )
    .unwrap_or_else(|error| panic!("exporting {CHECKPOINT} failed: {error:#}"));
    frmd_export::bake::write_module(&exported.policy, &out)
        .unwrap_or_else(|error| panic!("baking {CHECKPOINT} failed: {error:#}"));

    let target = env::var("TARGET").unwrap_or_default();
    let memory_map = frmd_firmware_support::host::board_memory_map(&target);
    fs::copy(Path::new("..").join(memory_map), out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rerun-if-changed={CHECKPOINT}");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=FRMD_CM_MEMORY_MAP");
}
