"""The pieces of a benchmark's results files that do not depend on the simulator: pooling rows
(one evaluation report of one task, training seed and method each) into group tables with a 95 %
Wilson interval, success per task, the spread over training seeds, the markdown tables, the bar
chart, the commit, the atomic file writes and the quick mode's validity check.

A row is a dict with task, group, seed (None for a scripted expert), method, episodes, successes,
success_rate, success_ci95, latency_us_median, latency_us_p99, roundtrip_us_median,
non_smooth_ee_mean, non_smooth_action_mean, rms_jerk_mean, mean_length (and report: its file).
"""
from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

from . import metrics

ROW_FIELDS = ["episodes", "successes", "success_rate", "success_ci95", "latency_us_median", "latency_us_p99",
              "roundtrip_us_median", "non_smooth_ee_mean", "non_smooth_action_mean", "rms_jerk_mean", "mean_length"]


def row_of(report: dict, task: str, group: str, seed, method: str, path) -> dict:
    """A results row from one evaluation report (the JSON `eval` writes)."""
    row = {"task": task, "group": group, "seed": seed, "method": method}
    row.update({k: report.get(k) for k in ROW_FIELDS})
    row["report"] = str(path)
    return row


def commit(here: Path) -> str:
    """HEAD's short hash, marked when the package directory `here` has uncommitted changes."""
    try:
        head = subprocess.check_output(["git", "rev-parse", "--short", "HEAD"], cwd=here, text=True).strip()
        dirty = subprocess.call(["git", "diff", "--quiet", "HEAD", "--", "."], cwd=here)
        return head + (" (with uncommitted changes)" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def pooled(rows: list) -> dict:
    """Episodes pooled over rows: success with its interval, median latency, non-smooth counts."""
    n = sum(r["episodes"] for r in rows)
    s = sum(r["successes"] for r in rows)
    lo, hi = metrics.wilson_interval(s, n) if n else (0.0, 0.0)
    steps = sum(r["mean_length"] * r["episodes"] for r in rows)
    non_smooth = sum(r["non_smooth_ee_mean"] * r["episodes"] for r in rows)
    return {"tasks": len({r["task"] for r in rows}), "runs": len(rows), "episodes": n, "successes": s,
            "success_rate": s / n if n else 0.0, "success_ci95": [lo, hi],
            "latency_us_median": metrics.quantile([r["latency_us_median"] for r in rows], 0.5) if rows else None,
            "non_smooth_ee_mean": metrics.mean([r["non_smooth_ee_mean"] for r in rows]) if rows else None,
            "non_smooth_per_step": non_smooth / steps if steps else None}


def summarize(rows: list, groups: dict, methods: list) -> dict:
    """group (and "overall") -> method -> pooled, over every training seed."""
    every = [t for tasks in groups.values() for t in tasks]
    return {group: {m: pooled([r for r in rows if r["method"] == m and r["task"] in tasks]) for m in methods}
            for group, tasks in list(groups.items()) + [("overall", every)]}


def per_task(rows: list, tasks: list, methods: list) -> dict:
    """task -> method -> mean success over the training seeds that have a report."""
    out = {}
    for task in tasks:
        for method in methods:
            rates = [r["success_rate"] for r in rows if r["task"] == task and r["method"] == method]
            if rates:
                out.setdefault(task, {})[method] = sum(rates) / len(rates)
    return out


def seed_spread(rows: list, tasks: list, methods: list) -> list:
    """Per task trained with several seeds and per method: mean, min and max success."""
    out = []
    for task in tasks:
        for method in methods:
            rates = [r["success_rate"] for r in rows if r["task"] == task and r["method"] == method]
            if len(rates) > 1:
                out.append({"task": task, "method": method, "seeds": len(rates),
                            "mean": sum(rates) / len(rates), "min": min(rates), "max": max(rates)})
    return out


def pct(p: dict) -> str:
    if not p["episodes"]:
        return "not run"
    lo, hi = p["success_ci95"]
    return f"{100 * p['success_rate']:.1f} [{100 * lo:.1f}, {100 * hi:.1f}]"


def num(v, fmt="{:.1f}") -> str:
    return "-" if v is None else fmt.format(v)


def group_tables_md(tables: dict) -> list:
    lines = []
    for group, table in tables.items():
        lines += [f"## {group}", "", "| method | tasks | task-seeds | success % [95 % CI] | latency us/chunk | "
                  "non-smooth / episode | non-smooth / step |", "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
        for m, p in table.items():
            lines.append(f"| {m} | {p['tasks']} | {p['runs']} | {pct(p)} | {num(p['latency_us_median'])} | "
                         f"{num(p['non_smooth_ee_mean'])} | {num(p['non_smooth_per_step'], '{:.3f}')} |")
        lines.append("")
    return lines


def per_task_md(mean_by_task: dict, methods: list, group_of: dict) -> list:
    if not mean_by_task:
        return []
    lines = ["## Per task (mean success % over training seeds)", "",
             "| task | group | " + " | ".join(methods) + " |", "| --- | --- | " + " | ".join("---:" for _ in methods) + " |"]
    for task, by_method in mean_by_task.items():
        lines.append(f"| {task} | {group_of[task]} | " + " | ".join(
            f"{100 * by_method[m]:.1f}" if m in by_method else "-" for m in methods) + " |")
    return lines + [""]


def spread_md(spread: list) -> list:
    if not spread:
        return []
    lines = ["## Spread over training seeds", "", "| task | method | seeds | mean success % | min | max |",
             "| --- | --- | ---: | ---: | ---: | ---: |"]
    lines += [f"| {x['task']} | {x['method']} | {x['seeds']} | {100 * x['mean']:.1f} | {100 * x['min']:.1f} | "
              f"{100 * x['max']:.1f} |" for x in spread]
    return lines + [""]


def per_seed_md(rows: list) -> list:
    lines = ["## Per task and seed", "", "| task | group | seed | method | success % [95 % CI] | latency us/chunk | "
             "round trip us | non-smooth / episode | mean length |", "| --- | --- | ---: | --- | ---: | ---: | ---: | ---: | ---: |"]
    for r in rows:
        lo, hi = r["success_ci95"]
        lines.append(f"| {r['task']} | {r['group']} | {'-' if r['seed'] is None else r['seed']} | {r['method']} | "
                     f"{100 * r['success_rate']:.1f} [{100 * lo:.1f}, {100 * hi:.1f}] | {r['latency_us_median']:.1f} | "
                     f"{num(r['roundtrip_us_median'])} | {r['non_smooth_ee_mean']:.1f} | {r['mean_length']:.1f} |")
    return lines


def targets_md(checks: list, heading: str = "## Targets (overall table)") -> list:
    if not checks:
        return []
    lines = [heading, "", "| target | measured | met |", "| --- | --- | --- |"]
    return lines + [f"| {t} | {v} | {'yes' if ok else 'NO'} |" for t, v, ok in checks] + [""]


def bar_chart(mean_by_task: dict, tasks: list, methods: list, path: Path, ylabel: str, title: str) -> None:
    """Grouped bars of success per task and method (PNG, written atomically)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    tasks = [t for t in tasks if t in mean_by_task]
    fig, ax = plt.subplots(figsize=(max(6, 1.4 * len(tasks) + 2), 4.5))
    width = 0.8 / len(methods)
    for i, method in enumerate(methods):
        values = [100 * mean_by_task[t].get(method, 0.0) for t in tasks]
        ax.bar([k + (i - (len(methods) - 1) / 2) * width for k in range(len(tasks))], values, width, label=method)
    ax.set_xticks(range(len(tasks)), tasks, rotation=30, ha="right")
    ax.set_ylabel(ylabel)
    ax.set_ylim(0, 105)
    ax.set_title(title, pad=28)
    # Above the axes, so no bar is hidden behind it.
    ax.legend(fontsize=8, ncol=len(methods), loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False)
    fig.tight_layout()
    tmp = path.with_name(path.name + ".partial")
    fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    os.replace(tmp, path)


def write_text(path: Path, text: str) -> None:
    """Writes `text` to `path` through a temporary file beside it (never a half-written file)."""
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(text)
    os.replace(tmp, path)


def write_json(path: Path, value) -> None:
    write_text(path, json.dumps(value, indent=1) + "\n")


def quick_check(written: dict, md_path: Path, expected: set) -> None:
    """--quick: every (task, method) of `expected` has a report, and the three files are valid."""
    got = {(r["task"], r["method"]) for r in written["rows"]}
    if expected - got:
        raise SystemExit(f"quick mode: missing reports {sorted(expected - got)}")
    json.loads(md_path.with_suffix(".json").read_text())
    png = md_path.with_suffix(".png").read_bytes()
    if not png.startswith(b"\x89PNG"):
        raise SystemExit("quick mode: the bar chart is not a PNG")
    if "## overall" not in md_path.read_text():
        raise SystemExit("quick mode: results.md lacks the overall table")
