"""results.md, results.json and the bar chart of a benchmark run (benchmark.py): one table per
difficulty group and overall (success with 95 % Wilson interval over the episodes pooled over
tasks and training seeds, median latency per chunk, non-smooth transitions per episode and per
step), success per task (mean over seeds), the spread over training seeds, success against the
firmware instructions a chunk costs, seeds, command, commit, and the targets checked against the
numbers."""
from __future__ import annotations

from pathlib import Path

from frmd_client import metrics
from frmd_client import report as shared
from frmd_client.report import pooled  # noqa: F401 (this module's name before)
from .benchmark import METHODS, OPTIONAL_METHODS, BenchConfig  # noqa: F401
from .tasks import GROUP_OF, GROUPS, TASKS


def methods_of(config: dict) -> list:
    """The methods a run evaluated (its config's `int16` adds int16-student, `only` selects), in
    table order."""
    only = config.get("only")
    return [m for m in METHODS if (m not in OPTIONAL_METHODS or config.get("int16"))
            and (only is None or m in only)]

def commit() -> str:
    return shared.commit(Path(__file__).resolve().parent)


def summarize(results: dict) -> dict:
    """Group and overall tables over every training seed of the run (and the expert)."""
    return shared.summarize(results["rows"], GROUPS, methods_of(results["config"]))


def per_task(results: dict) -> dict:
    """task -> method -> mean success over the training seeds that have a report."""
    return shared.per_task(results["rows"], TASKS, methods_of(results["config"]))


def seed_spread(results: dict) -> list:
    """Per task trained with several seeds and per learned method: mean, min and max success."""
    return shared.seed_spread(results["rows"], TASKS, methods_of(results["config"])[1:])


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


def bar_chart(results: dict, path: Path) -> None:
    seeds = results["config"]["seeds"]
    shared.bar_chart(per_task(results), TASKS, methods_of(results["config"]), path,
                     f"success, % of {results['config']['episodes']} episodes",
                     f"MetaWorld success per task and method (mean over training seeds {seeds})")


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
    shared.write_json(json_path, out)
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
    lines += shared.targets_md(checks)
    if budget:
        lines += ["## Success per instruction budget", "",
                  "Overall success against Cortex-M4 instructions per chunk (QEMU; see the notes for how each "
                  f"method's count was obtained): {budget}.", ""]
    lines += shared.group_tables_md(tables)
    lines += shared.per_task_md(per_task(results), methods_of(results["config"]), GROUP_OF)
    lines += shared.spread_md(spread)
    lines += shared.per_seed_md(results["rows"])
    lines += ["", f"![success per task and method]({png_path.name})", ""]
    shared.write_text(md_path, "\n".join(lines) + "\n")
    return out


def quick_check(written: dict, md_path: Path) -> None:
    """--quick: every method has a valid report for every task, and the files parse."""
    cfg = written["config"]
    shared.quick_check(written, md_path, {(t, m) for t in cfg["tasks"] for m in methods_of(cfg)})
