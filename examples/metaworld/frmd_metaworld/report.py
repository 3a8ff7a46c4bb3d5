"""results.md, results.json and the bar chart of a benchmark run (benchmark.py): one table per
difficulty group and overall (success with 95 % Wilson interval over the episodes pooled over
tasks and training seeds, median latency per chunk, non-smooth transitions per episode and per
step), success per task (mean over seeds), the spread over training seeds, success against the
firmware instructions a chunk costs, seeds, command, commit, and the targets checked against the
numbers."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

from . import metrics
from .benchmark import METHODS, OPTIONAL_METHODS, BenchConfig
from .tasks import GROUP_OF, GROUPS, TASKS



def methods_of(config: dict) -> list:
    """The methods a run evaluated (its config's `int16` adds int16-student, `only` selects), in
    table order."""
    only = config.get("only")
    return [m for m in METHODS if (m not in OPTIONAL_METHODS or config.get("int16"))
            and (only is None or m in only)]

def commit() -> str:
    here = Path(__file__).resolve().parent
    try:
        head = subprocess.check_output(["git", "rev-parse", "--short", "HEAD"], cwd=here, text=True).strip()
        dirty = subprocess.call(["git", "diff", "--quiet", "HEAD", "--", "."], cwd=here.parent.parent.parent)
        return head + (" (with uncommitted changes)" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def pooled(rows: list) -> dict:
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


def summarize(results: dict) -> dict:
    """Group and overall tables over every training seed of the run (and the expert)."""
    tables = {}
    for group, tasks in list(GROUPS.items()) + [("overall", TASKS)]:
        tables[group] = {m: pooled([r for r in results["rows"] if r["method"] == m and r["task"] in tasks])
                         for m in methods_of(results["config"])}
    return tables


def per_task(results: dict) -> dict:
    """task -> method -> mean success over the training seeds that have a report."""
    out = {}
    for task in TASKS:
        for method in methods_of(results["config"]):
            rates = [r["success_rate"] for r in results["rows"] if r["task"] == task and r["method"] == method]
            if rates:
                out.setdefault(task, {})[method] = sum(rates) / len(rates)
    return out


def seed_spread(results: dict) -> list:
    """Per task trained with several seeds and per learned method: mean, min and max success."""
    out = []
    for task in TASKS:
        for method in methods_of(results["config"])[1:]:
            rates = [r["success_rate"] for r in results["rows"] if r["task"] == task and r["method"] == method]
            if len(rates) > 1:
                out.append({"task": task, "method": method, "seeds": len(rates),
                            "mean": sum(rates) / len(rates), "min": min(rates), "max": max(rates)})
    return out


def targets(tables: dict, results: dict) -> list:
    """The targets on the overall table (all seeds): (what, measured, met)."""
    overall = {m: p for m, p in tables["overall"].items() if p["episodes"]}
    pts = {m: 100 * p["success_rate"] for m, p in overall.items()}
    checks = []
    if {"student-1", "teacher"} <= pts.keys():
        d = pts["student-1"] - pts["teacher"]
        checks.append(("one-step student >= teacher - 1 point", f"{d:+.1f} points", d >= -1.0))
        gaps = [(100 * (m["student-1"] - m["teacher"]), t) for t, m in per_task(results).items()
                if {"student-1", "teacher"} <= m.keys()]
        if gaps:
            worst, task = min(gaps)
            checks.append(("no task more than 4 points under its teacher (one-step student, mean over seeds)",
                           f"worst {task} {worst:+.1f} points", worst >= -4.0))
    if {"student-1", "dp-ddpm-100"} <= pts.keys():
        d = pts["student-1"] - pts["dp-ddpm-100"]
        checks.append(("one-step student >= DP DDPM-100 - 1 point", f"{d:+.1f} points", d >= -1.0))
    if {"student-1", "int8-student"} <= pts.keys():
        d = pts["int8-student"] - pts["student-1"]
        checks.append(("int8 student within 1 point of the float student", f"{d:+.1f} points", abs(d) <= 1.0))
    if {"student-1", "int16-student"} <= pts.keys():
        d = pts["int16-student"] - pts["student-1"]
        checks.append(("int16-activation student within 1 point of the float student", f"{d:+.1f} points",
                       abs(d) <= 1.0))
    # Latency: per task and seed, the int8 student against DDPM-100 of the same run.
    ratios = []
    for r in results["rows"]:
        if r["method"] != "int8-student":
            continue
        dp = [d for d in results["rows"] if d["task"] == r["task"] and d["seed"] == r["seed"] and d["method"] == "dp-ddpm-100"]
        if dp and r["latency_us_median"] > 0:
            ratios.append(dp[0]["latency_us_median"] / r["latency_us_median"])
    if ratios:
        worst = min(ratios)
        checks.append(("int8 student latency <= 1/100 of DP DDPM-100 (every task-seed)",
                       f"DDPM-100 / int8 = {worst:.0f}x at worst, {metrics.quantile(ratios, 0.5):.0f}x median "
                       f"({len(ratios)} task-seeds)", worst >= 100.0))
    return checks


def _pct(p: dict) -> str:
    if not p["episodes"]:
        return "not run"
    lo, hi = p["success_ci95"]
    return f"{100 * p['success_rate']:.1f} [{100 * lo:.1f}, {100 * hi:.1f}]"


def _num(v, fmt="{:.1f}") -> str:
    return "-" if v is None else fmt.format(v)


def bar_chart(results: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    means = per_task(results)
    tasks = [t for t in TASKS if t in means]
    fig, ax = plt.subplots(figsize=(max(6, 1.4 * len(tasks) + 2), 4.5))
    methods = methods_of(results["config"])
    width = 0.8 / len(methods)
    for i, method in enumerate(methods):
        values = [100 * means[t].get(method, 0.0) for t in tasks]
        ax.bar([k + (i - (len(methods) - 1) / 2) * width for k in range(len(tasks))], values, width, label=method)
    ax.set_xticks(range(len(tasks)), tasks, rotation=30, ha="right")
    ax.set_ylabel(f"success, % of {results['config']['episodes']} episodes")
    ax.set_ylim(0, 105)
    seeds = results["config"]["seeds"]
    ax.set_title(f"MetaWorld success per task and method (mean over training seeds {seeds})", pad=28)
    # Above the axes, so no bar is hidden behind it.
    ax.legend(fontsize=8, ncol=len(methods), loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


BUDGET_METHODS = ["student-1", "student-2", "teacher", "dp-ddim-10", "dp-ddpm-100"]


def budget_line(tables: dict, instructions: dict | None) -> str | None:
    """Overall success against the Cortex-M4 instructions one chunk of each method costs."""
    if not instructions:
        return None
    parts = []
    for m in BUDGET_METHODS:
        p = tables["overall"][m]
        if p["episodes"] and m in instructions:
            parts.append(f"{m} {100 * p['success_rate']:.1f} % at {instructions[m] / 1e6:.2f} M")
    return "; ".join(parts) if parts else None


def write(results: dict, md_path: Path, command: str, notes: list, instructions: dict | None = None) -> dict:
    """Writes results.md beside results.json and the PNG; returns the JSON written. `instructions`:
    Cortex-M4 instructions per chunk of each method (the budget line)."""
    cfg = results["config"]
    tables = summarize(results)
    spread, checks = seed_spread(results), targets(tables, results)
    budget = budget_line(tables, instructions)
    out = {**results, "tables": tables, "seed_spread": spread, "per_task": per_task(results),
           "targets": [{"target": t, "measured": v, "met": ok} for t, v, ok in checks],
           "instructions_per_chunk": instructions, "command": command, "commit": commit(), "notes": notes}
    json_path, png_path = md_path.with_suffix(".json"), md_path.with_suffix(".png")
    json_path.write_text(json.dumps(out, indent=1) + "\n")
    bar_chart(results, png_path)
    lines = [f"# MetaWorld benchmark results{' (QUICK MODE: pipeline check, not results)' if cfg['quick'] else ''}", ""]
    lines += ["Produced by:", "", "```sh", command, "```", "",
              f"Commit {out['commit']}; training seeds {cfg['seeds']} for every task"
              + (f", plus seeds {cfg['multi_seeds']} for {', '.join(cfg['multi_seed_tasks'])}" if cfg["multi_seed_tasks"] else "")
              + f"; {cfg['demos']} demonstrations per task; {cfg['episodes']} evaluation episodes per task and method "
              "(seeds 2^63 + 0 .., disjoint from the demonstrations' seeds 0 ..); backbone "
              f"`{cfg['backbone'] or 'mlp (frmd train default)'}`; training steps {cfg['train_steps'] or 'CLI default'} (teacher, DP), "
              f"{cfg['student_steps'] or cfg['train_steps'] or 'CLI default'} (student).", ""]
    lines += [f"- {n}" for n in notes] + [""]
    lines += ["Success: % of episodes [95 % Wilson interval] pooled over the group's tasks and training seeds; "
              "latency: median over task-seeds of the median policy time per chunk (`policy_ns` reported by `frmd "
              "serve`, the expert's call in process), us; non-smooth: end-effector non-smooth transitions per "
              "episode (mean) and per control step (pooled).", ""]
    if checks:
        lines += ["## Targets (overall table)", "", "| target | measured | met |", "| --- | --- | --- |"]
        lines += [f"| {t} | {v} | {'yes' if ok else 'NO'} |" for t, v, ok in checks] + [""]
    if budget:
        lines += ["## Success per instruction budget", "",
                  "Overall success against Cortex-M4 instructions per chunk (QEMU; see the notes for how each "
                  f"method's count was obtained): {budget}.", ""]
    for group, table in tables.items():
        lines += [f"## {group}", "", "| method | tasks | task-seeds | success % [95 % CI] | latency us/chunk | "
                  "non-smooth / episode | non-smooth / step |", "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
        for m in table:
            p = table[m]
            lines.append(f"| {m} | {p['tasks']} | {p['runs']} | {_pct(p)} | {_num(p['latency_us_median'])} | "
                         f"{_num(p['non_smooth_ee_mean'])} | {_num(p['non_smooth_per_step'], '{:.3f}')} |")
        lines.append("")
    mean_by_task = per_task(results)
    methods = methods_of(results["config"])
    if mean_by_task:
        lines += ["## Per task (mean success % over training seeds)", "",
                  "| task | group | " + " | ".join(methods) + " |", "| --- | --- | " + " | ".join("---:" for _ in methods) + " |"]
        for task, by_method in mean_by_task.items():
            lines.append(f"| {task} | {GROUP_OF[task]} | " + " | ".join(
                f"{100 * by_method[m]:.1f}" if m in by_method else "-" for m in methods) + " |")
        lines.append("")
    if spread:
        lines += ["## Spread over training seeds", "", "| task | method | seeds | mean success % | min | max |",
                  "| --- | --- | ---: | ---: | ---: | ---: |"]
        lines += [f"| {x['task']} | {x['method']} | {x['seeds']} | {100 * x['mean']:.1f} | {100 * x['min']:.1f} | "
                  f"{100 * x['max']:.1f} |" for x in spread] + [""]
    lines += ["## Per task and seed", "", "| task | group | seed | method | success % [95 % CI] | latency us/chunk | "
              "round trip us | non-smooth / episode | mean length |", "| --- | --- | ---: | --- | ---: | ---: | ---: | ---: | ---: |"]
    for r in results["rows"]:
        lo, hi = r["success_ci95"]
        lines.append(f"| {r['task']} | {r['group']} | {'-' if r['seed'] is None else r['seed']} | {r['method']} | "
                     f"{100 * r['success_rate']:.1f} [{100 * lo:.1f}, {100 * hi:.1f}] | {r['latency_us_median']:.1f} | "
                     f"{_num(r['roundtrip_us_median'])} | {r['non_smooth_ee_mean']:.1f} | {r['mean_length']:.1f} |")
    lines += ["", f"![success per task and method]({png_path.name})", ""]
    md_path.write_text("\n".join(lines) + "\n")
    return out


def quick_check(written: dict, md_path: Path) -> None:
    """--quick: every method has a valid report for every task, and the files parse."""
    cfg = written["config"]
    expected = {(t, m) for t in cfg["tasks"] for m in methods_of(cfg)}
    got = {(r["task"], r["method"]) for r in written["rows"]}
    if expected - got:
        raise SystemExit(f"quick mode: missing reports {sorted(expected - got)}")
    json.loads(md_path.with_suffix(".json").read_text())
    png = md_path.with_suffix(".png").read_bytes()
    if not png.startswith(b"\x89PNG"):
        raise SystemExit("quick mode: the bar chart is not a PNG")
    if "## overall" not in md_path.read_text():
        raise SystemExit("quick mode: results.md lacks the overall table")
