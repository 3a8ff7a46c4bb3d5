#!/usr/bin/env bash
# MetaWorld (data-options raw, seed 0) students: int16 exports with nearest and GPTQ rounding, 100 episodes each.
B=/work/main/target/debug/frmd
cd /work/main/examples/metaworld
for t in reach-v3 peg-insert-side-v3 push-v3; do
  S=/work/mwrun/data-options/raw/$t/seed0/student
  [ -e $S/frmd.json ] || continue
  for r in nearest gptq; do
    o=/work/gptq/mw-$t-int16-$r
    [ -e $o/eval100.json ] && continue
    [ -e $o/export.json ] || $B export --ckpt $S --out $o --activations int16 --weight-rounding $r --force > $o.export.log 2>&1 || { echo "export failed $o"; continue; }
    RAYON_NUM_THREADS=1 .venv/bin/python -m frmd_metaworld eval --task $t --episodes 100 --server "$B serve --baked $o" --json $o/eval100.json > $o.eval.log 2>&1
    echo "$(date +%H:%M:%S) $t $r $(python3 -c "import json;print(json.load(open('$o/eval100.json'))['success_rate'] if 'success_rate' in json.load(open('$o/eval100.json')) else open('$o/eval100.json').read()[:200])")"
  done
  [ -e /work/gptq/mw-$t-float/eval100.json ] || { mkdir -p /work/gptq/mw-$t-float; RAYON_NUM_THREADS=1 .venv/bin/python -m frmd_metaworld eval --task $t --episodes 100 --server "$B serve --ckpt $S --steps 1" --json /work/gptq/mw-$t-float/eval100.json > /work/gptq/mw-$t-float.eval.log 2>&1; echo "$(date +%H:%M:%S) $t float done"; }
done
