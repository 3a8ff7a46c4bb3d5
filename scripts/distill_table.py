"""The comparison table of scripts/distill_study.py: success per task (mean over training seeds,
[min-max]), the overall mean with its spread over seeds, the gap to the teachers, non-smooth
transitions per step and training time, from the evaluation summaries a run directory holds."""
from __future__ import annotations

import json
import shutil
from pathlib import Path


def _load(path: Path) -> dict | None:
    return json.loads(path.read_text()) if path.exists() else None


def _cells(runs: Path, reports: Path, name: str, tasks: list, seeds: list, steps: int) -> dict:
    """(task, seed) -> summary of one method (`teacher` or a variant at `steps`): from the run
    directory, else from the copy an earlier `table` committed under `reports` (so a table written
    from a new run directory keeps the rows measured in another)."""
    out = {}
    for t in tasks:
        for s in seeds:
            tag = "" if name == "teacher" else f"-{steps}"
            if name == "teacher":
                path = runs / "teachers" / t / f"s{s}" / "eval-teacher.summary.json"
            else:
                path = runs / "variants" / name / t / f"s{s}" / f"eval-{steps}.summary.json"
            summary = _load(path) or _load(reports / name / f"{t}-s{s}{tag}.json")
            if summary is not None:
                out[(t, s)] = summary
    return out


def _row(cells: dict, tasks: list, seeds: list, teacher: dict) -> dict:
    pct = {k: 100.0 * v["success_rate"] for k, v in cells.items()}
    per_task = {}
    for t in tasks:
        vals = [pct[(t, s)] for s in seeds if (t, s) in pct]
        if vals:
            per_task[t] = {"mean": sum(vals) / len(vals), "min": min(vals), "max": max(vals), "seeds": len(vals)}
    complete = len(cells) == len(tasks) * len(seeds)
    per_seed = {}
    for s in seeds:
        vals = [pct[(t, s)] for t in tasks if (t, s) in pct]
        if len(vals) == len(tasks):
            per_seed[s] = sum(vals) / len(vals)
    overall = sum(per_task[t]["mean"] for t in per_task) / len(per_task) if per_task else None
    shared = [k for k in cells if k in teacher]
    gap = None
    if shared:
        gap = sum(pct[k] - 100.0 * teacher[k]["success_rate"] for k in shared) / len(shared)
    smooth = [v["non_smooth_ee_total"] / v["steps_total"] for v in cells.values() if v["steps_total"]]
    secs = [v["train_seconds"] for v in cells.values() if v.get("train_seconds")]
    return {
        "per_task": per_task, "overall": overall, "complete": complete, "per_seed": per_seed,
        "gap_to_teacher": gap, "pairs": len(cells), "worst_task_gap": _worst_gap(pct, teacher, tasks, seeds),
        "non_smooth_per_step": sum(smooth) / len(smooth) if smooth else None,
        "train_seconds_mean": sum(secs) / len(secs) if secs else None,
    }


def _worst_gap(pct: dict, teacher: dict, tasks: list, seeds: list):
    worst = None
    for t in tasks:
        keys = [(t, s) for s in seeds if (t, s) in pct and (t, s) in teacher]
        if keys:
            g = sum(pct[k] - 100.0 * teacher[k]["success_rate"] for k in keys) / len(keys)
            worst = g if worst is None else min(worst, g)
    return worst


def _fmt(x, digits=1, sign=False):
    if x is None:
        return "-"
    return f"{x:+.{digits}f}" if sign else f"{x:.{digits}f}"


def write_table(runs: Path, variants: list, tasks: list, seeds: list, out: Path) -> None:
    runs = runs.resolve()
    out.mkdir(parents=True, exist_ok=True)
    teacher_cells = _cells(runs, out / "reports", "teacher", tasks, seeds, 0)
    methods = [("teacher", "teacher", 0, teacher_cells, [], "the fixed teachers (reference)")]
    for v in variants:
        for steps in v.get("steps", [1]):
            label = v["name"] if steps == 1 else f"{v['name']} ({steps} steps)"
            methods.append((label, v["name"], steps, _cells(runs, out / "reports", v["name"], tasks, seeds, steps),
                            v.get("flags", []), v.get("note", "")))
    rows = []
    for label, name, steps, cells, flags, note in methods:
        row = _row(cells, tasks, seeds, teacher_cells)
        row.update({"method": label, "variant": name, "flags": flags, "note": note})
        rows.append(row)
        dest = out / "reports" / name
        for (t, s), summary in cells.items():
            dest.mkdir(parents=True, exist_ok=True)
            tag = "" if name == "teacher" else f"-{steps}"
            (dest / f"{t}-s{s}{tag}.json").write_text(json.dumps(summary, indent=1) + "\n")
    lines = [
        "# Distillation development set",
        "",
        f"Success in % over {', '.join(str(s) for s in seeds)} training seeds (mean [min-max]), "
        "one student step unless the method says otherwise, the same evaluation seeds for every method; "
        "written by `python3 scripts/distill_study.py table`. `overall` is the mean over the tasks, "
        "`per seed` the overall value of each training seed, `vs teacher` the mean difference to the "
        "teacher on the same task-seeds and `worst task` the task with the largest loss; non-smooth is "
        "transitions per control step of the end-effector path (mean over task-seeds); train s is the "
        "mean training time of one student. `*` marks an incomplete row (pairs measured / expected).",
        "",
        "| method | " + " | ".join(tasks) + " | overall | per seed | vs teacher | worst task | non-smooth / step | train s |",
        "| --- | " + " | ".join("---:" for _ in tasks) + " | ---: | --- | ---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        cells = []
        for t in tasks:
            c = r["per_task"].get(t)
            cells.append("-" if c is None else (f"{c['mean']:.1f}" if c["min"] == c["max"]
                                                 else f"{c['mean']:.1f} [{c['min']:.0f}-{c['max']:.0f}]"))
        mark = "" if r["complete"] else f" * ({r['pairs']}/{len(tasks) * len(seeds)})"
        per_seed = " / ".join(f"{v:.1f}" for v in r["per_seed"].values()) or "-"
        lines.append(f"| {r['method']}{mark} | " + " | ".join(cells) +
                     f" | {_fmt(r['overall'])} | {per_seed} | {_fmt(r['gap_to_teacher'], sign=True) if r['variant'] != 'teacher' else ''}"
                     f" | {_fmt(r['worst_task_gap'], sign=True) if r['variant'] != 'teacher' else ''}"
                     f" | {_fmt(r['non_smooth_per_step'], 3)} | {_fmt(r['train_seconds_mean'], 0)} |")
    lines += ["", "| method | flags of `frmd train student` | what it is |", "| --- | --- | --- |"]
    for r in rows[1:]:
        if "(" in r["method"]:
            continue
        lines.append(f"| {r['method']} | `{' '.join(r['flags']) or '(defaults)'}` | {r['note']} |")
    (out / "results.md").write_text("\n".join(lines) + "\n")
    (out / "results.json").write_text(json.dumps({"tasks": tasks, "seeds": seeds, "rows": rows}, indent=1) + "\n")
    print(f"wrote {out / 'results.md'}")
