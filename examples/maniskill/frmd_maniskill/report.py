"""results.md, results.json and the success chart of a ManiSkill benchmark run, grouped like the
paper's Table 3 (easy, medium, hard, overall; success pooled over tasks and training seeds with a
95 % Wilson interval, latency, non-smooth transitions per episode and per step), with the paper's
numbers beside ours where the paper gives them, the demonstrations, issue 23's targets, success
per task, the spread over seeds and every report. The tables come from frmd_client.report."""
from __future__ import annotations

from pathlib import Path

from frmd_client import report as shared

from .benchmark import METHODS, BenchConfig  # noqa: F401
from .tasks import GROUP_OF, GROUPS, ISSUE_TASKS, TASKS

# The paper trained on RGB images: its numbers are context, not a like-for-like comparison.
# Success %, as issue 23 quotes the hard group (MPD = the ProDMP diffusion teacher, FRMD = the
# one-step student) and issue 13 the overall row of its 12 MetaWorld and ManiSkill tasks together.
PAPER_GROUP = {"hard": {"teacher": 28.6, "student-1": 29.0}}
PAPER_OVERALL = {"student-1": 64.8, "teacher": 64.1, "dp-ddpm-100": 50.1}


def methods_of(config: dict) -> list:
    only = config.get("only")
    return [m for m in METHODS if only is None or m in only]


def targets(tables: dict, results: dict) -> list:
    """Issue 23's targets on the numbers: (what, measured, met)."""
    cfg, rows = results["config"], results["rows"]
    checks = []
    # Over every task of the benchmark, not only the run's --task: a partial run does not meet it.
    missing = [(t, m) for t in TASKS for m in METHODS if not any(r["task"] == t and r["method"] == m for r in rows)]
    checks.append(("every task has a row for every method", f"{len(missing)} (task, method) pairs missing"
                   + (f", e.g. {missing[0][0]} {missing[0][1]}" if missing else ""), not missing))
    hard = {m: p for m, p in tables["hard"].items() if p["episodes"]}
    if {"student-1", "teacher"} <= hard.keys():
        d = 100 * (hard["student-1"]["success_rate"] - hard["teacher"]["success_rate"])
        checks.append(("hard group: one-step student >= teacher - 2 points", f"{d:+.1f} points", d >= -2.0 - 1e-9))
    if {"student-1", "dp-ddpm-100"} <= hard.keys():
        d = 100 * (hard["student-1"]["success_rate"] - hard["dp-ddpm-100"]["success_rate"])
        checks.append(("hard group: one-step student >= DP DDPM-100", f"{d:+.1f} points", d >= -1e-9))
    worse = []
    compared = 0
    for task in TASKS:
        per = {m: shared.pooled([r for r in rows if r["task"] == task and r["method"] == m])
               for m in ("student-1", "dp-ddpm-100")}
        if all(p["episodes"] for p in per.values()):
            compared += 1
            s, d = per["student-1"]["non_smooth_per_step"], per["dp-ddpm-100"]["non_smooth_per_step"]
            if s is not None and d is not None and s > d:
                worse.append(f"{task} {s:.3f} > {d:.3f}")
    if compared:
        checks.append(("non-smooth transitions per step: one-step student <= DP DDPM-100 on every task",
                       f"{compared - len(worse)} of {compared} tasks" + (f"; not on {', '.join(worse)}" if worse else ""),
                       not worse))
    return checks


def paper_md(tables: dict) -> list:
    lines = ["## Beside the paper", "",
             "The paper trained on RGB images; these runs observe ManiSkill's state vector on 2 CPU cores, so "
             "compare methods within a column, not the columns. The paper's per-task ManiSkill numbers were not "
             "available to this run: issue 23 quotes its hard group, issue 13 its overall row (the paper's 12 "
             "MetaWorld and ManiSkill tasks together).", "",
             "| group | method | ours: success % | paper: success % |", "| --- | --- | ---: | ---: |"]
    for group, by_method in PAPER_GROUP.items():
        for m, paper in by_method.items():
            lines.append(f"| {group} | {m} | {shared.pct(tables[group][m])} | {paper:.1f} |")
    for m, paper in PAPER_OVERALL.items():
        if m in tables["overall"]:
            lines.append(f"| overall | {m} | {shared.pct(tables['overall'][m])} | {paper:.1f} |")
    return lines + [""]


def demos_md(demos: dict) -> list:
    if not demos:
        return []
    lines = ["## Demonstrations (motion planner, replayed to state observations)", "",
             "| task | group | demos | seeds tried | planner failed | replay failed | mean length | longest | s |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for task, s in demos.items():
        lines.append(f"| {task} | {GROUP_OF[task]} | {s['episodes']} | {s['seeds_tried']} | {s['planner_failed']} | "
                     f"{s['replay_failed']} | {s['mean_length']:.1f} | {s['max_length']} | {s['seconds']:.0f} |")
    return lines + [""]


def write(results: dict, md_path: Path, command: str, notes: list) -> dict:
    cfg, rows = results["config"], results["rows"]
    methods = methods_of(cfg)
    tables = shared.summarize(rows, GROUPS, methods)
    mean_by_task = shared.per_task(rows, TASKS, methods)
    spread = shared.seed_spread(rows, TASKS, methods)
    checks = targets(tables, results)
    here = Path(__file__).resolve().parent
    out = {**results, "tables": tables, "per_task": mean_by_task, "seed_spread": spread,
           "targets": [{"target": t, "measured": v, "met": ok} for t, v, ok in checks],
           "paper": {"groups": PAPER_GROUP, "overall": PAPER_OVERALL}, "command": command,
           "commit": shared.commit(here), "notes": notes}
    shared.write_json(md_path.with_suffix(".json"), out)
    png = md_path.with_suffix(".png")
    shared.bar_chart(mean_by_task, TASKS, methods, png, f"success, % of {cfg['episodes']} episodes",
                     f"ManiSkill3 (state observations) success per task and method, mean over training seeds")
    lines = [f"# ManiSkill3 benchmark results{' (QUICK MODE: pipeline check, not results)' if cfg['quick'] else ''}",
             "", "Produced by:", "", "```sh", command, "```", "",
             f"Commit {out['commit']}; controller `{cfg['controller']}`; state observations; training seeds "
             f"{cfg['hard_seeds']} for the hard group, {cfg['seeds']} for the others; {cfg['demos']} demonstrations "
             f"per task; {cfg['episodes']} evaluation episodes per task, seed and method (seeds 2^31 + 0 .., disjoint "
             "from the demonstrations' seeds 0 ..); backbone "
             f"`{cfg['backbone'] or 'mlp (frmd train default)'}`; training steps {cfg['train_steps'] or 'CLI default'} "
             f"(teacher, DP), {cfg['student_steps'] or cfg['train_steps'] or 'CLI default'} (student). Tasks named by "
             f"issue 23: {', '.join(ISSUE_TASKS)}; the others are the remaining tasks whose motion planner works.", ""]
    lines += [f"- {n}" for n in notes] + [""]
    lines += ["Success: % of episodes [95 % Wilson interval] pooled over the group's tasks and training seeds "
              "(ManiSkill's success flag at some step); latency: median over task-seeds of the median policy time "
              "per chunk (`policy_ns` of `frmd serve`), us; non-smooth: end-effector (tool centre point) non-smooth "
              "transitions per episode (mean) and per control step (pooled).", ""]
    lines += shared.targets_md(checks, "## Targets (issue 23)")
    lines += shared.group_tables_md(tables)
    lines += paper_md(tables)
    lines += demos_md(results.get("demos", {}))
    lines += shared.per_task_md(mean_by_task, methods, GROUP_OF)
    lines += shared.spread_md(spread)
    lines += shared.per_seed_md(rows)
    lines += ["", f"![success per task and method]({png.name})", ""]
    shared.write_text(md_path, "\n".join(lines) + "\n")
    return out


def quick_check(written: dict, md_path: Path) -> None:
    cfg = written["config"]
    shared.quick_check(written, md_path, {(t, m) for t in cfg["tasks"] for m in methods_of(cfg)})
