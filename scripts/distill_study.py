#!/usr/bin/env python3
"""The distillation development set: student variants trained from fixed teachers, side by side.

    python3 scripts/distill_study.py run   --runs RUNS [--variants FILE] [--only A,B] [--jobs 2]
    python3 scripts/distill_study.py table --runs RUNS [--variants FILE] [--out DIR]

`run` collects the demonstrations and trains one teacher per task and training seed (the
recipe's: `mlp-paper` on the built-in tasks, the CLI's default backbone on MetaWorld, as README
and examples/metaworld/README.md train them), evaluates each teacher, then for every variant of
the variants file (a name and the flags it adds to `frmd train student`) distills a student from
each teacher and evaluates it on the same evaluation seeds. Every step writes its output
atomically and is skipped when that output exists, so a rerun resumes; the logs go to RUNS/logs.
`table` writes results.md and results.json (success mean and spread over training seeds,
non-smooth transitions per step, training time) and copies each evaluation's summary to
DIR/reports. Needs a built `frmd` (`--frmd`, default target/release/frmd) and, for MetaWorld,
`bash examples/metaworld/setup.sh`.
"""
from __future__ import annotations

import argparse
import concurrent.futures as futures
import json
import os
import shlex
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MW_DIR = ROOT / "examples" / "metaworld"
MW_TASKS = ["reach-v3", "push-v3", "pick-place-v3", "peg-insert-side-v3", "assembly-v3", "hammer-v3"]
BUILTIN_TASKS = ["avoid", "insert"]
DEV_TASKS = MW_TASKS + BUILTIN_TASKS
SEEDS = [0, 1]
EPISODES = 100
DEMOS = 100


def is_mw(task: str) -> bool:
    return task.endswith("-v3")


class Study:
    def __init__(self, args):
        self.runs = Path(args.runs).resolve()
        self.frmd = str(Path(args.frmd).resolve()) if os.sep in args.frmd else args.frmd
        self.python = str(MW_DIR / ".venv" / "bin" / "python")
        self.tasks = args.tasks
        self.seeds = args.seeds
        self.episodes = args.episodes
        self.logs = self.runs / "logs"
        self.logs.mkdir(parents=True, exist_ok=True)
        self.lock = threading.Lock()
        self.started = time.time()
        self.failures: list[str] = []

    def say(self, text: str) -> None:
        with self.lock:
            print(f"[{time.time() - self.started:7.0f} s] {text}", flush=True)

    def claim(self, name: str, done: Path) -> Path | None:
        """The step's lock file in RUNS/locks, once no other live process holds it (several study
        processes may share RUNS); None when `done` appeared meanwhile."""
        lock = self.runs / "locks" / f"{name}.lock"
        lock.parent.mkdir(parents=True, exist_ok=True)
        while not done.exists():
            try:
                fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:
                try:
                    pid = int(lock.read_text() or 0)
                    os.kill(pid, 0)
                except (ValueError, ProcessLookupError, FileNotFoundError):
                    lock.unlink(missing_ok=True)  # its process is gone
                    continue
                except PermissionError:
                    pass
                time.sleep(20)
                continue
            os.write(fd, str(os.getpid()).encode())
            os.close(fd)
            if done.exists():
                lock.unlink()
                return None
            return lock
        return None

    def step(self, name: str, done: Path, argv: list, cwd: Path | None = None, retry_dir: Path | None = None) -> None:
        """Runs `argv` unless `done` exists; a half-written checkpoint dir is replaced (--force)."""
        if done.exists():
            return
        lock = self.claim(name, done)
        if lock is None:
            return
        try:
            self.execute(name, done, argv, cwd, retry_dir)
        finally:
            lock.unlink(missing_ok=True)

    def execute(self, name: str, done: Path, argv: list, cwd: Path | None, retry_dir: Path | None) -> None:
        if retry_dir is not None and retry_dir.exists() and any(retry_dir.iterdir()):
            argv = [*argv, "--force"]
        log = self.logs / f"{name}.log"
        env = {**os.environ, "RAYON_NUM_THREADS": "1", "PYTHONPATH": str(MW_DIR)}
        self.say(f"{name}: running")
        t0 = time.time()
        with open(log, "w") as f:
            f.write("$ " + shlex.join(argv) + "\n")
            f.flush()
            status = subprocess.call(argv, stdout=f, stderr=subprocess.STDOUT, env=env, cwd=cwd)
        if status != 0 or not done.exists():
            raise RuntimeError(f"{name} failed (status {status}); see {log}")
        self.say(f"{name}: finished in {time.time() - t0:.0f} s")

    def data(self, task: str) -> Path:
        path = self.runs / "data" / f"{task}.safetensors"
        path.parent.mkdir(parents=True, exist_ok=True)
        if is_mw(task):
            argv = [self.python, "-m", "frmd_metaworld", "collect", "--task", task, "--episodes", str(DEMOS),
                    "--out", str(path)]
        else:
            argv = [self.frmd, "collect", "--task", task, "--episodes", str(DEMOS), "--out", str(path)]
        self.step(f"collect-{task}", path, argv, cwd=MW_DIR if is_mw(task) else None)
        return path

    def evaluate(self, name: str, task: str, ckpt: Path, report: Path, sampler: list) -> None:
        if is_mw(task):
            server = shlex.join([self.frmd, "serve", "--ckpt", str(ckpt), *sampler])
            argv = [self.python, "-m", "frmd_metaworld", "eval", "--task", task, "--episodes",
                    str(self.episodes), "--server", server, "--json", str(report)]
        else:
            argv = [self.frmd, "eval", "--task", task, "--ckpt", str(ckpt), *sampler, "--episodes",
                    str(self.episodes), "--json", str(report)]
        self.step(name, report, argv, cwd=MW_DIR if is_mw(task) else None)
        summarize(report, ckpt)

    def teacher(self, task: str, seed: int) -> Path:
        data = self.data(task)
        run = self.runs / "teachers" / task / f"s{seed}"
        ckpt = run / "teacher"
        backbone = [] if is_mw(task) else ["--backbone", "mlp-paper"]
        self.step(f"{task}-s{seed}-teacher", ckpt / "frmd.json",
                  [self.frmd, "train", "teacher", "--data", str(data), "--out", str(ckpt), "--seed", str(seed),
                   *backbone, "--eval-episodes", "0"], retry_dir=ckpt)
        self.evaluate(f"{task}-s{seed}-eval-teacher", task, ckpt, run / "eval-teacher.json", teacher_sampler(task))
        return ckpt

    def student(self, variant: dict, task: str, seed: int) -> None:
        teacher = self.runs / "teachers" / task / f"s{seed}" / "teacher"
        data = self.runs / "data" / f"{task}.safetensors"
        run = self.runs / "variants" / variant["name"] / task / f"s{seed}"
        ckpt = run / "student"
        tag = f"{variant['name']}-{task}-s{seed}"
        self.step(f"{tag}-student", ckpt / "frmd.json",
                  [self.frmd, "train", "student", "--teacher", str(teacher), "--data", str(data), "--out", str(ckpt),
                   "--seed", str(seed), "--eval-episodes", "0", *variant.get("flags", [])], retry_dir=ckpt)
        for steps in variant.get("steps", [1]):
            self.evaluate(f"{tag}-eval-{steps}", task, ckpt, run / f"eval-{steps}.json", ["--steps", str(steps)])

    def guarded(self, what: str, fn, *args) -> None:
        try:
            fn(*args)
        except Exception as e:  # one failed chain does not stop the others
            self.say(f"FAILED {what}: {e}")
            with self.lock:
                self.failures.append(f"{what}: {e}")

    def run(self, variants: list, jobs: int) -> int:
        pairs = [(t, s) for s in self.seeds for t in self.tasks]
        for t in self.tasks:  # collection is quick; do it once, in order
            self.guarded(f"collect {t}", self.data, t)
        with futures.ThreadPoolExecutor(jobs) as pool:
            list(pool.map(lambda p: self.guarded(f"teacher {p}", self.teacher, *p), pairs))
        chains = [(v, t, s) for v in variants for (t, s) in pairs if t in v.get("tasks", self.tasks)]
        with futures.ThreadPoolExecutor(jobs) as pool:
            list(pool.map(lambda c: self.guarded(f"{c[0]['name']} {c[1]} s{c[2]}", self.student, *c), chains))
        for f in self.failures:
            print("FAILED", f)
        return 1 if self.failures else 0


def teacher_sampler(task: str) -> list:
    """The teacher as each table evaluates it: DPM-Solver++(2M) 10 steps on the built-in tasks
    (README's recipe table), the server's default (Heun 10) on MetaWorld (results.md)."""
    return [] if is_mw(task) else ["--steps", "10", "--solver", "dpm++2m"]


def summarize(report: Path, ckpt: Path) -> dict:
    """A small summary beside an evaluation report (what the table reads)."""
    r = json.loads(report.read_text())
    meta = json.loads((ckpt / "frmd.json").read_text())
    training = meta.get("training", {})
    eps = r["per_episode"]
    summary = {
        "task": r["task"], "episodes": r["episodes"], "successes": r["successes"],
        "success_rate": r["success_rate"], "success_ci95": r["success_ci95"],
        "non_smooth_ee_total": sum(e["non_smooth_ee"] for e in eps),
        "steps_total": sum(e["length"] for e in eps),
        "train_seconds": training.get("seconds"),
        "distill": training.get("distill"),
        "policy": r.get("policy"),
    }
    out = report.with_suffix(".summary.json")
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps(summary, indent=1) + "\n")
    tmp.replace(out)
    return summary


def load_variants(path: Path, only: list | None) -> list:
    variants = json.loads(path.read_text())
    names = [v["name"] for v in variants]
    if len(set(names)) != len(names):
        sys.exit(f"{path}: variant names must be unique")
    for v in variants:
        if not isinstance(v.get("flags", []), list):
            sys.exit(f"{path}: variant {v['name']}: `flags` must be a list of strings")
    if only:
        unknown = [o for o in only if o not in names]
        if unknown:
            sys.exit(f"--only: no variant named {unknown} in {path} (have {names})")
        variants = [v for v in variants if v["name"] in only]
    return variants


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from distill_table import write_table  # noqa: E402

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("command", choices=["run", "table"])
    p.add_argument("--runs", required=True, help="directory for data, teachers, students and logs")
    p.add_argument("--variants", default=str(ROOT / "docs" / "results" / "distill" / "variants.json"))
    p.add_argument("--only", type=lambda s: s.split(","), help="comma-separated variant names")
    p.add_argument("--tasks", type=lambda s: s.split(","), default=DEV_TASKS)
    p.add_argument("--seeds", type=lambda s: [int(x) for x in s.split(",")], default=SEEDS)
    p.add_argument("--episodes", type=int, default=EPISODES)
    p.add_argument("--frmd", default=str(ROOT / "target" / "release" / "frmd"))
    p.add_argument("--jobs", type=int, default=1, help="chains run at once (one core each)")
    p.add_argument("--out", default=str(ROOT / "docs" / "results" / "distill"))
    a = p.parse_args()
    unknown = [t for t in a.tasks if t not in DEV_TASKS]
    if unknown:
        sys.exit(f"--tasks: {unknown} are not in the development set {DEV_TASKS}")
    variants = load_variants(Path(a.variants), a.only)
    # The table always has every variant of the file (--only selects what runs), over the whole
    # development set: rows measured in other run directories come from the committed reports.
    every = load_variants(Path(a.variants), None)
    if a.command == "run":
        if any(is_mw(t) for t in a.tasks) and not Path(Study(a).python).exists():
            sys.exit("MetaWorld needs its venv: bash examples/metaworld/setup.sh")
        status = Study(a).run(variants, max(1, a.jobs))
        write_table(Path(a.runs), every, DEV_TASKS, SEEDS, Path(a.out))
        sys.exit(status)
    write_table(Path(a.runs), every, DEV_TASKS, SEEDS, Path(a.out))
