#!/usr/bin/env bash
# Issue 22: frmd equiv over 2,000 episodes for run2.sh's transformer-lite student (int8, int16).
# (A recipe-length student from the same teacher, 3,000 steps at batch 128, ran at ~4 s per step
# here beside other jobs and did not fit the session.) Resumable.
set -euo pipefail
N=/work/bin/frmd-s4; R=/work/tf16
export RAYON_NUM_THREADS=1
step() { local done=$1; shift; [ -e "$done" ] && { echo "skip $done"; return; }; echo "$(date +%T) start $*"; "$@"; }
for q in int16 int8; do
  step $R/$q/equiv2000.json $N equiv --ckpt $R/student --baked $R/$q --episodes 2000 --json $R/$q/equiv2000.json || true
done
