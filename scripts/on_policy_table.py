#!/usr/bin/env python3
"""On-policy distillation against the recipe student (docs/experiments.md, "On-policy
distillation").

    python3 scripts/on_policy_table.py [RESULTS]     (default docs/results/on-policy)

Built-in tasks: RESULTS/<task>/s<seed>/<variant>/eval-{1,2}.json (400 episodes, evaluation seeds
0-399) against the recipe's teacher and student of the same seed on the same seeds
(docs/results/recipe-anchor: seeds 0-199, docs/results/after-success/baseline: 200-399, where
the seed-0-199 report of a seed missing from recipe-anchor also lives). MetaWorld:
RESULTS/metaworld/<task>/{teacher,base-1,onp-1,onp-2}.json (100 episodes each, seed 0).
Prints Markdown tables."""
import json
import os
import sys

RESULTS = sys.argv[1] if len(sys.argv) > 1 else "docs/results/on-policy"
ROOT = os.path.dirname(os.path.normpath(RESULTS))
ANCHOR, BASELINE = os.path.join(ROOT, "recipe-anchor"), os.path.join(ROOT, "after-success", "baseline")


def rate(path):
    with open(path) as f:
        return 100.0 * json.load(f)["success_rate"]


def first(*paths):
    for path in paths:
        if os.path.exists(path):
            return rate(path)
    return None


def recipe(task, seed, rel):
    """Mean of the recipe model's two 200-episode reports (seeds 0-199 and 200-399)."""
    low = first(os.path.join(ANCHOR, task, seed, rel + ".json"), os.path.join(BASELINE, task, seed, rel + ".json"))
    high = first(os.path.join(BASELINE, task, seed, rel + "-seeds200.json"))
    return None if low is None or high is None else (low + high) / 2


def fmt(x):
    return "-" if x is None else f"{x:.1f}"


def builtin():
    rows = []
    for task in sorted(os.listdir(RESULTS)):
        if task == "metaworld" or not os.path.isdir(os.path.join(RESULTS, task)):
            continue
        for seed in sorted(os.listdir(os.path.join(RESULTS, task))):
            teacher, student = recipe(task, seed, "teacher/eval-dpm10"), recipe(task, seed, "student/eval-1")
            for variant in sorted(os.listdir(os.path.join(RESULTS, task, seed))):
                base = os.path.join(RESULTS, task, seed, variant)
                one, two = first(os.path.join(base, "eval-1.json")), first(os.path.join(base, "eval-2.json"))
                rows.append((f"{task} {seed}", variant, teacher, student, one, two))
    print("| task, seed | variant | teacher | recipe student, 1 step | on-policy student, 1 step | "
          "2 steps | 1 step vs teacher (recipe -> on-policy) |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: |")
    for name, variant, teacher, student, one, two in rows:
        gap = (f"{student - teacher:+.1f} -> {one - teacher:+.1f}"
               if None not in (teacher, student, one) else "-")
        print(f"| {name} | {variant} | {fmt(teacher)} | {fmt(student)} | {fmt(one)} | {fmt(two)} | {gap} |")


def metaworld():
    root = os.path.join(RESULTS, "metaworld")
    if not os.path.isdir(root):
        return
    print()
    print("| MetaWorld task (seed 0) | teacher | student, 1 step | on-policy student, 1 step | 2 steps |")
    print("| --- | ---: | ---: | ---: | ---: |")
    sums, count = [0.0] * 4, 0
    for task in sorted(os.listdir(root)):
        values = [first(os.path.join(root, task, f"{name}.json")) for name in ("teacher", "base-1", "onp-1", "onp-2")]
        print(f"| {task} | " + " | ".join(fmt(v) for v in values) + " |")
        if None not in values:
            sums, count = [s + v for s, v in zip(sums, values)], count + 1
    if count:
        print(f"| mean of {count} | " + " | ".join(f"{s / count:.1f}" for s in sums) + " |")


builtin()
metaworld()
