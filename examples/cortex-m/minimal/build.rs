//! Exports and bakes the policy into `$OUT_DIR` and puts a memory map on the linker path.
//!
//! In your own firmware: point `CHECKPOINT` at your student (any backbone: the generated module
//! offers the same `Storage`, `policy()` and sizes for each) and keep your chip's `memory.x` next
//! to Cargo.toml instead of `board_memory_map`.
use std::{
    env, fs,
    path::{Path, PathBuf},
};

/// The student checkpoint (`frmd.json`, `model.safetensors`, `calibration.safetensors`);
/// `FRMD_MINIMAL_CHECKPOINT=DIR` bakes another one (the host test of a transformer-lite student)
/// and `FRMD_MINIMAL_ACTIVATIONS=int8|int16` picks the activation precision (default: the
/// backbone's recipe).
const CHECKPOINT: &str = "../policy/reach";

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let checkpoint = env::var_os("FRMD_MINIMAL_CHECKPOINT")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(CHECKPOINT));
    let activations = env::var("FRMD_MINIMAL_ACTIVATIONS").ok().map(|text| {
        text.parse()
            .unwrap_or_else(|error| panic!("FRMD_MINIMAL_ACTIVATIONS: {error:#}"))
    });
    let options = frmd_export::ExportOptions {
        activations,
        ..Default::default()
    };
    frmd_export::export(&checkpoint, &options, None)
        .and_then(|student| student.write_module(&out))
        .unwrap_or_else(|error| panic!("exporting {} failed: {error:#}", checkpoint.display()));

    let target = env::var("TARGET").unwrap_or_default();
    let memory_map = frmd_firmware_support::host::board_memory_map(&target);
    fs::copy(Path::new("..").join(memory_map), out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rerun-if-changed={}", checkpoint.display());
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=FRMD_CM_MEMORY_MAP");
    println!("cargo:rerun-if-env-changed=FRMD_MINIMAL_CHECKPOINT");
    println!("cargo:rerun-if-env-changed=FRMD_MINIMAL_ACTIVATIONS");
}
