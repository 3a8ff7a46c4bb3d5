#!/usr/bin/env bash
# Runs cargo for a Cortex-M target (thumbv7em-none-eabihf unless CARGO_BUILD_TARGET says
# thumbv8m.main-none-eabihf or thumbv6m-none-eabi) with the toolchain chosen by
# scripts/setup-cortex-m.sh:
#
#   bash scripts/cortex-m-cargo.sh build --release -p frmd-core
#   (cd examples/cortex-m && bash ../../scripts/cortex-m-cargo.sh build --release)
#
# Sets CARGO_BUILD_TARGET (unless the caller set it), RUSTC/RUSTDOC of the chosen toolchain, and on
# the Debian path RUSTC_BOOTSTRAP=1, -Z build-std=core (+ compiler-builtins-mem, which provides
# memcpy & co.) and the ld.lld-16 linker. Runs the setup script first if its env file is missing.
# FRMD_CM_FORCE_BUILD_STD=1 compiles core from source on the rustup path too (needs the rust-src
# component; scripts/check-no-std.sh uses this).
set -euo pipefail

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
env_file="${FRMD_CORTEX_M_ENV:-$repo/target/cortex-m.env}"
if [ ! -f "$env_file" ]; then
    bash "$repo/scripts/setup-cortex-m.sh" >&2
fi
# shellcheck disable=SC1090
. "$env_file"

export RUSTC="$FRMD_CM_RUSTC"
export RUSTDOC="$FRMD_CM_RUSTDOC"
export CARGO_BUILD_TARGET="${CARGO_BUILD_TARGET:-$FRMD_CM_TARGET}"
if [ -n "$FRMD_CM_LINKER" ]; then
    # CARGO_TARGET_<TRIPLE>_LINKER for the target being built (thumbv7em, thumbv8m.main, thumbv6m).
    linker_var="CARGO_TARGET_$(echo "$CARGO_BUILD_TARGET" | tr 'a-z.-' 'A-Z__')_LINKER"
    export "$linker_var=$FRMD_CM_LINKER"
fi

z_flags=()
if [ "$FRMD_CM_BUILD_STD" = 1 ] || [ "${FRMD_CM_FORCE_BUILD_STD:-0}" = 1 ]; then
    export RUSTC_BOOTSTRAP=1
    z_flags+=(-Z build-std=core -Z build-std-features=compiler-builtins-mem)
fi

exec "$FRMD_CM_CARGO" "${z_flags[@]}" "$@"
