"""Command line: python -m frmd_metaworld {tasks,collect,eval,info,bench,benchmark} ... (--help on each)."""
from __future__ import annotations

import argparse
import json
import shlex
import os
import sys
import time
from pathlib import Path

from .tasks import GROUPS, OBS_LAYOUTS, TASKS


def _progress(task: str, total: int):
    """A progress callback printing to a terminal's standard error (silent in logs and pipes)."""
    if not sys.stderr.isatty():
        return None
    return lambda n, *_: print(f"\r{task}: {n}/{total}", end="", file=sys.stderr, flush=True)


def _methods(text: str) -> list:
    from .benchmark import METHODS
    methods = [m for m in text.split(",") if m]
    unknown = [m for m in methods if m not in METHODS]
    if unknown or not methods:
        raise SystemExit(f"--methods: unknown {unknown} (choose from {', '.join(METHODS)})")
    return methods


def _tasks(value: str) -> list[str]:
    if value == "all":
        return list(TASKS)
    names = value.split(",")
    for name in names:
        if name not in TASKS:
            raise argparse.ArgumentTypeError(f"unknown task {name!r}; choose from: all, {', '.join(TASKS)}")
    return names


def cmd_tasks(args) -> int:
    for group, names in GROUPS.items():
        print(f"{group}: {' '.join(names)}")
    return 0


def cmd_collect(args) -> int:
    from .collect import collect
    if len(args.task) > 1 and args.out:
        sys.exit("--out names one file; use --out-dir for several tasks")
    if args.policy_server and (args.obs != "raw" or args.after_success):
        sys.exit("--obs and --after-success shape expert demonstrations; --policy-server records in the "
                 "policy's own observation layout until its first success")
    out_dir = Path(args.out_dir) if args.out_dir else None
    if out_dir:
        out_dir.mkdir(parents=True, exist_ok=True)
    for task in args.task:
        path = Path(args.out) if args.out else out_dir / f"{task}.safetensors"
        if path.exists() and not args.force:
            print(f"{task}: {path} exists, skipped (--force to redo)", flush=True)
            continue
        if args.policy_server:
            from frmd_client.policy_client import open_policy
            from .collect import record_policy
            from .tasks import DT
            policy = open_policy(args.policy_server, False, dt=DT)
            try:
                data, stats = record_policy(task, policy, args.episodes, args.seed,
                                            progress=_progress(task, args.episodes))
            finally:
                policy.close()
        else:
            data, stats = collect(task, args.episodes, args.seed, progress=_progress(task, args.episodes),
                                  obs_layout=args.obs, after_success=args.after_success)
        tmp = path.with_name(path.name + ".partial")
        data.save(tmp)
        os.replace(tmp, path)
        stats.update(path=str(path), bytes=path.stat().st_size)
        print(json.dumps(stats), flush=True)
    return 0


def cmd_eval(args) -> int:
    from frmd_client.evaluation import summary_line
    from .evaluate import ExpertPolicy, evaluate
    from frmd_client.policy_client import open_policy
    from .tasks import DT
    if (args.server is None) == (not args.expert):
        sys.exit("give exactly one of --expert and --server CMD")
    if args.in_process and not args.server:
        sys.exit("--in-process runs the policy of --server CMD in this process; give --server")
    if len(args.task) > 1 and args.json:
        sys.exit("--json names one file; use --json-dir for several tasks")
    for task in args.task:
        policy = ExpertPolicy(task) if args.expert else open_policy(args.server, args.in_process, dt=DT)
        started = time.perf_counter()
        try:
            report = evaluate(task, policy, args.episodes, args.first_seed, args.exec_steps,
                              progress=_progress(task, args.episodes),
                              obs_layout=None if args.obs == "auto" else args.obs)
        finally:
            policy.close()
        report["wall_seconds"] = time.perf_counter() - started
        print(summary_line(report), flush=True)
        path = Path(args.json) if args.json else (Path(args.json_dir) / f"{task}-{args.label}.json" if args.json_dir else None)
        if path:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(report, indent=1) + "\n")
    return 0


def cmd_info(args) -> int:
    import numpy as np
    from frmd_client.dataset import Dataset
    for path in args.files:
        d = Dataset.load(path)
        lengths = np.diff(np.concatenate([[0], d.episode_ends]))
        constant = [int(i) for i in np.flatnonzero(d.obs.max(axis=0) == d.obs.min(axis=0))]
        print(json.dumps({"path": str(path), "task": d.task, "episodes": len(lengths), "steps": int(len(d.obs)),
                          "obs_dim": d.obs.shape[1], "action_dim": d.action.shape[1], "dt": d.dt,
                          "mean_length": float(lengths.mean()), "min_length": int(lengths.min()),
                          "max_length": int(lengths.max()), "constant_obs_dims": constant,
                          "action_min": d.action.min(axis=0).round(3).tolist(),
                          "action_max": d.action.max(axis=0).round(3).tolist(), "bytes": Path(path).stat().st_size}))
    return 0


def cmd_bench(args) -> int:
    from . import bench
    if args.what == "protocol":
        for cpu in ([None, args.cpu] if args.cpu is not None else [None]):
            print(json.dumps(bench.protocol_roundtrip(args.calls, cpu=cpu, server=args.server)), flush=True)
    else:
        for task in args.task:
            print(json.dumps(bench.step_costs(task, args.episodes)), flush=True)
    return 0


def cmd_benchmark(args) -> int:
    from .benchmark import BenchConfig, Runner, collect_results
    from frmd_client.runner import run_and_report
    from . import report
    overrides = {k: v for k, v in {
        "tasks": args.task, "demos": args.demos, "episodes": args.episodes, "backbone": args.backbone,
        "train_steps": args.train_steps, "student_steps": args.student_steps, "data_dir": args.data_dir,
        "out": args.out, "frmd": args.frmd, "obs": args.obs, "after_success": args.after_success,
        "int16": True if args.int16 else None,
        "on_policy": True if args.on_policy else None,
        "in_process": True if args.in_process else None,
        "only": _methods(args.methods) if args.methods else None,
        "seeds": [int(s) for s in args.seeds.split(",")] if args.seeds else None,
        "multi_seed_tasks": ([] if args.multi_seed_tasks == "none" else _tasks(args.multi_seed_tasks))
        if args.multi_seed_tasks else None}.items() if v is not None}
    cfg = BenchConfig.quick_config(**overrides) if args.quick else BenchConfig(**overrides)
    md = Path(args.results) if args.results else Path(cfg.out) / "results.md"
    md.parent.mkdir(parents=True, exist_ok=True)
    instructions = json.loads(Path(args.instructions).read_text()) if args.instructions else None
    command = "cd examples/metaworld && .venv/bin/python -m frmd_metaworld " + " ".join(
        shlex.quote(a) for a in argv_of(args) if a != "--report-only")
    return run_and_report(Runner(cfg), cfg, collect_results,
                          lambda results, md, command, notes: report.write(results, md, command, notes, instructions),
                          report.quick_check, md, command, args.note or [],
                          report_only=args.report_only, quick=args.quick,
                          previous=Path(args.previous) if args.previous else None)


def argv_of(args) -> list:
    return args.argv


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m frmd_metaworld", description="MetaWorld demonstrations and "
                                 "evaluation for FRMD (see examples/metaworld/README.md)")
    sub = ap.add_subparsers(dest="command", required=True)
    sub.add_parser("tasks", help="list the benchmark's 12 tasks by difficulty").set_defaults(run=cmd_tasks)

    c = sub.add_parser("collect", help="collect expert demonstrations into FRMD's dataset format")
    c.add_argument("--task", type=_tasks, required=True, help="a task, a comma-separated list, or all")
    c.add_argument("--episodes", type=int, default=100, help="successful demonstrations per task (with "
                   "--policy-server: episodes recorded)")
    c.add_argument("--seed", type=int, default=0, help="first episode seed (below 2**63)")
    c.add_argument("--out", help="output file (one task)")
    c.add_argument("--out-dir", help="output directory: TASK.safetensors per task; existing files are skipped")
    c.add_argument("--force", action="store_true", help="overwrite existing files")
    c.add_argument("--policy-server", metavar="CMD", help="record this served policy's rollouts instead of the "
                   "expert's demonstrations, every episode kept (e.g. 'frmd serve --ckpt STUDENT'; on-policy "
                   "states for frmd train student --on-policy-data)")
    c.add_argument("--obs", choices=OBS_LAYOUTS, default="raw", help="observation layout: raw (MetaWorld's 39 "
                   "floats) or relative (those and goal - hand, object - hand, goal - object)")
    c.add_argument("--after-success", type=int, default=0, metavar="K",
                   help="record K more expert steps after the first success (default 0: stop there)")
    c.set_defaults(run=cmd_collect)

    e = sub.add_parser("eval", help="closed-loop evaluation: the expert, or a policy server")
    e.add_argument("--task", type=_tasks, required=True, help="a task, a comma-separated list, or all")
    e.add_argument("--episodes", type=int, default=50)
    e.add_argument("--first-seed", type=int, default=0, help="index of the first seed in the evaluation stream")
    e.add_argument("--expert", action="store_true", help="MetaWorld's scripted expert, in this process")
    e.add_argument("--server", metavar="CMD", help="policy server command, e.g. 'frmd serve --ckpt DIR'")
    e.add_argument("--in-process", action="store_true", help="run the policy of --server's `frmd serve` command "
                   "in this process through the frmd wheel (pip install ./frmd-host/python) instead of over "
                   "the protocol: the same chunks, without the pipe")
    e.add_argument("--exec-steps", type=int, help="actions executed per chunk (default: the server's)")
    e.add_argument("--json", help="write the report here (one task)")
    e.add_argument("--json-dir", help="write TASK-LABEL.json per task here")
    e.add_argument("--label", default="policy", help="file label with --json-dir")
    e.add_argument("--obs", choices=("auto",) + OBS_LAYOUTS, default="auto", help="observation layout the policy "
                   "reads (default: the one whose length the server announces)")
    e.set_defaults(run=cmd_eval)

    i = sub.add_parser("info", help="summarize dataset files")
    i.add_argument("files", nargs="+")
    i.set_defaults(run=cmd_info)

    b = sub.add_parser("bench", help="protocol round trip against the mock server, or simulator step costs")
    b.add_argument("what", choices=["protocol", "step"])
    b.add_argument("--calls", type=int, default=2000)
    b.add_argument("--cpu", type=int, help="also measure with client and server pinned to this CPU")
    b.add_argument("--server", metavar="CMD", help="protocol: time this server command instead of the mock server")
    b.add_argument("--task", type=_tasks, default=["push-v3"])
    b.add_argument("--episodes", type=int, default=5)
    b.set_defaults(run=cmd_bench)

    m = sub.add_parser("benchmark", help="train, export and evaluate every method on the tasks (resumable); "
                       "writes results.md/.json/.png")
    m.add_argument("--quick", action="store_true", help="CI mode: 1 task, 5 demonstrations, 1 episode, 20 "
                   "training steps; checks that every report is valid (no success threshold)")
    m.add_argument("--task", type=_tasks, help="tasks (default: all 12; quick: reach-v3)")
    m.add_argument("--seeds", help="training seeds for every task, comma-separated (default 0)")
    m.add_argument("--multi-seed-tasks", help="tasks that also train seeds 1 and 2 (default: "
                   "reach-v3,push-v3,peg-insert-side-v3; 'none' for none)")
    m.add_argument("--demos", type=int, help="demonstrations per task collected when DATA_DIR lacks the file (default 100)")
    m.add_argument("--episodes", type=int, help="evaluation episodes per task and method (default 50)")
    m.add_argument("--backbone", help="backbone of all three models (default: frmd train's default)")
    m.add_argument("--obs", choices=OBS_LAYOUTS, help="observation layout of the collected data (default raw)")
    m.add_argument("--after-success", type=int, metavar="K", help="expert steps recorded after the first "
                   "success (default 0)")
    m.add_argument("--methods", help="comma-separated methods to run (default: all); models none of them "
                   "needs are not trained (e.g. no DP without dp-ddpm-100 and dp-ddim-10)")
    m.add_argument("--on-policy", action="store_true", help="distill the evaluated student with an on-policy "
                   "round: rollouts of a first student (RUN/student0), labelled by the teacher")
    m.add_argument("--int16", action="store_true", help="also export the student with int16 activations "
                   "(frmd export --activations int16) and evaluate it as int16-student")
    m.add_argument("--in-process", action="store_true", help="evaluate the trained policies in this process "
                   "through the frmd wheel (eval --in-process) instead of over the protocol")
    m.add_argument("--train-steps", type=int, help="gradient steps of teacher and DP (default: frmd train's)")
    m.add_argument("--student-steps", type=int, help="gradient steps of the student (default: as --train-steps)")
    m.add_argument("--data-dir", help="demonstration files TASK.safetensors (collected if missing; default ./data)")
    m.add_argument("--out", help="run directory: checkpoints, reports, logs (default runs/metaworld)")
    m.add_argument("--frmd", help="the frmd binary (default: frmd on PATH)")
    m.add_argument("--results", help="results.md path (results.json and .png beside it; default OUT/results.md)")
    m.add_argument("--note", action="append", help="a line for the results file (repeatable)")
    m.add_argument("--instructions", metavar="JSON", help="Cortex-M4 instructions per chunk of each method "
                   "({\"student-1\": N, ...}): adds the success-per-instruction-budget line")
    m.add_argument("--previous", metavar="RESULTS_JSON", help="an earlier results.json: its rows stand in for the "
                   "runs that have no report under --out (e.g. made on another machine), noted in the report")
    m.add_argument("--report-only", action="store_true", help="run nothing: write the results files from the "
                   "reports OUT already holds (e.g. while parts of a run are still going)")
    m.set_defaults(run=cmd_benchmark)

    args = ap.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    return args.run(args)
