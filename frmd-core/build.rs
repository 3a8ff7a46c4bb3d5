//! Sets `cfg(frmd_arm_dsp)` when the target has the Arm DSP extension (`SMLAD`, `SXTB16`), which
//! selects the int8 matrix-vector kernel of `src/kernels/dsp.rs` instead of the portable one.
//!
//! Why a build script: Arm target features are unstable in Rust, so on a stable toolchain
//! `cfg(target_feature = "dsp")` is false even for `thumbv7em-none-eabihf` (it is only reported
//! with `RUSTC_BOOTSTRAP`/nightly). The DSP extension is part of every Armv7E-M core (Cortex-M4,
//! M7), so the `thumbv7em-*` targets enable it; any other Arm target enables it when the compiler
//! reports the feature. `FRMD_PORTABLE_KERNELS=1` forces the portable kernels (for A/B
//! measurements), and so does `-C target-feature=-dsp` in the encoded rustflags.

use std::env;

fn main() {
    println!("cargo::rustc-check-cfg=cfg(frmd_arm_dsp)");
    println!("cargo::rustc-check-cfg=cfg(frmd_no_clz)");
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-env-changed=FRMD_PORTABLE_KERNELS");
    let var = |name: &str| env::var(name).unwrap_or_default();
    let is_arm = var("CARGO_CFG_TARGET_ARCH") == "arm";
    let reported = var("CARGO_CFG_TARGET_FEATURE")
        .split(',')
        .any(|feature| feature == "dsp");
    let armv7em = var("TARGET").starts_with("thumbv7em-");
    let disabled_by_flags = var("CARGO_ENCODED_RUSTFLAGS")
        .split('\x1f')
        .any(|flag| flag.contains("-dsp"));
    let forced_portable = var("FRMD_PORTABLE_KERNELS") == "1";
    if is_arm && (reported || armv7em) && !disabled_by_flags && !forced_portable {
        println!("cargo::rustc-cfg=frmd_arm_dsp");
    }
}
