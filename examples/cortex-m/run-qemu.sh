#!/usr/bin/env bash
# Builds the FRMD firmware (release) for a core and runs it under QEMU with instruction counting:
#
#   bash examples/cortex-m/run-qemu.sh m4|m7|m33|m0|m55 [prodmp|mlp|policy|policy16|transformer|transformer-student|transformer-student16|policy-stages|policy16-stages|transformer-stages|kernels|minimal] [extra cargo build args]
#
#   m4:  thumbv7em-none-eabihf,     -machine mps2-an386  -cpu cortex-m4  (Cortex-M4F)
#   m7:  thumbv7em-none-eabihf,     -machine mps2-an500  -cpu cortex-m7  (Cortex-M7, same ELF)
#   m33: thumbv8m.main-none-eabihf, -machine mps2-an505  -cpu cortex-m33 (DSP kernels, FPU)
#   m0:  thumbv6m-none-eabi,        -machine microbit    -cpu cortex-m0  (portable kernels, soft
#        float; 256 KiB flash, 16 KiB RAM: the transformer images do not fit)
#   m55: thumbv8m.main-none-eabihf, -machine mps3-an547  -cpu cortex-m55 (the M33 code, linked for
#        the AN547 memory map: this toolchain has no Armv8.1-M target, so no Helium kernels)
#   prodmp (default): firmware frmd-cortex-m, the baked ProDMP decoder
#   mlp: firmware frmd-cortex-m-mlp, synthetic int8 MLP 40-256-256-256-42 + decoder
#   policy: firmware frmd-cortex-m-policy, the trained student in policy/reach/ baked by frmd-export
#   policy16: firmware frmd-cortex-m-policy16, the same student exported with int16 activations
#   transformer: firmware frmd-cortex-m-transformer, a synthetic one-step policy with a
#     transformer-lite network
#   transformer-student, transformer-student16: firmware frmd-cortex-m-transformer-student[16], a
#     random transformer-lite student exported with int8 / int16 activations, run from its blob
#   pil: firmware frmd-cortex-m-pil, processor in the loop: answers frames on standard input
#     (frmd_firmware_support::pil); driven by the host (`frmd eval --firmware`), not run here
#   policy-stages, transformer-stages: the policy (same baked student) and the transformer
#     measurement, each plus the per-stage breakdown
#     (`stage <name>: <instructions>` lines)
#   kernels: firmware frmd-cortex-m-kernels, the fully connected kernels on random shapes (for
#     the host's bit-for-bit comparison)
#   minimal: crate minimal/ (frmd-minimal), the smallest policy firmware: prints its first action
#     (no measurement lines)
#
# Prints the firmware's `key: value` lines on stdout (build and setup chatter go to stderr) and
# exits non-zero if the build fails, the firmware reports an error or panics, a required line
# (digest, instructions, flash, ram) is missing, or QEMU runs longer than FRMD_QEMU_TIMEOUT
# seconds (default 120). FRMD_QEMU_TRACE=FILE also writes QEMU's instruction trace to FILE (for
# qemu-cycles.py). FRMD_QEMU_BUILD_ONLY=1 only builds and prints `elf: <path>`, `machine: <name>`,
# `cpu: <name>` and `qemu: <binary>` (what the host's processor-in-the-loop driver needs to start
# QEMU itself).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
board="${1:-}"
memory_map=""
case "$board" in
    m4) machine=mps2-an386; cpu=cortex-m4; target=thumbv7em-none-eabihf ;;
    m7) machine=mps2-an500; cpu=cortex-m7; target=thumbv7em-none-eabihf ;;
    m33) machine=mps2-an505; cpu=cortex-m33; target=thumbv8m.main-none-eabihf ;;
    m0) machine=microbit; cpu=cortex-m0; target=thumbv6m-none-eabi ;;
    m55) machine=mps3-an547; cpu=cortex-m55; target=thumbv8m.main-none-eabihf; memory_map=an547 ;;
    *) echo "usage: $0 m4|m7|m33|m0|m55 [prodmp|mlp|policy|policy16|transformer|transformer-student|transformer-student16|policy-stages|policy16-stages|transformer-stages|kernels|minimal] [extra cargo build args]" >&2; exit 2 ;;
esac
shift
bin=frmd-cortex-m
case "${1:-}" in
    prodmp) shift ;;
    mlp) bin=frmd-cortex-m-mlp; shift ;;
    policy) bin=frmd-cortex-m-policy; shift ;;
    policy16) bin=frmd-cortex-m-policy16; shift ;;
    transformer) bin=frmd-cortex-m-transformer; shift ;;
    transformer-student) bin=frmd-cortex-m-transformer-student; shift ;;
    transformer-student16) bin=frmd-cortex-m-transformer-student16; shift ;;
    policy-stages) bin=frmd-cortex-m-policy-stages; shift ;;
    policy16-stages) bin=frmd-cortex-m-policy16-stages; shift ;;
    kernels) bin=frmd-cortex-m-kernels; shift ;;
    minimal) bin=frmd-minimal; shift ;;
    transformer-stages) bin=frmd-cortex-m-transformer-stages; shift ;;
    pil) bin=frmd-cortex-m-pil; shift ;;
esac
timeout_s="${FRMD_QEMU_TIMEOUT:-120}"
case " $* " in *defmt*)
    echo "run-qemu: the defmt feature logs over RTT for a real probe; QEMU cannot show it (build it with scripts/cortex-m-cargo.sh instead)" >&2
    exit 2 ;;
esac

# Toolchain and QEMU: scripts/setup-cortex-m.sh records its choice in an env file; run it when
# that file or QEMU is missing (FRMD_CORTEX_M_PATH=rustup|debian forces a path on first setup).
env_file="${FRMD_CORTEX_M_ENV:-$repo/target/cortex-m.env}"
if [ ! -f "$env_file" ] || ! command -v qemu-system-arm >/dev/null; then
    bash "$repo/scripts/setup-cortex-m.sh" >&2
fi
# shellcheck disable=SC1090
. "$env_file"
echo "run-qemu: $bin for $target on $machine, $FRMD_CM_PATH toolchain ($("$FRMD_CM_RUSTC" --version))" >&2

cd "$here"
target_dir="${CARGO_TARGET_DIR:-$here/target}"
if [ -n "$memory_map" ]; then
    # Same target as another board, other memory map: its own build directory.
    target_dir="$target_dir/board-$memory_map"
fi
CARGO_TARGET_DIR="$target_dir" CARGO_BUILD_TARGET="$target" FRMD_CM_MEMORY_MAP="$memory_map" \
    bash "$repo/scripts/cortex-m-cargo.sh" build --release --workspace --bin "$bin" "$@" >&2
elf="$target_dir/$target/release/$bin"
[ -f "$elf" ] || { echo "run-qemu: firmware ELF not found at $elf" >&2; exit 1; }
if [ -n "${FRMD_QEMU_BUILD_ONLY:-}" ]; then
    printf 'elf: %s\nmachine: %s\ncpu: %s\nqemu: %s\n' "$elf" "$machine" "$cpu" "$FRMD_CM_QEMU"
    exit 0
fi

output="$(mktemp)"
trap 'rm -f "$output"' EXIT
set +e
trace=()
if [ -n "${FRMD_QEMU_TRACE:-}" ]; then
    # Every translated block and every block execution, for qemu-cycles.py (hundreds of MB).
    trace=(-d in_asm,exec,nochain -D "$FRMD_QEMU_TRACE")
fi
timeout "$timeout_s" "$FRMD_CM_QEMU" -machine "$machine" -cpu "$cpu" -nographic \
    -semihosting-config enable=on,target=native -icount shift=0 "${trace[@]}" -kernel "$elf" >"$output" 2>&1 </dev/null
status=$?
set -e
cat "$output"

if [ "$status" -eq 124 ]; then
    echo "run-qemu: QEMU ($machine) timed out after ${timeout_s} s" >&2
    exit 1
fi
if [ "$status" -ne 0 ]; then
    echo "run-qemu: firmware on $machine failed (QEMU exit status $status)" >&2
    exit 1
fi
required=(digest instructions flash ram)
[ "$bin" != frmd-minimal ] || required=("first action, dof 0")
for key in "${required[@]}"; do
    if ! grep -q "^$key: " "$output"; then
        echo "run-qemu: firmware output on $machine lacks the '$key:' line" >&2
        exit 1
    fi
done
