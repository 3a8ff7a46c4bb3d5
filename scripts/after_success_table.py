#!/usr/bin/env python3
"""The settling-data comparison of docs/experiments.md ("Settling after success").

    python3 scripts/after_success_table.py [RESULTS]     (default docs/results/after-success)

RESULTS/<task>/s<seed>/ holds the K = 20 runs (teacher/eval-dpm10.json, student/eval-1.json on
evaluation seeds 0-199, *-seeds200.json on 200-399); RESULTS/baseline/<task>/s<seed>/ the K = 0
runs' reports on seeds 200-399 and, where docs/results/recipe-anchor lacks the seed, on 0-199.
Prints one Markdown row per task and seed: the mean of the two 200-episode runs per model."""
import json, os, sys

RESULTS = sys.argv[1] if len(sys.argv) > 1 else "docs/results/after-success"
ANCHOR = os.path.join(os.path.dirname(os.path.normpath(RESULTS)), "recipe-anchor")
MODELS = [("teacher", "teacher/eval-dpm10"), ("student", "student/eval-1")]


def rate(*candidates):
    for path in candidates:
        if os.path.exists(path):
            with open(path) as f:
                return 100.0 * json.load(f)["success_rate"]
    raise SystemExit(f"missing report: {candidates[0]}")


def mean_of_runs(k20, task, seed, rel):
    if k20:
        base = os.path.join(RESULTS, task, seed)
        first = rate(os.path.join(base, rel + ".json"))
    else:
        base = os.path.join(RESULTS, "baseline", task, seed)
        first = rate(os.path.join(base, rel + ".json"), os.path.join(ANCHOR, task, seed, rel + ".json"))
    return (first + rate(os.path.join(base, rel + "-seeds200.json"))) / 2


rows = []
for task in ["avoid", "insert", "push", "reach"]:
    seeds = sorted(os.listdir(os.path.join(RESULTS, task))) if os.path.isdir(os.path.join(RESULTS, task)) else []
    for seed in seeds:
        t0, s0 = (mean_of_runs(False, task, seed, rel) for _, rel in MODELS)
        t1, s1 = (mean_of_runs(True, task, seed, rel) for _, rel in MODELS)
        rows.append((t0, t1, s0, s1))
        print(f"| {task} {seed} | {t0:.1f} | {t1:.1f} | {s0:.1f} | {s1:.1f} | {s0 - t0:+.1f} / {s1 - t1:+.1f} |")
if rows:
    m = [sum(r[i] for r in rows) / len(rows) for i in range(4)]
    print(f"| mean of {len(rows)} | {m[0]:.1f} | {m[1]:.1f} | {m[2]:.1f} | {m[3]:.1f} | {m[2] - m[0]:+.1f} / {m[3] - m[1]:+.1f} |")
