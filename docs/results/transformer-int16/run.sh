#!/usr/bin/env bash
# Transformer-lite student on built-in avoid (shortened: teacher 5,000 steps, student 1,000) for
# issue 22's int8-vs-int16 comparison of a trained transformer. Resumable.
set -euo pipefail
F=/work/bin/frmd-t3; D=/work/recipe/data/avoid.safetensors; R=/work/tf16
export RAYON_NUM_THREADS=1
step() { local done=$1; shift; [ -e "$done" ] && { echo "skip $done"; return; }; echo "$(date +%T) start $*"; "$@"; }
step $R/teacher/frmd.json $F train teacher --data $D --out $R/teacher --backbone transformer-lite --seed 0 --steps 5000 --eval-episodes 0
step $R/student/frmd.json $F train student --teacher $R/teacher --data $D --out $R/student --seed 0 --steps 1000 --eval-episodes 0
for q in int8 int16; do
  step $R/$q/export.json /work/bin/frmd-s4 export --ckpt $R/student --out $R/$q --activations $q
done
