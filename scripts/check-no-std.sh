#!/usr/bin/env bash
# Proves that frmd-core uses neither `alloc` nor `std` on thumbv7em-none-eabihf:
#
#   1. frmd-core is compiled with `-Z build-std=core` (RUSTC_BOOTSTRAP=1): the only standard
#      crates that exist are `core` and `compiler_builtins`, so any `extern crate alloc` / `std`
#      anywhere in frmd-core or its dependencies fails to compile. A negative control (a tiny
#      crate that does `extern crate alloc;`, then one with `extern crate std;`) must FAIL under
#      the same command, which shows the method can catch a violation.
#   2. `cargo tree -e normal --target thumbv7em-none-eabihf`: frmd-core's direct dependencies are
#      only libm, micromath, heapless, bytemuck, postcard, defmt (default features, and every
#      firmware feature: `defmt`, `reference`; `alloc` is the host-only feature and is left out).
#   3. frmd-core builds normally with --release for thumbv7em-none-eabihf, thumbv8m.main-none-eabihf
#      and thumbv6m-none-eabi, and with the `defmt` feature for thumbv7em-none-eabihf.
#
# Uses the rustup toolchain with the rust-src component if `rustup component add rust-src` works,
# otherwise Debian's rustc-web + rust-web-src (installed by scripts/setup-cortex-m.sh --path debian).
# Exits non-zero with a message naming the problem on any failure.
set -euo pipefail

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
target=thumbv7em-none-eabihf
# docs/design.md s.1: frmd-core's dependencies come only from these crates. `serde` (default features
# off) is accepted as postcard's companion: the postcard blob descriptor derives Serialize and
# Deserialize, which needs serde itself as a direct dependency (postcard depends on it anyway).
allowed="libm micromath heapless bytemuck postcard serde defmt"
build_root="${CARGO_TARGET_DIR:-$repo/target}"
proof_dir="$build_root/no-std-proof"

fail() { echo "check-no-std: FAIL: $*" >&2; exit 1; }
say() { echo "check-no-std: $*"; }

# --- Toolchain: the normal one from setup, and one with rust-src for the build-std proof.
env_file="${FRMD_CORTEX_M_ENV:-$repo/target/cortex-m.env}"
[ -f "$env_file" ] || bash scripts/setup-cortex-m.sh >&2
proof_env="$env_file"
# shellcheck disable=SC1090
. "$env_file"
if [ "$FRMD_CM_PATH" = rustup ]; then
    if timeout 180 rustup component add rust-src >&2; then
        say "build-std proof uses the rustup toolchain + rust-src ($("$FRMD_CM_RUSTC" --version))"
    else
        say "rustup component add rust-src failed; using Debian's rustc-web + rust-web-src instead"
        proof_env="$build_root/cortex-m-debian.env"
        FRMD_CORTEX_M_ENV="$proof_env" bash scripts/setup-cortex-m.sh --path debian >&2 \
            || fail "no toolchain with rust-src: rustup component add rust-src failed and the Debian fallback could not be set up"
    fi
else
    say "build-std proof uses Debian's toolchain + rust-web-src ($("$FRMD_CM_RUSTC" --version))"
fi

# The proof compiles against a sysroot that holds only the standard library *sources* (a link to
# the toolchain's rust-src) and no prebuilt target libraries, so `core` and `compiler_builtins`
# built by -Z build-std are the only standard crates rustc can find. (With the real rustup sysroot,
# `extern crate alloc` would load the prebuilt alloc and fail only with a duplicate-lang-item error.)
# shellcheck disable=SC1090
real_sysroot="$(. "$proof_env"; "$FRMD_CM_RUSTC" --print sysroot)"
[ -d "$real_sysroot/lib/rustlib/src/rust/library/core" ] \
    || fail "no standard library sources under $real_sysroot/lib/rustlib/src (rust-src / rust-web-src)"
proof_sysroot="$proof_dir/sources-only-sysroot"
mkdir -p "$proof_sysroot/lib/rustlib"
ln -sfn "$real_sysroot/lib/rustlib/src" "$proof_sysroot/lib/rustlib/src"

proof_cargo() { # cargo args...: build with only `core` available
    env -u CARGO_ENCODED_RUSTFLAGS RUSTFLAGS="--sysroot=$proof_sysroot" \
        FRMD_CORTEX_M_ENV="$proof_env" FRMD_CM_FORCE_BUILD_STD=1 CARGO_TARGET_DIR="$proof_dir" \
        bash "$repo/scripts/cortex-m-cargo.sh" "$@"
}

# --- 1a. Negative control: the same command must reject `extern crate alloc` and `std`.
control="$build_root/no-std-control"
mkdir -p "$control/src"
cat >"$control/Cargo.toml" <<'EOF'
[package]
name = "no-std-control"
version = "0.0.0"
edition = "2021"
publish = false

[workspace]

[features]
use-alloc = []
use-std = []
EOF
cat >"$control/src/lib.rs" <<'EOF'
//! Negative control for scripts/check-no-std.sh: must not compile with only `core` available.
#![no_std]
#[cfg(feature = "use-alloc")]
extern crate alloc;
#[cfg(feature = "use-std")]
extern crate std;
pub fn answer() -> u32 { 42 }
EOF
for crate_name in alloc std; do
    log="$control/build-$crate_name.log"
    if (cd "$control" && proof_cargo build --release --features "use-$crate_name") >"$log" 2>&1; then
        fail "negative control: a crate with 'extern crate $crate_name' compiled under -Z build-std=core, so the proof would prove nothing (log: $log)"
    fi
    grep -q "can't find crate for \`$crate_name\`" "$log" \
        || fail "negative control for '$crate_name' failed for an unexpected reason (log: $log):
$(tail -n 20 "$log")"
    say "negative control: 'extern crate $crate_name' is rejected under -Z build-std=core"
done

# Every feature a firmware may enable (`alloc` is for std hosts and their tests only).
firmware_features="--features defmt,reference"

# --- 1b. frmd-core with only `core`: default features and every firmware feature.
for features in "" "$firmware_features"; do
    log="$proof_dir/frmd-core-build-std${features:+-firmware-features}.log"
    mkdir -p "$proof_dir"
    if ! proof_cargo build --release -p frmd-core $features >"$log" 2>&1; then
        tail -n 30 "$log" >&2
        fail "frmd-core${features:+ ($features)} does not build for $target with only 'core' (-Z build-std=core): it or a dependency needs alloc/std (log: $log)"
    fi
    say "frmd-core${features:+ ($features)} builds for $target with only core + compiler_builtins"
done

# --- 2. Direct dependencies of frmd-core on the target are from the allowed list.
for features in "" "$firmware_features"; do
    deps="$("$FRMD_CM_CARGO" tree -p frmd-core -e normal --target "$target" $features \
        --depth 1 --prefix none --format '{p}' 2>&1)" || fail "cargo tree failed: $deps"
    bad=""
    while read -r name _; do
        [ -z "$name" ] || [ "$name" = frmd-core ] && continue
        case " $allowed " in *" $name "*) ;; *) bad="$bad $name" ;; esac
    done <<<"$deps"
    [ -z "$bad" ] || fail "frmd-core${features:+ ($features)} depends on crates outside the allowed list ($allowed):$bad"
    say "frmd-core${features:+ ($features)} direct dependencies: $(echo "$deps" | awk '$1 != "frmd-core" {printf "%s ", $1}')(allowed: $allowed)"

    # No crate compiled for the target (proc macros run on the host and are excluded) may have
    # an `std` or `alloc` feature enabled.
    enabled="$("$FRMD_CM_CARGO" tree -p frmd-core -e normal,no-proc-macro --target "$target" $features \
        --prefix none --format '{p}|{f}' 2>&1)" || fail "cargo tree failed: $enabled"
    offenders="$(echo "$enabled" | awk -F'|' '{ n = split($2, f, ","); for (i = 1; i <= n; i++)
        if (f[i] == "std" || f[i] == "alloc") { split($1, p, " "); print p[1] " (feature " f[i] ")" } }' | sort -u)"
    [ -z "$offenders" ] || fail "dependencies of frmd-core${features:+ ($features)} enable std/alloc features: $offenders"
    say "frmd-core${features:+ ($features)}: no target crate enables an std or alloc feature ($(echo "$enabled" | sort -u | wc -l) crates checked)"
done

# --- 3. Normal release build for every Cortex-M target of the firmware (Armv7E-M: M4F/M7,
# Armv8-M Mainline: M33/M55, Armv6-M: M0) with the toolchain chosen by setup.
for build_target in "$target" thumbv8m.main-none-eabihf thumbv6m-none-eabi; do
    log="$build_root/frmd-core-$build_target-release.log"
    if ! CARGO_BUILD_TARGET="$build_target" bash scripts/cortex-m-cargo.sh build --release -p frmd-core >"$log" 2>&1; then
        tail -n 30 "$log" >&2
        fail "frmd-core does not build for $build_target --release (log: $log)"
    fi
    say "frmd-core builds for $build_target --release ($FRMD_CM_PATH toolchain)"
done
log="$build_root/frmd-core-$target-defmt-release.log"
if ! bash scripts/cortex-m-cargo.sh build --release -p frmd-core --features defmt >"$log" 2>&1; then
    tail -n 30 "$log" >&2
    fail "frmd-core with the defmt feature does not build for $target --release (log: $log)"
fi
say "frmd-core with the defmt feature builds for $target --release"
say "OK: frmd-core links neither alloc nor std"
