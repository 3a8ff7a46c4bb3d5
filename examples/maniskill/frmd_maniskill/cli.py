"""Command line: python -m frmd_maniskill {tasks,check,demos,info,demo-metrics,eval,benchmark} ... (--help on each)."""
from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import time
from pathlib import Path

from .tasks import CONTROLLER, CONTROLLERS, GROUPS, TASKS


def _tasks(value: str) -> list:
    if value == "all":
        return list(TASKS)
    names = value.split(",")
    for name in names:
        if name not in TASKS:
            raise argparse.ArgumentTypeError(f"unknown task {name!r}; choose from: all, {', '.join(TASKS)}")
    return names


def _progress(label: str, total: int):
    """Progress on a terminal's standard error (silent in logs and pipes)."""
    if not sys.stderr.isatty():
        return None
    return lambda n, *rest: print(f"\r{label}: {n}/{total}" + (f" ({rest[0]} tried)" if rest and isinstance(rest[0], int)
                                                               else ""), end="", file=sys.stderr, flush=True)


def cmd_tasks(args) -> int:
    for group, names in GROUPS.items():
        print(f"{group}: {' '.join(names)}")
    return 0


def cmd_check(args) -> int:
    """Builds a scene and steps it: SAPIEN's Vulkan device, PhysX on the CPU, the state observation."""
    from .tasks import SeededEnv, package_versions
    started = time.perf_counter()
    env = SeededEnv("PickCube-v1")
    obs = env.reset(0)
    obs, _, _ = env.step(env.init_action())
    env.close()
    print(f"ManiSkill works: PickCube-v1 observation {len(obs)} floats, {env.action_dim} actions in {env.control_mode}, "
          f"{time.perf_counter() - started:.1f} s; {json.dumps(package_versions())}")
    return 0


def cmd_demos(args) -> int:
    from .demos import collect
    if len(args.task) > 1 and args.out:
        sys.exit("--out names one file; use --out-dir for several tasks")
    if not args.out and not args.out_dir:
        sys.exit("give --out FILE (one task) or --out-dir DIR")
    for task in args.task:
        path = Path(args.out) if args.out else Path(args.out_dir) / f"{task}.{args.controller}.safetensors"
        if path.exists() and not args.force:
            print(f"{task}: {path} exists, skipped (--force to redo)", flush=True)
            continue
        path.parent.mkdir(parents=True, exist_ok=True)
        data, stats = collect(task, args.episodes, args.seed, args.controller, args.max_tries,
                              progress=_progress(task, args.episodes))
        tmp = path.with_name(path.name + ".partial")
        data.save(tmp)
        stats.update(path=str(path), bytes=tmp.stat().st_size)
        from frmd_client.report import write_json
        write_json(path.with_suffix(".json"), stats)
        os.replace(tmp, path)
        print(json.dumps(stats), flush=True)
    return 0


def cmd_info(args) -> int:
    import numpy as np
    from frmd_client.dataset import Dataset
    for path in args.files:
        d = Dataset.load(path)
        lengths = np.diff(np.concatenate([[0], d.episode_ends]))
        print(json.dumps({"path": str(path), "task": d.task, "controller": d.extra.get("controller"),
                          "episodes": len(lengths), "steps": int(len(d.obs)), "obs_dim": d.obs.shape[1],
                          "action_dim": d.action.shape[1], "dt": d.dt, "mean_length": float(lengths.mean()),
                          "max_length": int(lengths.max()), "action_before_start": d.extra.get("action_before_start"),
                          "action_min": d.action.min(axis=0).round(3).tolist(),
                          "action_max": d.action.max(axis=0).round(3).tolist()}))
    return 0


def cmd_demo_metrics(args) -> int:
    from .evaluate import demo_metrics
    for path in args.files:
        print(json.dumps(demo_metrics(path, args.episodes)), flush=True)
    return 0


def cmd_eval(args) -> int:
    from frmd_client.evaluation import summary_line
    from frmd_client.policy_client import open_policy
    from frmd_client.report import write_json
    from .evaluate import evaluate
    from .tasks import DT, SeededEnv
    if args.in_process and not args.server:
        sys.exit("--in-process runs the policy of --server CMD in this process; give --server")
    if len(args.task) > 1 and args.json:
        sys.exit("--json names one file; use --json-dir for several tasks")
    for task in args.task:
        path = Path(args.json) if args.json else (Path(args.json_dir) / f"{task}-{args.label}.json" if args.json_dir
                                                  else None)
        env = SeededEnv(task, args.controller)
        policy = open_policy(args.server, args.in_process, dt=DT)
        started = time.perf_counter()
        try:
            report = evaluate(task, policy, args.episodes, args.first_seed, args.exec_steps,
                              progress=_progress(task, args.episodes), env=env)
        finally:
            policy.close()
            env.close()
        report["wall_seconds"] = time.perf_counter() - started
        report["server"] = args.server
        print(summary_line(report), flush=True)
        if path:
            path.parent.mkdir(parents=True, exist_ok=True)
            write_json(path, report)
    return 0


def cmd_benchmark(args) -> int:
    from . import report
    from .benchmark import METHODS, BenchConfig, Runner, collect_results
    from frmd_client.runner import run_and_report
    only = None
    if args.methods:
        only = [m for m in args.methods.split(",") if m]
        unknown = [m for m in only if m not in METHODS]
        if unknown or not only:
            sys.exit(f"--methods: unknown {unknown} (choose from {', '.join(METHODS)})")
    overrides = {k: v for k, v in {
        "tasks": args.task, "demos": args.demos, "episodes": args.episodes, "backbone": args.backbone,
        "train_steps": args.train_steps, "student_steps": args.student_steps, "data_dir": args.data_dir,
        "out": args.out, "frmd": args.frmd, "controller": args.controller, "only": only,
        "in_process": True if args.in_process else None,
        "seeds": [int(s) for s in args.seeds.split(",")] if args.seeds else None,
        "hard_seeds": [int(s) for s in args.hard_seeds.split(",")] if args.hard_seeds else None}.items()
        if v is not None}
    cfg = BenchConfig.quick_config(**overrides) if args.quick else BenchConfig(**overrides)
    md = Path(args.results) if args.results else Path(cfg.out) / "results.md"
    md.parent.mkdir(parents=True, exist_ok=True)
    command = "cd examples/maniskill && .venv/bin/python -m frmd_maniskill " + " ".join(
        shlex.quote(a) for a in args.argv if a != "--report-only")
    return run_and_report(Runner(cfg), cfg, collect_results, report.write, report.quick_check, md, command,
                          args.note or [], report_only=args.report_only, quick=args.quick,
                          previous=Path(args.previous) if args.previous else None)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m frmd_maniskill", description="ManiSkill3 demonstrations and "
                                 "evaluation for FRMD (see examples/maniskill/README.md)")
    sub = ap.add_subparsers(dest="command", required=True)
    sub.add_parser("tasks", help="list the benchmark's tasks by group").set_defaults(run=cmd_tasks)
    sub.add_parser("check", help="build and step a PickCube scene (Vulkan device, PhysX CPU); setup.sh runs it"
                   ).set_defaults(run=cmd_check)

    d = sub.add_parser("demos", help="motion-planner demonstrations replayed to state observations, in FRMD's "
                       "dataset format (FILE.safetensors and its statistics FILE.json)")
    d.add_argument("--task", type=_tasks, required=True, help="a task, a comma-separated list, or all")
    d.add_argument("--episodes", type=int, default=100, help="successful demonstrations per task (default 100)")
    d.add_argument("--seed", type=int, default=0, help="first planner seed (below 2**31; default 0)")
    d.add_argument("--controller", choices=CONTROLLERS, default=CONTROLLER,
                   help=f"controller the actions are replayed into (default {CONTROLLER}, the benchmark's)")
    d.add_argument("--max-tries", type=int, help="seeds to try at most (default 3 x episodes + 20)")
    d.add_argument("--out", help="output file (one task)")
    d.add_argument("--out-dir", help="output directory: TASK.CONTROLLER.safetensors per task")
    d.add_argument("--force", action="store_true", help="replace an existing output file")
    d.set_defaults(run=cmd_demos)

    i = sub.add_parser("info", help="summarize dataset files")
    i.add_argument("files", nargs="+")
    i.set_defaults(run=cmd_info)

    dm = sub.add_parser("demo-metrics", help="the evaluation's end-effector metrics (non-smooth transitions, RMS "
                        "jerk) on a dataset's demonstrations, replayed open loop from their seeds")
    dm.add_argument("files", nargs="+")
    dm.add_argument("--episodes", type=int, help="the first N episodes of each file (default: all)")
    dm.set_defaults(run=cmd_demo_metrics)

    e = sub.add_parser("eval", help="closed-loop evaluation of a policy server (frmd serve ...)")
    e.add_argument("--task", type=_tasks, required=True, help="a task, a comma-separated list, or all")
    e.add_argument("--server", metavar="CMD", required=True, help="policy server command, e.g. 'frmd serve --ckpt DIR'")
    e.add_argument("--in-process", action="store_true", help="run the policy of --server's `frmd serve` command in "
                   "this process through the frmd wheel (pip install ./frmd-host/python) instead of over the protocol")
    e.add_argument("--episodes", type=int, default=50, help="evaluation episodes (default 50)")
    e.add_argument("--first-seed", type=int, default=0, help="index of the first seed in the evaluation stream")
    e.add_argument("--controller", choices=CONTROLLERS, default=CONTROLLER, help="controller the policy's actions "
                   f"drive (default {CONTROLLER}); must be the one its dataset was replayed into")
    e.add_argument("--exec-steps", type=int, help="actions executed per chunk (default: the server's)")
    e.add_argument("--json", help="write the report here (one task)")
    e.add_argument("--json-dir", help="write TASK-LABEL.json per task here")
    e.add_argument("--label", default="policy", help="file label with --json-dir")
    e.set_defaults(run=cmd_eval)

    m = sub.add_parser("benchmark", help="demonstrations, training, export and evaluation of every method on the "
                       "tasks (resumable); writes results.md/.json/.png")
    m.add_argument("--quick", action="store_true", help="CI mode: PickCube-v1, 3 demonstrations, 1 episode, 20 "
                   "training steps; checks that every report is valid (no success threshold)")
    m.add_argument("--task", type=_tasks, help="tasks (default: all; quick: PickCube-v1)")
    m.add_argument("--seeds", help="training seeds of the easy and medium tasks, comma-separated (default 0)")
    m.add_argument("--hard-seeds", help="training seeds of the hard tasks (default 0,1,2)")
    m.add_argument("--demos", type=int, help="demonstrations per task made when DATA_DIR lacks the file (default 100)")
    m.add_argument("--episodes", type=int, help="evaluation episodes per task, seed and method (default 50)")
    m.add_argument("--controller", choices=CONTROLLERS, help=f"controller of the demonstrations and policies "
                   f"(default {CONTROLLER})")
    m.add_argument("--methods", help="comma-separated methods to run (default: all); models none of them needs are "
                   "not trained")
    m.add_argument("--in-process", action="store_true", help="evaluate through the frmd wheel in this process")
    m.add_argument("--backbone", help="backbone of all three models (default: frmd train's default)")
    m.add_argument("--train-steps", type=int, help="gradient steps of teacher and DP (default: frmd train's)")
    m.add_argument("--student-steps", type=int, help="gradient steps of the student (default: as --train-steps)")
    m.add_argument("--data-dir", help="demonstration files TASK.CONTROLLER.safetensors (made if missing; default ./data)")
    m.add_argument("--out", help="run directory: checkpoints, reports, logs (default runs/maniskill)")
    m.add_argument("--frmd", help="the frmd binary (default: frmd on PATH)")
    m.add_argument("--results", help="results.md path (results.json and .png beside it; default OUT/results.md)")
    m.add_argument("--note", action="append", help="a line for the results file (repeatable)")
    m.add_argument("--previous", metavar="RESULTS_JSON", help="an earlier results.json: its rows stand in for the "
                   "runs that have no report under --out (e.g. made on another machine), noted in the report")
    m.add_argument("--report-only", action="store_true", help="run nothing: write the results files from the "
                   "reports OUT already holds")
    m.set_defaults(run=cmd_benchmark)

    args = ap.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    return args.run(args)
