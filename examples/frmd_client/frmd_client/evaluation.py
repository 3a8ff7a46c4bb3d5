"""The closed loop of a chunking policy in any simulator, and the report of `frmd eval --json`
(frmd-host/src/eval/mod.rs: EvalReport) built from its episodes.

A simulator package supplies an environment object with
- `reset(seed) -> obs`: the initial condition drawn from the episode seed alone;
- `step(action) -> (obs, success, truncated)`: one control step;
- `ee_position() -> [x, y, z]`: where the end effector is (the path the smoothness metrics read);
- `commanded_position() -> [x, y, z]`: where the actions drive it (`non_smooth_action`);
- `unstable() -> bool`: whether the simulator broke down in this episode (reported, not judged);
- optionally `init_action() -> list | None`: the command that holds the robot where the episode
  starts (absolute position targets), sent with RESET; without it the server's default (zeros).

Per episode: reset the environment and the policy with the episode's seed, then repeatedly send
the last M observations, execute up to E actions of the returned chunk (stopping at the first
success, at truncation or after `max_steps`), and report how many were executed with the next
request (`policy_client.Episode`). Success = the simulator's success flag at some step.

Latency (`latency_us_*`) is the policy's own time per chunk (`policy_ns` from `frmd serve`, or a
scripted expert's call), as `frmd eval` measures in process; `roundtrip_us_*` is the client-side
time from sending ACT to holding the CHUNK; the difference is the protocol's overhead.
"""
from __future__ import annotations

import os
import time
from typing import Callable

from . import metrics
from .policy_client import Episode

# The fields `frmd eval --json` writes (frmd-host EvalReport), checked by the tests.
FRMD_EVAL_FIELDS = ["task", "policy", "episodes", "successes", "success_rate", "success_ci95", "mean_length",
                    "mean_length_success", "exec_steps", "history", "first_seed", "chunk_calls", "latency_us_median",
                    "latency_us_p99", "sim_step_us", "non_smooth_ee_mean", "non_smooth_action_mean", "rms_jerk_mean",
                    "threads", "per_episode"]
EPISODE_FIELDS = ["seed", "success", "failed", "length", "non_smooth_ee", "non_smooth_action", "rms_jerk"]


def new_timings() -> dict:
    """Where `rollout` appends seconds: round trip and policy time per chunk, simulator step."""
    return {"roundtrip": [], "policy": [], "step": []}


def rollout(env, policy, seed: int, exec_steps: int, max_steps: int, dt: float, timings: dict,
            observe: Callable = lambda obs: obs, record: Callable | None = None) -> dict:
    """One episode; `observe` turns the simulator's observation into the policy's; `record(obs,
    action)`, if given, sees each step's policy observation and the action then executed."""
    obs = env.reset(seed)
    init = env.init_action() if hasattr(env, "init_action") else None
    episode = Episode(policy, seed, observe(obs), init)
    ee_path, cmd_path = [env.ee_position()], [env.commanded_position()]
    steps, success, failed, truncated = 0, False, False, False
    while steps < max_steps and not success and not truncated:
        chunk, policy_seconds, roundtrip = episode.chunk()
        timings["roundtrip"].append(roundtrip)
        timings["policy"].append(policy_seconds)
        for action in chunk[:exec_steps]:
            if record:
                record(episode.history[-1], action)
            t0 = time.perf_counter()
            obs, success, truncated = env.step(action)
            timings["step"].append(time.perf_counter() - t0)
            steps += 1
            episode.executed_action(observe(obs))
            ee_path.append(env.ee_position())
            cmd_path.append(env.commanded_position())
            failed = failed or env.unstable()
            if success or truncated or steps >= max_steps:
                break
    return {"seed": seed, "success": success, "failed": failed, "length": steps,
            "non_smooth_ee": metrics.non_smooth_transitions(ee_path),
            "non_smooth_action": metrics.non_smooth_transitions(cmd_path),
            "rms_jerk": metrics.rms_jerk(ee_path, dt)}


def check_exec_steps(policy, exec_steps: int | None, episodes: int) -> int:
    """The number of actions to execute per chunk (default: the policy's), checked."""
    if episodes < 1:
        raise ValueError("at least one evaluation episode is needed")
    exec_steps = exec_steps or policy.exec_steps
    if not 1 <= exec_steps <= policy.horizon:
        raise ValueError(f"exec_steps {exec_steps} is outside 1..={policy.horizon}")
    return exec_steps


def warm_up(policy, seed: int, first_obs, calls: int, init_action=None) -> None:
    """`calls` untimed chunks on the first evaluation observation (caches, page faults)."""
    if calls:
        if init_action is None:
            policy.reset(seed)
        else:
            policy.reset(seed, init_action)
        for _ in range(calls):
            policy.act([first_obs] * policy.history, 0)


def report(task: str, policy, records: list, timings: dict, exec_steps: int, first_seed: int,
           extra_before: dict | None = None, extra_after: dict | None = None) -> dict:
    """`frmd eval --json`'s fields from the episodes, plus round-trip timing; `extra_before` goes
    among them (before the per-episode list, e.g. the observation layout), `extra_after` after
    the timing fields (seed stream, package versions)."""
    successes = sum(r["success"] for r in records)
    micros = {k: [v * 1e6 for v in vs] for k, vs in timings.items()}
    overhead = [r - p for r, p in zip(micros["roundtrip"], micros["policy"])]
    out = {
        "task": task,
        "policy": policy.name,
        "episodes": len(records),
        "successes": successes,
        "success_rate": successes / len(records),
        "success_ci95": metrics.wilson_interval(successes, len(records)),
        "mean_length": metrics.mean([r["length"] for r in records]),
        "mean_length_success": metrics.mean([r["length"] for r in records if r["success"]]),
        "exec_steps": exec_steps,
        "history": policy.history,
        **(extra_before or {}),
        "first_seed": first_seed,
        "chunk_calls": len(micros["policy"]),
        "latency_us_median": metrics.quantile(micros["policy"], 0.5),
        "latency_us_p99": metrics.quantile(micros["policy"], 0.99),
        "sim_step_us": metrics.mean(micros["step"]),
        "non_smooth_ee_mean": metrics.mean([r["non_smooth_ee"] for r in records]),
        "non_smooth_action_mean": metrics.mean([r["non_smooth_action"] for r in records]),
        "rms_jerk_mean": metrics.mean([r["rms_jerk"] for r in records]),
        "threads": os.environ.get("RAYON_NUM_THREADS", "unset"),
        "per_episode": records,
        # Beyond frmd eval's fields:
        "horizon": policy.horizon,
        "float_type": policy.float_type,
        "roundtrip_us_median": metrics.quantile(micros["roundtrip"], 0.5),
        "roundtrip_us_p99": metrics.quantile(micros["roundtrip"], 0.99),
        "overhead_us_median": metrics.quantile(overhead, 0.5),
        **(extra_after or {}),
    }
    return out


def summary_line(report: dict, jerk_unit: str = "m/s^3") -> str:
    """The one line `eval` prints per task."""
    lo, hi = report["success_ci95"]
    return (f"{report['task']} {report['policy']}: success {100 * report['success_rate']:.1f} % [{100 * lo:.1f}, "
            f"{100 * hi:.1f}] over {report['episodes']} episodes, mean length {report['mean_length']:.1f}, latency "
            f"{report['latency_us_median']:.1f} us (round trip {report['roundtrip_us_median']:.1f}), non-smooth "
            f"{report['non_smooth_ee_mean']:.2f}/episode, RMS jerk {report['rms_jerk_mean']:.2f} {jerk_unit}, "
            f"{report['wall_seconds']:.1f} s")
