"""The ManiSkill benchmark (issue 23, the paper's Table 3): per task, make the demonstrations
(motion planner, replayed to state observations); per task and training seed, train teacher,
student and DP with `frmd train` (the CLI's recipe), export the student with int8 and with int16
activations, and evaluate DP DDPM-100 and DDIM-10, the teacher, the one- and two-step student and
both exports through `frmd serve`; then report.py writes results.md, results.json and the chart.

Every step writes its output atomically and is skipped when that output exists (resumable), with
one progress line per step and each command's output in OUT/logs/STEP.log (frmd_client.runner).
`--quick` is the CI mode: one task, 3 demonstrations, one episode per method, 20 training steps,
and a validity check of every report (no success threshold).
"""
from __future__ import annotations

import json
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path

from frmd_client.report import row_of, write_json
from frmd_client.runner import StepRunner, check_report

from .tasks import CONTROLLER, GROUP_OF, GROUPS, TASKS, check_task

METHODS = ["dp-ddpm-100", "dp-ddim-10", "teacher", "student-1", "student-2", "int8-student", "int16-student"]
SERVE = {"dp-ddpm-100": "--ckpt {run}/dp --steps 100", "dp-ddim-10": "--ckpt {run}/dp --steps 10",
         "teacher": "--ckpt {run}/teacher", "student-1": "--ckpt {run}/student --steps 1",
         "student-2": "--ckpt {run}/student --steps 2", "int8-student": "--baked {run}/baked",
         "int16-student": "--baked {run}/baked16"}


@dataclass
class BenchConfig:
    """One benchmark run; the defaults are issue 23's: every task, 100 demonstrations, training
    seeds 0, 1, 2 for the hard group and 0 for the others, 50 evaluation episodes."""
    tasks: list = field(default_factory=lambda: list(TASKS))
    seeds: list = field(default_factory=lambda: [0])
    hard_seeds: list = field(default_factory=lambda: [0, 1, 2])
    demos: int = 100
    controller: str = CONTROLLER
    episodes: int = 50
    only: list | None = None
    in_process: bool = False
    backbone: str | None = None
    train_steps: int | None = None
    student_steps: int | None = None
    data_dir: str = "data"
    out: str = "runs/maniskill"
    frmd: str = "frmd"
    quick: bool = False

    @staticmethod
    def quick_config(**overrides) -> "BenchConfig":
        cfg = BenchConfig(tasks=["PickCube-v1"], seeds=[0], hard_seeds=[0], demos=3, episodes=1, train_steps=20,
                          student_steps=10, quick=True)
        for key, value in overrides.items():
            setattr(cfg, key, value)
        return cfg

    def methods(self) -> list:
        return [m for m in METHODS if self.only is None or m in self.only]

    def seeds_of(self, task: str) -> list:
        return self.hard_seeds if GROUP_OF[task] == "hard" else self.seeds

    def runs(self):
        """(task, seed) pairs in run order: every task's first seed, then the extra seeds."""
        for task in self.tasks:
            yield task, self.seeds_of(task)[0]
        for task in self.tasks:
            for seed in self.seeds_of(task)[1:]:
                yield task, seed


class Runner(StepRunner):
    def __init__(self, cfg: BenchConfig):
        self.cfg = cfg
        self.python = sys.executable
        super().__init__(cfg.out, [str(Path(__file__).resolve().parent.parent)])

    def data(self, task: str) -> Path:
        cfg = self.cfg
        path = Path(cfg.data_dir) / f"{task}.{cfg.controller}.safetensors"
        path.parent.mkdir(parents=True, exist_ok=True)
        self.run(f"{task}-demos", path, [self.python, "-m", "frmd_maniskill", "demos", "--task", task, "--episodes",
                                         str(cfg.demos), "--controller", cfg.controller, "--out", str(path)])
        return path

    def train(self, task: str, seed: int, data: Path) -> Path:
        cfg, f = self.cfg, self.cfg.frmd
        run = self.out / task / f"seed{seed}"
        common = ["--data", str(data), "--seed", str(seed)] + (["--backbone", cfg.backbone] if cfg.backbone else [])
        quick = ["--warmup", "2", "--log-every", "5"] if cfg.quick else []
        steps = (["--steps", str(cfg.train_steps)] if cfg.train_steps else []) + quick
        student = (["--steps", str(cfg.student_steps or cfg.train_steps)] if (cfg.student_steps or cfg.train_steps)
                   else []) + quick
        methods = cfg.methods()
        self.run(f"{task}-s{seed}-teacher", run / "teacher" / "frmd.json",
                 [f, "train", "teacher", *common, *steps, "--out", str(run / "teacher")])
        if any(m.startswith("student") or m.endswith("-student") for m in methods):
            self.run(f"{task}-s{seed}-student", run / "student" / "frmd.json",
                     [f, "train", "student", "--teacher", str(run / "teacher"), "--data", str(data), "--seed",
                      str(seed), *student, "--out", str(run / "student")])
        if any(m.startswith("dp-") for m in methods):
            self.run(f"{task}-s{seed}-dp", run / "dp" / "frmd.json", [f, "train", "dp", *common, *steps, "--out",
                                                                      str(run / "dp")])
        for method, bits, out in (("int8-student", "int8", "baked"), ("int16-student", "int16", "baked16")):
            if method in methods:
                self.run(f"{task}-s{seed}-export-{bits}", run / out / "export.json",
                         [f, "export", "--ckpt", str(run / "student"), "--out", str(run / out), "--activations", bits])
        return run

    def evaluate(self, task: str, seed: int, run: Path) -> None:
        for method in self.cfg.methods():
            report = run / "eval" / f"{method}.json"
            report.parent.mkdir(parents=True, exist_ok=True)
            server = f"{self.cfg.frmd} serve " + SERVE[method].format(run=run)
            self.run(f"{task}-s{seed}-eval-{method}", report,
                     [self.python, "-m", "frmd_maniskill", "eval", "--task", task, "--episodes", str(self.cfg.episodes),
                      "--controller", self.cfg.controller, "--server", server, "--json", str(report)]
                     + (["--in-process"] if self.cfg.in_process else []))
            check_report(report, task, self.cfg.episodes)

    def all(self) -> dict:
        for task in self.cfg.tasks:
            check_task(task)
        write_json(self.out / "config.json", asdict(self.cfg))
        for task, seed in self.cfg.runs():
            data = self.data(task)
            self.evaluate(task, seed, self.train(task, seed, data))
        return collect_results(self.cfg)


def demo_stats(cfg: BenchConfig) -> dict:
    """task -> the statistics `demos` wrote beside each dataset (planner success, lengths, ...)."""
    out = {}
    for task in cfg.tasks:
        path = Path(cfg.data_dir) / f"{task}.{cfg.controller}.json"
        if path.exists():
            out[task] = json.loads(path.read_text())
    return out


def collect_results(cfg: BenchConfig) -> dict:
    """Every finished report of the run."""
    rows = []
    for task, seed in cfg.runs():
        for method in METHODS:
            path = Path(cfg.out) / task / f"seed{seed}" / "eval" / f"{method}.json"
            if path.exists():
                rows.append(row_of(json.loads(path.read_text()), task, GROUP_OF[task], seed, method, path))
    return {"config": asdict(cfg), "rows": rows, "demos": demo_stats(cfg), "groups": GROUPS}
