#!/usr/bin/env python3
"""Summarize a run tree written by scripts/recipe-table.sh into the recipe table of docs/status.md.

usage: recipe_table.py RUNS_DIR [--json OUT]
       recipe_table.py RUNS_DIR --copy-reports DEST   (the reports behind the table, as committed
                                                       in docs/results/recipe; existing files kept)

RUNS_DIR/<task>/s<seed>/{teacher,student,dp,int8}/ hold the evaluation reports of `frmd eval
--json` and `frmd equiv --json`. Prints a Markdown table: per task and method the mean success
over the training seeds that finished, the spread (min-max), the seed count, and the non-smooth
transitions per successful episode; then the int8-vs-float rows."""
import json, os, re, shutil, statistics, sys

METHODS = [  # (column, relative path of the report)
    ("teacher DPM++(2M)-10", "teacher/eval-dpm10.json"),
    ("student 1 step", "student/eval-1.json"),
    ("student 2 steps", "student/eval-2.json"),
    ("DP DDPM-100", "dp/eval-ddpm100.json"),
    ("DP DDIM-10", "dp/eval-ddim10.json"),
]
TASKS = ["reach", "avoid", "push", "insert"]


def load(path):
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def nonsmooth_per_success(rep):
    eps = [e for e in rep.get("per_episode", []) if e.get("success")]
    vals = [e.get("non_smooth_ee", e.get("non_smooth")) for e in eps]
    vals = [v for v in vals if v is not None]
    return statistics.mean(vals) if vals else float("nan")


def int8_vs_float(equiv):
    """(float rate, int8 rate, episodes) from `frmd equiv --json`'s closed-loop row (b)."""
    for row in equiv.get("rows", []):
        if row.get("check") == "b" and row.get("metric", "").startswith("success-rate"):
            m = re.search(r"(\d+) episodes: float ([\d.]+) %, int8 ([\d.]+) %", row.get("note", ""))
            if m:
                return float(m.group(2)) / 100, float(m.group(3)) / 100, int(m.group(1))
    return None


def seeds_of(root, task):
    d = os.path.join(root, task)
    if not os.path.isdir(d):
        return []
    return sorted(s for s in os.listdir(d) if s.startswith("s") and s[1:].isdigit())


def cell(values):
    if not values:
        return "-"
    m = 100 * statistics.mean(values)
    if len(values) == 1:
        return f"{m:.1f} (1 seed)"
    return f"{m:.1f} [{100 * min(values):.1f}-{100 * max(values):.1f}] ({len(values)} seeds)"


REPORTS = [rel for _, rel in METHODS] + ["int8/equiv2000.json", "int8/export.json"]


def copy_reports(root, dest):
    """Copies every report of RUNS_DIR into DEST/<task>/s<seed>/, plus each checkpoint's frmd.json
    without tensors and loss curve as training.json. Files already in DEST are left alone."""
    for task in TASKS:
        for s in seeds_of(root, task):
            files = {}  # relative path -> (source file to copy, or JSON to write)
            for rel in REPORTS:
                if os.path.exists(os.path.join(root, task, s, rel)):
                    files[rel] = (os.path.join(root, task, s, rel), None)
            for role in ("teacher", "student", "dp"):
                meta = load(os.path.join(root, task, s, role, "frmd.json"))
                if meta:
                    meta["training"].pop("loss_curve", None)
                    files[f"{role}/training.json"] = (None, {k: meta[k] for k in ("role", "model", "dataset", "training")})
            for rel, (src, data) in files.items():
                out = os.path.join(dest, task, s, rel)
                if os.path.exists(out):
                    continue
                os.makedirs(os.path.dirname(out), exist_ok=True)
                if src:
                    shutil.copyfile(src, out)
                else:
                    with open(out, "w") as f:
                        json.dump(data, f, indent=1)
                print("wrote", out)


def main():
    root = sys.argv[1]
    if "--copy-reports" in sys.argv:
        copy_reports(root, sys.argv[sys.argv.index("--copy-reports") + 1])
        return
    summary = {}
    print("| task | " + " | ".join(c for c, _ in METHODS) + " |")
    print("| --- |" + " ---: |" * len(METHODS))
    for task in TASKS:
        row, smooth = [], []
        for col, rel in METHODS:
            reps = [load(os.path.join(root, task, s, rel)) for s in seeds_of(root, task)]
            reps = [r for r in reps if r]
            rates = [r["success_rate"] for r in reps]
            ns = [nonsmooth_per_success(r) for r in reps]
            summary.setdefault(task, {})[col] = {"success": rates, "non_smooth_per_success": ns}
            row.append(cell(rates))
        print(f"| {task} | " + " | ".join(row) + " |")
    print()
    print("| task | " + " | ".join(f"non-smooth / success, {c}" for c, _ in METHODS) + " |")
    print("| --- |" + " ---: |" * len(METHODS))
    for task in TASKS:
        cells = []
        for col, _ in METHODS:
            ns = [v for v in summary[task][col]["non_smooth_per_success"] if v == v]
            cells.append(f"{statistics.mean(ns):.1f}" if ns else "-")
        print(f"| {task} | " + " | ".join(cells) + " |")
    print()
    print("| task, seed | float student | int8 student | difference (points) | episodes |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for task in TASKS:
        for s in seeds_of(root, task):
            eq = load(os.path.join(root, task, s, "int8", "equiv2000.json"))
            if not eq:
                continue
            parsed = int8_vs_float(eq)
            if parsed is None:
                continue
            f, q, n = parsed
            summary[task].setdefault("int8", {})[s] = {"float": f, "int8": q, "episodes": n}
            print(f"| {task} {s} | {100*f:.1f} | {100*q:.1f} | {100*(q-f):+.1f} | {n} |")
    if "--json" in sys.argv:
        with open(sys.argv[sys.argv.index("--json") + 1], "w") as f:
            json.dump(summary, f, indent=1)


if __name__ == "__main__":
    main()
