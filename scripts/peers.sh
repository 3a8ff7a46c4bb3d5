#!/usr/bin/env bash
# frmd-core's chunk beside ONNX Runtime on the same network shapes, in one run (issue 26):
#   scripts/peers.sh [BACKBONES] [ROUNDS] [CALLS]   (defaults: "mlp mlp-paper", 3, 2000)
# Each round times `frmd bench --synthetic` (the whole int8 / int16 chunk: noise, network,
# decode) and then scripts/peers.py (ONNX Runtime's `session.run` from Python on the network
# alone: int8 dynamic quantization, fp32, and an Identity graph for the call overhead), one
# thread, batch 1; the table shows the median over the rounds of each median and p99.
# FRMD_BIN names the frmd binaries, space-separated (default: target/release/frmd, what
# README's benchmark commands build with `cargo build --release -p frmd-host --bin frmd`); each is
# timed in every round and its rows carry its profile directory (`release`, `debug` = dev), so
#   FRMD_BIN="target/release/frmd target/debug/frmd" scripts/peers.sh
# compares the two profiles too. ONNX Runtime comes from PyPI into target/peers-venv (created on
# first use: python3 -m venv target/peers-venv && target/peers-venv/bin/pip install onnxruntime
# onnx numpy).
set -euo pipefail
cd "$(dirname "$0")/.."
backbones=${1:-"mlp mlp-paper"}
rounds=${2:-3}
calls=${3:-2000}
bins=${FRMD_BIN:-target/release/frmd}
venv=target/peers-venv
export RAYON_NUM_THREADS=1 OMP_NUM_THREADS=1
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install -q onnxruntime onnx numpy
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for round in $(seq "$rounds"); do
    for backbone in $backbones; do
        for bin in $bins; do
            profile=$(basename "$(dirname "$bin")")
            "$bin" bench --synthetic --backbone "$backbone" --calls "$calls" --warmup 200 \
                --json "$work/frmd.$backbone.$round.$profile.json" >/dev/null
        done
        "$venv/bin/python" scripts/peers.py --calls "$calls" "$backbone" \
            >"$work/ort.$backbone.$round.jsonl" 2>/dev/null
    done
done
python3 - "$work" "$bins" <<'EOF'
import glob, json, statistics, sys
work, binaries = sys.argv[1:]
rows = {}
for path in glob.glob(f"{work}/frmd.*.json"):
    _, backbone, _, profile, _ = path.split("/")[-1].split(".")
    for r in json.load(open(path))["results"]:
        if r["label"].startswith("frmd-core int") and "2-step" not in r["label"]:
            label = f"{r['label']} ({profile})"
            rows.setdefault((backbone, label), []).append((r["median_us"], r["p99_us"]))
for path in glob.glob(f"{work}/ort.*.jsonl"):
    for line in open(path):
        r = json.loads(line)
        rows.setdefault((r["backbone"], r["runtime"]), []).append((r["median_us"], r["p99_us"]))
print(f"frmd binaries: {binaries}")
print("| shape | runtime | median us | p99 us | rounds |")
print("| --- | --- | ---: | ---: | ---: |")
for (backbone, label), values in sorted(rows.items()):
    median = statistics.median(v[0] for v in values)
    p99 = statistics.median(v[1] for v in values)
    print(f"| {backbone} | {label} | {median:.1f} | {p99:.1f} | {len(values)} |")
profiles = [b.rstrip("/").split("/")[-2] for b in binaries.split()]
for backbone in sorted({b for b, _ in rows}):
    ort = [statistics.median(v[0] for v in vals) for (b, l), vals in rows.items()
           if b == backbone and l.startswith("ort") and "identity" not in l]
    for profile in profiles:
        core = rows.get((backbone, f"frmd-core int8 1-step ({profile})"))
        if ort and core:
            ratio = min(ort) / statistics.median(v[0] for v in core)
            print(f"{backbone}: ONNX Runtime's best / frmd-core int8 chunk ({profile}) = {ratio:.2f}x")
EOF
