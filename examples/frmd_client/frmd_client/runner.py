"""Resumable benchmark steps: each step is a command whose output file marks it done, so a
rerun of the same benchmark skips what exists and continues where it stopped. Each command's
output goes to OUT/logs/NAME.log; the console gets one progress line per step. `check_report`
validates an evaluation report before the step counts as done."""
from __future__ import annotations

import json
import os
import shlex
import subprocess
import time
from pathlib import Path

from .evaluation import EPISODE_FIELDS, FRMD_EVAL_FIELDS

SHARED_ROOT = str(Path(__file__).resolve().parent.parent)  # the directory that holds frmd_client


class StepFailed(Exception):
    pass


class StepRunner:
    """Runs benchmark steps under `out` with logs; `python_path`: directories the steps' Python
    processes import from (this package's is added)."""

    def __init__(self, out, python_path: list | None = None):
        self.out = Path(out)
        self.logs = self.out / "logs"
        self.logs.mkdir(parents=True, exist_ok=True)
        self.python_path = os.pathsep.join(list(python_path or []) + [SHARED_ROOT])
        self.started = time.perf_counter()

    def say(self, text: str) -> None:
        print(f"[{time.perf_counter() - self.started:7.0f} s] {text}", flush=True)

    def run(self, name: str, done: Path, argv: list, env_extra: dict | None = None) -> None:
        """Runs `argv` unless `done` exists; output to logs/NAME.log; fails on a non-zero status
        or when the command did not write `done`."""
        if done.exists():
            self.say(f"{name}: done earlier ({done})")
            return
        log = self.logs / f"{name}.log"
        env = {**os.environ, "RAYON_NUM_THREADS": os.environ.get("RAYON_NUM_THREADS", "1"),
               "PYTHONPATH": self.python_path, **(env_extra or {})}
        self.say(f"{name}: running (log {log})")
        t0 = time.perf_counter()
        with open(log, "w") as f:
            f.write("$ " + shlex.join(argv) + "\n")
            f.flush()
            status = subprocess.call(argv, stdout=f, stderr=subprocess.STDOUT, env=env)
        if status != 0:
            raise StepFailed(f"{name} failed with status {status}; see {log}")
        if not done.exists():
            raise StepFailed(f"{name} finished but {done} is missing; see {log}")
        self.say(f"{name}: finished in {time.perf_counter() - t0:.0f} s")


def check_report(path: Path, task: str, episodes: int) -> dict:
    """The fields and ranges `frmd eval --json` promises; raises StepFailed naming the file and
    every problem otherwise."""
    try:
        report = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise StepFailed(f"{path}: unreadable report: {e}") from None
    missing = [k for k in FRMD_EVAL_FIELDS if k not in report]
    problems = []
    if missing:
        problems.append(f"missing fields {missing}")
    if report.get("task") != task:
        problems.append(f"task {report.get('task')!r}, expected {task!r}")
    if report.get("episodes") != episodes or len(report.get("per_episode", [])) != episodes:
        problems.append(f"episodes {report.get('episodes')}, expected {episodes}")
    rate = report.get("success_rate")
    if not (isinstance(rate, (int, float)) and 0 <= rate <= 1):
        problems.append(f"success_rate {rate!r} outside [0, 1]")
    lo, hi = report.get("success_ci95", [None, None])
    if not (isinstance(lo, (int, float)) and 0 <= lo <= (rate or 0) <= hi <= 1):
        problems.append(f"success_ci95 {[lo, hi]} does not bracket {rate}")
    if not report.get("latency_us_median", -1) >= 0:
        problems.append("latency_us_median is not a non-negative number")
    for i, ep in enumerate(report.get("per_episode", [])):
        if [k for k in EPISODE_FIELDS if k not in ep]:
            problems.append(f"episode {i} lacks fields")
            break
    if problems:
        raise StepFailed(f"{path}: invalid report: {'; '.join(problems)}")
    return report


def load_previous(path: Path) -> dict:
    """An earlier results.json (for `--previous`), checked before any step runs: raises StepFailed
    naming the file and what is wrong."""
    try:
        previous = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise StepFailed(f"--previous {path}: unreadable results file: {e}") from None
    rows = previous.get("rows") if isinstance(previous, dict) else None
    keys = ("task", "seed", "method", "episodes", "successes")
    if not isinstance(rows, list) or not all(isinstance(r, dict) and all(k in r for k in keys) for r in rows):
        raise StepFailed(f"--previous {path}: expected a results.json with a 'rows' list whose rows have "
                         f"{', '.join(keys)}")
    return previous


def carry_over(results: dict, previous: dict, cfg) -> int:
    """Adds to `results` the rows of `previous` (an earlier results.json) for the configured
    task-seeds and methods that have no report under OUT (e.g. runs made on another machine, whose
    files are gone), and the demonstration statistics of tasks without any here. Each carried row
    keeps the report path recorded in `previous`. Returns how many rows were added."""
    runs = set(cfg.runs())
    methods = set(cfg.methods())
    have = {(r["task"], r["seed"], r["method"]) for r in results["rows"]}
    carried = [r for r in previous["rows"] if (r["task"], r["seed"], r["method"]) not in have
               and (r["task"], r["seed"]) in runs and r["method"] in methods]
    results["rows"].extend(carried)
    demos = results.setdefault("demos", {})
    for task, stats in (previous.get("demos") or {}).items():
        demos.setdefault(task, stats)
    return len(carried)


def run_and_report(runner, cfg, collect_results, write_report, quick_check, md: Path, command: str,
                   notes: list, report_only: bool = False, quick: bool = False,
                   previous: Path | None = None) -> int:
    """A simulator package's `benchmark` command after its options: runs every step (unless
    `report_only`), then writes the report of whatever exists, noting an early stop and the task-seeds
    without reports; the quick mode checks the written reports. 1 if a step failed, else 0.
    `write_report(results, md, command, notes)` returns what `quick_check(written, md)` checks.
    `previous`: an earlier results.json whose rows fill in the runs without a report here
    ([`carry_over`]; noted in the report)."""
    import sys
    try:
        earlier = load_previous(previous) if previous else None
    except StepFailed as e:
        print(e, file=sys.stderr, flush=True)
        return 2
    failed = None
    if report_only:
        results = collect_results(cfg)
    else:
        try:
            results = runner.all()
        except StepFailed as e:
            failed = str(e)
            print(f"benchmark stopped: {failed}", file=sys.stderr, flush=True)
            results = collect_results(cfg)
    notes = list(notes)
    if earlier is not None:
        carried = carry_over(results, earlier, cfg)
        notes.append(f"{carried} of the {len(results['rows'])} reports are carried over from {previous} (runs "
                     "without a report under the run directory; each row names the report file it was read from "
                     "when that results file was written).")
    if failed:
        notes.append(f"The run stopped early: {failed}")
    missing = sorted({(task, seed) for task, seed in cfg.runs()}
                     - {(r["task"], r["seed"]) for r in results["rows"] if r["seed"] is not None})
    if missing:
        notes.append("INCOMPLETE: no trained-model reports for " + ", ".join(f"{t} seed {s}" for t, s in missing)
                     + "; the group and overall rows cover only the tasks that have them. The same "
                     "command without --report-only resumes the run.")
    written = write_report(results, md, command, notes)
    runner.say(f"wrote {md}, {md.with_suffix('.json')}, {md.with_suffix('.png')} ({len(results['rows'])} reports)")
    if quick and not failed:
        quick_check(written, md)
        runner.say("quick mode: every report is valid")
    return 1 if failed else 0
