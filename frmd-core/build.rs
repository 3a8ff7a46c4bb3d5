//! Sets `cfg(frmd_arm_dsp)` when the target has the Arm DSP extension (`SMLAD`, `SXTB16`), which
//! selects the int8 matrix-vector kernel of `src/kernels/dsp.rs` instead of the portable one, and
//! `cfg(frmd_no_clz)` on cores without a `CLZ` instruction (the Gaussian sampler's count of
//! leading zeros is then branch-free arithmetic).
//!
//! Why a build script: Arm target features are unstable in Rust, so on a stable toolchain
//! `cfg(target_feature = "dsp")` is false even for `thumbv7em-none-eabihf` (it is only reported
//! with `RUSTC_BOOTSTRAP`/nightly). The DSP extension is part of every Armv7E-M core (Cortex-M4,
//! M7), so the `thumbv7em-*` targets enable it, as do the Armv8-M Mainline and Armv8.1-M targets
//! (optional there, present in the M33 and M55); any other Arm target enables it when the compiler
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
    let target = var("TARGET");
    // Armv7E-M (M4, M7) always has the DSP extension; the Armv8-M Mainline and Armv8.1-M
    // targets are taken to have it too (the M33 of mps2-an505 and the M55 have it; a DSP-less
    // M33 or M23 build sets `-C target-feature=-dsp` or FRMD_PORTABLE_KERNELS=1).
    let dsp_by_target = ["thumbv7em-", "thumbv8m.main-", "thumbv8.1m.main-"]
        .iter()
        .any(|prefix| target.starts_with(prefix));
    let disabled_by_flags = var("CARGO_ENCODED_RUSTFLAGS")
        .split('\x1f')
        .any(|flag| flag.contains("-dsp"));
    let forced_portable = var("FRMD_PORTABLE_KERNELS") == "1";
    if is_arm && (reported || dsp_by_target) && !disabled_by_flags && !forced_portable {
        println!("cargo::rustc-cfg=frmd_arm_dsp");
    }
    // Armv6-M (M0, M0+) and Armv8-M Baseline (M23) have no CLZ instruction.
    if ["thumbv6m-", "thumbv8m.base-"]
        .iter()
        .any(|prefix| target.starts_with(prefix))
    {
        println!("cargo::rustc-cfg=frmd_no_clz");
    }
}
