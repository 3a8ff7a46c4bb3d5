#!/usr/bin/env bash
# aarch64 (Linux ARM controllers: Raspberry Pi 5, Jetson CPUs): cross-builds
# examples/host-digests for aarch64-unknown-linux-gnu, runs it under qemu-aarch64 (user mode)
# and requires every digest to equal this host's (x86-64, every kernel level of this CPU checked
# to agree first). aarch64 runs frmd-core's NEON row kernels (kernels::aarch64): once on qemu's
# `max` CPU, which has the dot-product extension (SDOT path, checked against the NEON-only and
# portable paths inside the program), once on a Cortex-A53 (no SDOT: detection must say so).
#   scripts/aarch64.sh [--install] [--test] [--count]
# --install  installs what is missing first (as CI does): Debian's qemu-user, the aarch64 cross
#            gcc (the linker) and libc; the Rust standard library for the target from
#            `rustup target add`, or else Debian's Rust (rustc-web >= 1.95) with its arm64
#            standard library (libstd-rust-web-dev:arm64);
# --test     also runs frmd-core's tests/row_kernels.rs under qemu-aarch64 (the row kernels
#            against the wide sums on random shapes at every level; a plain program, since
#            libtest's threads hang under Debian 12's qemu-aarch64 7.2);
# --count    also prints the aarch64 instructions of one run of the firmware-size MLP workload
#            (int8 MLP 256-256-256 and its decode, as the Cortex-M `mlp` image) for each kernel
#            level, counted with qemu's one-instruction translation blocks:
#            (trace(3 runs) - trace(1 run)) / 2.
set -euo pipefail
cd "$(dirname "$0")/.."
install=0
count=0
unit=0
for arg in "$@"; do
    case "$arg" in
        --install) install=1 ;;
        --test) unit=1 ;;
        --count) count=1 ;;
        *) echo "usage: $0 [--install] [--test] [--count]" >&2; exit 2 ;;
    esac
done
target=aarch64-unknown-linux-gnu
apt_install() {
    local missing=() pkg
    for pkg in "$@"; do
        dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q 'install ok installed' || missing+=("$pkg")
    done
    [ ${#missing[@]} -eq 0 ] && return 0
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
}
rustup_has_target() {
    command -v rustup >/dev/null && rustup target list --installed 2>/dev/null | grep -qx "$target"
}
if [ "$install" = 1 ]; then
    apt_install qemu-user gcc-aarch64-linux-gnu libc6-dev-arm64-cross
    if ! rustup_has_target && ! { command -v rustup >/dev/null && rustup target add "$target"; }; then
        dpkg --print-foreign-architectures | grep -qx arm64 || dpkg --add-architecture arm64
        apt-get update -qq
        apt_install rustc-web cargo-web libstd-rust-web-dev:arm64
    fi
fi
# The toolchain for the target: rustup's if it has the target's standard library, else Debian's.
if rustup_has_target; then
    cross_cargo=(cargo)
else
    cross_cargo=(env RUSTC=/usr/bin/rustc /usr/bin/cargo)
fi
for tool in aarch64-linux-gnu-gcc qemu-aarch64 "${cross_cargo[-1]}"; do
    command -v "$tool" >/dev/null || { echo "aarch64: $tool missing (run with --install)" >&2; exit 1; }
done
manifest=examples/host-digests/Cargo.toml
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
CARGO_TARGET_DIR=target/host-digests cargo build -q --release --manifest-path "$manifest"
CARGO_TARGET_DIR=target/aarch64 "${cross_cargo[@]}" build -q --release --target "$target" \
    --manifest-path "$manifest"
native=target/host-digests/release/frmd-host-digests
arm=target/aarch64/$target/release/frmd-host-digests
qemu=(qemu-aarch64 -L /usr/aarch64-linux-gnu)
"$native" >target/aarch64/digests.x86_64
passed=0
failed=0
for cpu in max cortex-a53; do
    "${qemu[@]}" -cpu "$cpu" "$arm" >target/aarch64/digests.aarch64
    while read -r name host; do
        arm_digest=$(awk -v n="$name" '$1 == n { print $2 }' target/aarch64/digests.aarch64)
        if [ "$arm_digest" = "$host" ]; then
            passed=$((passed + 1))
            echo "aarch64 ($cpu) $name $arm_digest = x86-64"
        else
            failed=$((failed + 1))
            echo "aarch64 ($cpu) $name ${arm_digest:-missing} != x86-64 $host"
        fi
    done <target/aarch64/digests.x86_64
done
if [ "$unit" = 1 ]; then
    CARGO_TARGET_DIR=target/aarch64 \
        CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER="${qemu[*]} -cpu max" \
        "${cross_cargo[@]}" test -q -p frmd-core --target "$target" --test row_kernels
fi
if [ "$count" = 1 ]; then
    trace() {
        FRMD_KERNELS=$1 "${qemu[@]}" -cpu max -singlestep -d exec,nochain "$arm" mlp "$2" 2>&1 >/dev/null |
            grep -c '^Trace'
    }
    for level in portable neon sdot; do
        one=$(trace "$level" 1)
        three=$(trace "$level" 3)
        echo "aarch64 instructions per MLP-256 run ($level kernels): $(((three - one) / 2))"
    done
fi
echo "aarch64 digests: $passed passed, $failed failed"
[ "$failed" = 0 ] && [ "$passed" -gt 0 ]
