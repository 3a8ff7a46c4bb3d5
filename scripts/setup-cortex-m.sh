#!/usr/bin/env bash
# Makes Cortex-M builds (thumbv7em-none-eabihf: M4F/M7; thumbv8m.main-none-eabihf: M33/M55;
# thumbv6m-none-eabi: M0) and QEMU Cortex-M runs work (Debian 12, idempotent).
#
#   bash scripts/setup-cortex-m.sh [--path auto|rustup|debian]
#
# Toolchain paths, tried in this order with `auto` (the default; FRMD_CORTEX_M_PATH overrides):
#   rustup  `rustup target add` of the three targets, linked by the toolchain's rust-lld
#           (checked by linking a tiny no_std probe for each).
#   debian  Debian's rustc-web/cargo-web (1.96), rust-web-src and lld-16: core is compiled from
#           source (RUSTC_BOOTSTRAP=1, -Z build-std=core) and linked with ld.lld-16. Works with only
#           the Debian archive and crates.io reachable.
# Also installs qemu-system-arm. Writes the choice to an env file (default
# <repo>/target/cortex-m.env, override with FRMD_CORTEX_M_ENV) that scripts/cortex-m-cargo.sh
# reads; it prints the same variables so a caller can `eval` them.
set -euo pipefail

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
target=thumbv7em-none-eabihf
targets=(thumbv7em-none-eabihf thumbv8m.main-none-eabihf thumbv6m-none-eabi)
env_file="${FRMD_CORTEX_M_ENV:-$repo/target/cortex-m.env}"
choice="${FRMD_CORTEX_M_PATH:-auto}"
while [ $# -gt 0 ]; do
    case "$1" in
        --path) choice="${2:?--path needs auto, rustup or debian}"; shift 2 ;;
        --path=*) choice="${1#--path=}"; shift ;;
        -h|--help) sed -n '2,14p' "${BASH_SOURCE[0]}"; exit 0 ;;
        *) echo "setup-cortex-m: unknown argument '$1' (expected --path auto|rustup|debian)" >&2; exit 2 ;;
    esac
done
case "$choice" in auto|rustup|debian) ;; *)
    echo "setup-cortex-m: unknown toolchain path '$choice' (expected auto, rustup or debian)" >&2; exit 2 ;;
esac

log() { echo "setup-cortex-m: $*" >&2; }

# --- Debian packages: apt-get update at most once, and only when something is missing.
apt_updated=0
as_root() {
    if [ "$(id -u)" -eq 0 ]; then "$@"
    elif command -v sudo >/dev/null; then sudo "$@"
    else log "need root (or sudo) to run: $*"; return 1; fi
}
apt_update_once() {
    [ "$apt_updated" -eq 1 ] && return 0
    log "apt-get update"
    as_root env DEBIAN_FRONTEND=noninteractive apt-get update -q >&2
    apt_updated=1
}
apt_install() {
    local missing=()
    local options=()
    local pkg
    # Leading apt-get options (e.g. -t SUITE) pass through.
    while [ $# -gt 0 ] && [ "${1#-}" != "$1" ]; do options+=("$1" "$2"); shift 2; done
    for pkg in "$@"; do
        dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q 'install ok installed' || missing+=("$pkg")
    done
    [ ${#missing[@]} -eq 0 ] && return 0
    apt_update_once
    log "apt-get install ${missing[*]}"
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${options[@]}" "${missing[@]}" >&2
}

# --- Probe: link a tiny no_std program for the target with a given rustc (target default linker).
probe_dir="$(mktemp -d)"
trap 'rm -rf "$probe_dir"' EXIT
cat >"$probe_dir/probe.rs" <<'EOF'
#![no_std]
#![no_main]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! { loop {} }
#[no_mangle]
pub extern "C" fn _start() -> ! { loop {} }
EOF
probe_link() { # rustc target
    "$1" --edition 2021 --target "$2" -C panic=abort -O \
        "$probe_dir/probe.rs" -o "$probe_dir/probe.elf" >"$probe_dir/probe.log" 2>&1
}

try_rustup() {
    command -v rustup >/dev/null || { log "rustup not found"; return 1; }
    local missing=() t
    for t in "${targets[@]}"; do
        rustup target list --installed 2>/dev/null | grep -qx "$t" || missing+=("$t")
    done
    if [ ${#missing[@]} -gt 0 ]; then
        log "rustup target add ${missing[*]}"
        # Bounded: where static.rust-lang.org is unreachable, rustup may retry for a long time.
        timeout 300 rustup target add "${missing[@]}" >&2 || { log "rustup target add failed"; return 1; }
    fi
    local rustc
    rustc="$(rustup which rustc)"
    for t in "${targets[@]}"; do
        if ! probe_link "$rustc" "$t"; then
            log "rustup toolchain cannot link for $t with rust-lld:"; cat "$probe_dir/probe.log" >&2
            return 1
        fi
    done
    path=rustup
    cargo_bin="$(rustup which cargo)"
    rustc_bin="$rustc"
    rustdoc_bin="$(rustup which rustdoc)"
    build_std=0
    linker=""
    sysroot="$("$rustc" --print sysroot)"
}

try_debian() {
    apt_install rustc-web cargo-web rust-web-src lld-16
    local rustc=/usr/bin/rustc
    [ -x "$rustc" ] && [ -x /usr/bin/cargo ] && command -v ld.lld-16 >/dev/null \
        || { log "Debian toolchain incomplete after install"; return 1; }
    # The workspace's rust-version (MSRV); Debian 12 without bookworm-security only has 1.85.
    local msrv version
    msrv="$(sed -n 's/^rust-version *= *"\([0-9.]*\)".*/\1/p' "$repo/Cargo.toml" | head -n1)"
    version="$("$rustc" --version | awk '{print $2}')"
    if [ -n "$msrv" ] && [ "$(printf '%s\n%s\n' "$msrv" "$version" | sort -V | head -n1)" != "$msrv" ]; then
        log "Debian's rustc $version is older than the workspace's rust-version $msrv (enable bookworm-security for rustc-web 1.96)"
        return 1
    fi
    local t
    for t in "${targets[@]}"; do
        "$rustc" --print target-list | grep -qx "$t" || { log "$rustc does not know target $t"; return 1; }
    done
    sysroot="$("$rustc" --print sysroot)"
    [ -f "$sysroot/lib/rustlib/src/rust/library/core/Cargo.toml" ] \
        || { log "rust-web-src missing: no $sysroot/lib/rustlib/src/rust/library/core"; return 1; }
    path=debian
    cargo_bin=/usr/bin/cargo
    rustc_bin="$rustc"
    rustdoc_bin=/usr/bin/rustdoc
    build_std=1
    linker="$(command -v ld.lld-16)"
}

case "$choice" in
    rustup) try_rustup || { log "rustup path requested but unavailable"; exit 1; } ;;
    debian) try_debian || { log "debian path requested but unavailable"; exit 1; } ;;
    auto) try_rustup || { log "falling back to Debian's toolchain with -Z build-std=core"; try_debian; } ;;
esac

# QEMU from the suite of the machine's other QEMU packages: an image with qemu-utils from
# bookworm-backports (10.x) cannot take bookworm's qemu-system-arm 7.2 (qemu-utils Breaks
# qemu-system-common < 8.0), so it gets the backports build when that suite is configured (e.g.
# by examples/maniskill/setup-system.sh, which CI runs first).
qemu_suite=()
if ! command -v qemu-system-arm >/dev/null \
    && dpkg-query -W -f='${Version}' qemu-utils 2>/dev/null | grep -q 'bpo12'; then
    apt_update_once
    if apt-get indextargets --format '$(RELEASE)' | grep -qx bookworm-backports; then
        qemu_suite=(-t bookworm-backports)
    else
        log "qemu-utils comes from bookworm-backports but that suite is not in apt's sources; installing bookworm's qemu-system-arm may conflict (add bookworm-backports, e.g. with sudo bash examples/maniskill/setup-system.sh)"
    fi
fi
apt_install "${qemu_suite[@]}" qemu-system-arm
qemu="$(command -v qemu-system-arm)"

mkdir -p "$(dirname "$env_file")"
cat >"$env_file" <<EOF
# Written by scripts/setup-cortex-m.sh; read by scripts/cortex-m-cargo.sh.
FRMD_CM_PATH=$path
FRMD_CM_TARGET=$target
FRMD_CM_CARGO=$cargo_bin
FRMD_CM_RUSTC=$rustc_bin
FRMD_CM_RUSTDOC=$rustdoc_bin
FRMD_CM_BUILD_STD=$build_std
FRMD_CM_LINKER=$linker
FRMD_CM_SYSROOT=$sysroot
FRMD_CM_QEMU=$qemu
EOF

echo "setup-cortex-m: toolchain path: $path ($("$rustc_bin" --version))"
if [ "$build_std" = 1 ]; then
    echo "setup-cortex-m: builds use RUSTC_BOOTSTRAP=1 -Z build-std=core -Z build-std-features=compiler-builtins-mem, linker $linker"
else
    echo "setup-cortex-m: builds use the prebuilt $target std and rust-lld"
fi
echo "setup-cortex-m: qemu: $("$qemu" --version | head -n1)"
echo "setup-cortex-m: env file: $env_file (use: bash scripts/cortex-m-cargo.sh <cargo args>)"
sed -n 's/^\(FRMD_CM_[A-Z_]*=\)\(.*\)$/export \1"\2"/p' "$env_file"
