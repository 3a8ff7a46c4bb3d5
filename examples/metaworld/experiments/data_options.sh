#!/usr/bin/env bash
# The data options of `collect` measured on all 12 tasks (issue 21, item 3): the benchmark run
# once per data configuration, task by task in alternation so that the comparison is complete for
# every finished task. Resumable (each benchmark step is skipped when its output exists); run it
# from examples/metaworld after setup.sh:
#
#   bash experiments/data_options.sh FRMD OUT [SEEDS]
#
# FRMD: the frmd binary; OUT: a directory for the data (OUT/data) and one run directory per
# configuration (OUT/raw, OUT/relative-after20); SEEDS: training seeds (default 0). TASKS in the
# environment overrides the task order (default: the benchmark's 12, easy to hard).
# Each run directory's results: `python -m frmd_metaworld benchmark --report-only --out OUT/CFG
# --data-dir OUT/data [--obs relative --after-success 20] --seeds SEEDS`.
set -euo pipefail
frmd="$(realpath "$1")"
out="$(realpath -m "$2")"
seeds="${3:-0}"
python=.venv/bin/python
tasks=${TASKS:-$("$python" -c "from frmd_metaworld.tasks import TASKS; print(' '.join(TASKS))")}
mkdir -p "$out"
for task in $tasks; do
    for cfg in raw relative-after20; do
        case "$cfg" in
            raw) opts=() ;;
            # The data options are for the learned ProDMP policies: no DP on this data here.
            relative-after20) opts=(--obs relative --after-success 20
                                    --methods teacher,student-1,student-2,int8-student,int16-student) ;;
        esac
        echo "== $task $cfg (seeds $seeds)"
        "$python" -m frmd_metaworld benchmark --task "$task" --seeds "$seeds" --multi-seed-tasks none --int16 \
            --frmd "$frmd" --data-dir "$out/data" --out "$out/$cfg" "${opts[@]}"
    done
done
