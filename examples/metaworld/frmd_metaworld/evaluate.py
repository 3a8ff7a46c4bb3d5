"""Closed-loop evaluation on MetaWorld with the report fields of `frmd eval --json`
(frmd-host/src/eval/mod.rs: EvalReport) and the metrics of docs/design.md section 6.

A policy is either MetaWorld's scripted expert in this process, any policy server speaking
docs/serve-protocol.md (`frmd serve ...`, the mock server), or the policy of a `frmd serve`
command run in this process by the `frmd` wheel (`policy_client`). Per episode: reset the environment
and the policy with the episode's seed (EVAL_SEED_OFFSET + first_seed + i), then repeatedly send
the last M observations, execute up to E actions of the returned chunk (stopping at the first
success or after 500 steps), and report how many were executed with the next request. Success =
`info["success"]` true at some step. The end-effector path is the hand position obs[0:3] (one
point per step, the initial one included); the commanded path (`non_smooth_action`) is the mocap
target the actions move.

Latency (`latency_us_*`) is the policy's own time per chunk: `policy_ns` reported by the server
(or the expert's call), as `frmd eval` measures in process; `roundtrip_us_*` is the client-side
time from sending ACT to holding the CHUNK, and the difference is the protocol's overhead.
"""
from __future__ import annotations

import os
import time

from . import metrics
from .policy_client import Episode, ServedPolicy  # noqa: F401 (ServedPolicy: this module's name before)
from .tasks import (DT, MAX_STEPS, SeededEnv, check_task, eval_seed, expert_policy, layout_dim, layout_of_dim,
                    observe, package_versions)


class ExpertPolicy:
    """The scripted expert as a chunking policy of horizon 1 (float64 observations)."""

    def __init__(self, task: str):
        self.expert = expert_policy(task)
        self.name, self.history, self.horizon, self.exec_steps = "expert", 1, 1, 1
        self.float_type = "f64"
        self.obs_dim = layout_dim("raw")

    def reset(self, seed: int) -> None:
        pass

    def act(self, observations, executed: int):
        """(chunk [N][K], policy seconds)."""
        t0 = time.perf_counter()
        action = self.expert(observations[-1])
        return [action], time.perf_counter() - t0

    def close(self) -> None:
        pass


def rollout(env: SeededEnv, policy, seed: int, exec_steps: int, timings: dict, obs_layout: str = "raw") -> dict:
    obs = env.reset(seed)
    episode = Episode(policy, seed, observe(obs, obs_layout))
    ee_path, cmd_path = [obs[:3].copy()], [env.commanded_position()]
    steps, success, failed = 0, False, False
    while steps < MAX_STEPS and not success:
        chunk, policy_seconds, roundtrip = episode.chunk()
        timings["roundtrip"].append(roundtrip)
        timings["policy"].append(policy_seconds)
        for action in chunk[:exec_steps]:
            t0 = time.perf_counter()
            obs, success, truncated = env.step(action)
            timings["step"].append(time.perf_counter() - t0)
            steps += 1
            episode.executed_action(observe(obs, obs_layout))
            ee_path.append(obs[:3].copy())
            cmd_path.append(env.commanded_position())
            failed = failed or env.unstable()
            if success or truncated or steps >= MAX_STEPS:
                break
    return {"seed": seed, "success": success, "failed": failed, "length": steps,
            "non_smooth_ee": metrics.non_smooth_transitions(ee_path),
            "non_smooth_action": metrics.non_smooth_transitions(cmd_path),
            "rms_jerk": metrics.rms_jerk(ee_path, DT)}


def evaluate(task: str, policy, episodes: int = 50, first_seed: int = 0, exec_steps: int | None = None,
             warmup_calls: int = 5, progress=None, obs_layout: str | None = None) -> dict:
    """The report of `frmd eval --json`, plus round-trip timing and provenance fields.
    `obs_layout` (tasks.OBS_LAYOUTS) is what the policy observes; None: the layout of the policy's
    observation length (the server's hello)."""
    check_task(task)
    if obs_layout is None:
        obs_layout = layout_of_dim(policy.obs_dim)
    elif layout_dim(obs_layout) != policy.obs_dim:
        raise ValueError(f"the policy observes {policy.obs_dim} floats, the {obs_layout!r} layout has "
                         f"{layout_dim(obs_layout)}")
    if episodes < 1:
        raise ValueError("at least one evaluation episode is needed")
    exec_steps = exec_steps or policy.exec_steps
    if not 1 <= exec_steps <= policy.horizon:
        raise ValueError(f"exec_steps {exec_steps} is outside 1..={policy.horizon}")
    env = SeededEnv(task)
    if warmup_calls:
        seed = eval_seed(first_seed, 0)
        obs = env.reset(seed)
        policy.reset(seed)
        for _ in range(warmup_calls):
            policy.act([observe(obs, obs_layout)] * policy.history, 0)
    timings = {"roundtrip": [], "policy": [], "step": []}
    records = []
    for index in range(episodes):
        records.append(rollout(env, policy, eval_seed(first_seed, index), exec_steps, timings, obs_layout))
        if progress:
            progress(index + 1, records[-1])
    successes = sum(r["success"] for r in records)
    micros = {k: [v * 1e6 for v in vs] for k, vs in timings.items()}
    overhead = [r - p for r, p in zip(micros["roundtrip"], micros["policy"])]
    return {
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
        "obs_layout": obs_layout,
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
        "seed_stream": "episode i runs on seed 2**63 + first_seed + i; demonstrations use seeds < 2**63",
        "versions": package_versions(),
    }


# The fields `frmd eval --json` writes (frmd-host EvalReport), checked by the tests.
FRMD_EVAL_FIELDS = ["task", "policy", "episodes", "successes", "success_rate", "success_ci95", "mean_length",
                    "mean_length_success", "exec_steps", "history", "first_seed", "chunk_calls", "latency_us_median",
                    "latency_us_p99", "sim_step_us", "non_smooth_ee_mean", "non_smooth_action_mean", "rms_jerk_mean",
                    "threads", "per_episode"]
EPISODE_FIELDS = ["seed", "success", "failed", "length", "non_smooth_ee", "non_smooth_action", "rms_jerk"]
