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


def quantized_vs_float(equiv, label="int8"):
    """(float rate, quantized rate, episodes) from `frmd equiv --json`'s closed-loop row (b) of
    an export with `label` activations (int8, int16)."""
    for row in equiv.get("rows", []):
        if row.get("check") == "b" and row.get("metric", "").startswith("success-rate"):
            m = re.search(r"(\d+) episodes: float ([\d.]+) %, " + label + r" ([\d.]+) %", row.get("note", ""))
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


QUANTIZED = ["int8", "int16"]
REPORTS = [rel for _, rel in METHODS] + [f"{q}/{f}" for q in QUANTIZED for f in ("equiv2000.json", "export.json")]


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
    print("| task, seed | float student | int8 student | int8 - float | int16 student | int16 - float | episodes |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for task in TASKS:
        for s in seeds_of(root, task):
            cells, floats, episodes = [], [], set()
            for q in QUANTIZED:
                eq = load(os.path.join(root, task, s, q, "equiv2000.json"))
                parsed = quantized_vs_float(eq, q) if eq else None
                if parsed is None:
                    cells.append(None)
                    continue
                f, rate, n = parsed
                floats.append(f)
                episodes.add(n)
                summary[task].setdefault(q, {})[s] = {"float": f, q: rate, "episodes": n}
                cells.append((f, rate))
            if not floats:
                continue
            # Each equiv run evaluates the float student itself (same seeds): the first one shown.
            f = floats[0]
            text = lambda c: ("-", "-") if c is None else (f"{100*c[1]:.1f}", f"{100*(c[1]-c[0]):+.1f}")
            (q8, d8), (q16, d16) = text(cells[0]), text(cells[1])
            n = "/".join(str(e) for e in sorted(episodes))
            print(f"| {task} {s} | {100*f:.1f} | {q8} | {d8} | {q16} | {d16} | {n} |")
    if "--json" in sys.argv:
        with open(sys.argv[sys.argv.index("--json") + 1], "w") as f:
            json.dump(summary, f, indent=1)


if __name__ == "__main__":
    main()
