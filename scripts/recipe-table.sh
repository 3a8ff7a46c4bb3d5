#!/usr/bin/env bash
# The recipe table of docs/status.md: the default recipe on the built-in tasks, several training seeds.
#
#   scripts/recipe-table.sh [OUT_DIR] [TASKS] [SEEDS]
#   defaults: runs/recipe "reach avoid push insert" "0 1 2"
#
# Every step is the plain CLI with its defaults (only --backbone mlp-paper and --seed are given;
# --eval-episodes 0 skips the 20-episode check at the end of training, the table evaluates on 200);
# the student is exported with int8 and with int16 activations (the default) and each export is
# compared with the float student over 2,000 episodes (`frmd equiv`).
# A step whose output exists is skipped, so the script resumes after an interruption. Logs go to
# OUT_DIR/logs. Needs `frmd` on the PATH (`cargo install --path frmd-host`) or FRMD=/path/to/frmd.
# DP=0 skips the DP baseline (when only the teacher or student recipe changed, its reports in
# docs/results/recipe still hold). COLLECT_ARGS adds options to `frmd collect` (a data variant,
# e.g. COLLECT_ARGS="--after-success 20"). Summary: python3 scripts/recipe_table.py OUT_DIR
set -euo pipefail
OUT=${1:-runs/recipe}
TASKS=${2:-"reach avoid push insert"}
SEEDS=${3:-"0 1 2"}
FRMD=${FRMD:-frmd}
DP=${DP:-1}
read -r -a collect_args <<< "${COLLECT_ARGS:-}"
export RAYON_NUM_THREADS=${RAYON_NUM_THREADS:-1}
mkdir -p "$OUT/data" "$OUT/logs"

step() { # step NAME DONE_FILE CMD...
    local name=$1 done=$2; shift 2
    if [ -e "$done" ]; then echo "skip  $name"; return; fi
    echo "$(date +%H:%M:%S) start $name"
    # `frmd equiv` exits 1 when a check fails (e.g. int8 more than 5 points under float): that is
    # a result, recorded in its report, so only a missing report stops the script.
    "$@" > "$OUT/logs/$name.log" 2>&1 || [ -e "$done" ] || { echo "FAILED $name (see $OUT/logs/$name.log)"; exit 1; }
}

for t in $TASKS; do
    step "collect-$t" "$OUT/data/$t.safetensors" "$FRMD" collect --task "$t" --out "$OUT/data/$t.safetensors" "${collect_args[@]}"
done
for s in $SEEDS; do
    for t in $TASKS; do
        d=$OUT/data/$t.safetensors; r=$OUT/$t/s$s
        step "$t-s$s-teacher" "$r/teacher/frmd.json" "$FRMD" train teacher --data "$d" --out "$r/teacher" --backbone mlp-paper --seed "$s" --eval-episodes 0
        step "$t-s$s-eval-teacher" "$r/teacher/eval-dpm10.json" "$FRMD" eval --task "$t" --ckpt "$r/teacher" --steps 10 --solver dpm++2m --episodes 200 --json "$r/teacher/eval-dpm10.json"
        step "$t-s$s-student" "$r/student/frmd.json" "$FRMD" train student --teacher "$r/teacher" --data "$d" --out "$r/student" --seed "$s" --eval-episodes 0
        step "$t-s$s-eval-student" "$r/student/eval-1.json" "$FRMD" eval --task "$t" --ckpt "$r/student" --steps 1 --episodes 200 --json "$r/student/eval-1.json"
        step "$t-s$s-eval-student2" "$r/student/eval-2.json" "$FRMD" eval --task "$t" --ckpt "$r/student" --steps 2 --episodes 200 --json "$r/student/eval-2.json"
        for q in int8 int16; do
            step "$t-s$s-export-$q" "$r/$q/export.json" "$FRMD" export --ckpt "$r/student" --out "$r/$q" --activations "$q"
            step "$t-s$s-equiv-$q" "$r/$q/equiv2000.json" "$FRMD" equiv --ckpt "$r/student" --baked "$r/$q" --episodes 2000 --json "$r/$q/equiv2000.json"
        done
        if [ "$DP" != 0 ]; then
            step "$t-s$s-dp" "$r/dp/frmd.json" "$FRMD" train dp --data "$d" --out "$r/dp" --backbone mlp-paper --seed "$s" --eval-episodes 0
            step "$t-s$s-eval-dp100" "$r/dp/eval-ddpm100.json" "$FRMD" eval --task "$t" --ckpt "$r/dp" --steps 100 --episodes 200 --json "$r/dp/eval-ddpm100.json"
            step "$t-s$s-eval-dp10" "$r/dp/eval-ddim10.json" "$FRMD" eval --task "$t" --ckpt "$r/dp" --steps 10 --episodes 200 --json "$r/dp/eval-ddim10.json"
        fi
    done
done
python3 "$(dirname "$0")/recipe_table.py" "$OUT"
