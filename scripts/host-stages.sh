#!/usr/bin/env bash
# Per-stage breakdown of the host chunk (frmd_host::bench::stages): instructions per chunk under
# callgrind and median wall time, for the int8 and int16-activation exports of the random
# reach-shape students. Usage:
#   scripts/host-stages.sh [BACKBONES] [PRECISIONS] [REPS]
#   (defaults: "mlp mlp-paper", "int8 int16", 20)
# Builds examples/chunk_stages.rs in release. Layer parts are increments: `rows` is the layer's
# accumulators alone, `requant` what requantizing adds, `table` what the activation table adds;
# `other` is the chunk minus every stage (the policy's bookkeeping and the host glue).
# Under callgrind the kernels run their AVX2 build (valgrind's CPU has no AVX-512); the wall times
# are those of this CPU's dispatch.
set -euo pipefail
cd "$(dirname "$0")/.."
backbones=${1:-"mlp mlp-paper"}
precisions=${2:-"int8 int16"}
reps=${3:-20}
export RAYON_NUM_THREADS=1
nice -n 10 cargo build --release -q -p frmd-host --example chunk_stages
bin=target/release/examples/chunk_stages
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for backbone in $backbones; do
    for precision in $precisions; do
        out="$work/cg.$backbone.$precision"
        valgrind --tool=callgrind --callgrind-out-file="$out" --collect-atstart=no \
            --toggle-collect='chunk_stages::measured' --dump-after='chunk_stages::measured' \
            "$bin" "$precision" "$backbone" "$reps" >"$work/names" 2>"$work/valgrind.log"
        "$bin" "$precision" "$backbone" 200 --time >"$work/times"
        python3 - "$out" "$work/names" "$work/times" "$reps" "$backbone" "$precision" <<'EOF'
import sys
out, names_file, times_file, reps, backbone, precision = sys.argv[1:]
names = open(names_file).read().split("\n")[: -1]
instr = {}
for i, name in enumerate(names, start=1):
    for line in open(f"{out}.{i}"):
        if line.startswith("totals:"):
            instr[name] = int(line.split()[1]) / int(reps)
wall = dict(line.rstrip("\n").split("\t") for line in open(times_file))
rows, previous = [], 0.0
for name in names:
    value = instr[name]
    part = name.rsplit(" ", 1)[-1]
    shown = value - previous if part in ("requant", "table") else value
    previous = value
    rows.append((name, shown))
chunk = instr["chunk"]
rows.insert(len(rows) - 1, ("other", chunk - sum(v for n, v in rows if n != "chunk")))
print(f"\n{backbone} {precision}: instructions per chunk (callgrind, AVX2 kernels), median ns")
print("| stage | instructions | share | wall ns |")
print("| --- | ---: | ---: | ---: |")
for name, value in rows:
    key = "other (host glue)" if name == "other" else name
    ns = float(wall.get(key, "nan"))
    print(f"| {name} | {value:,.0f} | {100 * value / chunk:.1f} % | {ns:,.0f} |")
EOF
    done
done
