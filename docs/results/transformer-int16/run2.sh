#!/usr/bin/env bash
# After run.sh's teacher: a short student (400 steps, batch 64) to fit the session, both exports,
# and frmd equiv for int8 and int16 (500 episodes each). Resumable.
set -euo pipefail
F=/work/bin/frmd-t3; N=/work/bin/frmd-s4; D=/work/recipe/data/avoid.safetensors; R=/work/tf16
export RAYON_NUM_THREADS=1
step() { local done=$1; shift; [ -e "$done" ] && { echo "skip $done"; return; }; echo "$(date +%T) start $*"; "$@"; }
step $R/student/frmd.json $F train student --teacher $R/teacher --data $D --out $R/student --seed 0 --steps 400 --batch 64 --eval-episodes 0
for q in int8 int16; do
  step $R/$q/export.json $N export --ckpt $R/student --out $R/$q --activations $q
done
for q in int16 int8; do
  step $R/$q/equiv500.json $N equiv --ckpt $R/student --baked $R/$q --episodes 500 --json $R/$q/equiv500.json || true
done
