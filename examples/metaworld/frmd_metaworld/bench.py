"""Costs of the Python side: the protocol round trip against the mock server, and one
simulator step, expert call and reset.

Round trip: HELLO, RESET, warm-up ACTs, then timed ACTs of MetaWorld's shapes (2 observations
of 39 values in, 12 x 4 actions out, f32) against `mock_server --policy zeros`; reported as
client round trip, the server's policy_ns and their difference (the overhead). `cpu` pins this
process and the server (taskset) to one CPU.
"""
from __future__ import annotations

import os
import shlex
import sys
import time

import numpy as np

from . import metrics
from .protocol import Client


def protocol_roundtrip(calls: int = 2000, warmup: int = 200, cpu: int | None = None, history: int = 2,
                       horizon: int = 12, server: str | None = None) -> dict:
    """`server`: a server command (e.g. `frmd serve --ckpt DIR --zeros`) instead of the mock."""
    command = shlex.split(server) if server else [
        sys.executable, "-m", "frmd_metaworld.mock_server", "--policy", "zeros", "--history", str(history),
        "--horizon", str(horizon), "--exec-steps", str(min(8, horizon))]
    previous = os.sched_getaffinity(0)
    if cpu is not None:
        command = ["taskset", "-c", str(cpu)] + command
        os.sched_setaffinity(0, {cpu})
    try:
        client = Client(command, env={**os.environ, "PYTHONPATH": _package_root()})
        info = client.hello()
        client.reset(1)
        obs = [np.linspace(-1, 1, info.obs_dim).tolist()] * info.obs_history
        roundtrip, policy = [], []
        for i in range(warmup + calls):
            t0 = time.perf_counter_ns()
            client.act(0, obs)
            elapsed = time.perf_counter_ns() - t0
            if i >= warmup:
                roundtrip.append(elapsed / 1e3)
                policy.append(client.last_policy_ns / 1e3)
        status = client.close()
    finally:
        os.sched_setaffinity(0, previous)
    overhead = [r - p for r, p in zip(roundtrip, policy)]
    return {"server": server or "mock_server --policy zeros", "pinned_cpu": cpu, "calls": calls, "roundtrip_us_median": metrics.quantile(roundtrip, 0.5),
            "roundtrip_us_p99": metrics.quantile(roundtrip, 0.99), "policy_us_median": metrics.quantile(policy, 0.5),
            "overhead_us_median": metrics.quantile(overhead, 0.5), "overhead_us_p99": metrics.quantile(overhead, 0.99),
            "server_exit_status": status}


def step_costs(task: str = "push-v3", episodes: int = 5) -> dict:
    """Median microseconds of env.step, the expert's get_action and env.reset over expert episodes."""
    from .tasks import SeededEnv, expert_policy
    env, expert = SeededEnv(task), expert_policy(task)
    steps, experts, resets = [], [], []
    for seed in range(episodes):
        t0 = time.perf_counter()
        obs = env.reset(seed)
        resets.append(time.perf_counter() - t0)
        for _ in range(500):
            t0 = time.perf_counter()
            action = expert(obs)
            t1 = time.perf_counter()
            obs, success, truncated = env.step(action)
            steps.append(time.perf_counter() - t1)
            experts.append(t1 - t0)
            if success or truncated:
                break
    us = lambda xs: metrics.quantile([x * 1e6 for x in xs], 0.5)
    return {"task": task, "steps": len(steps), "step_us_median": us(steps), "step_us_mean": metrics.mean(steps) * 1e6,
            "expert_us_median": us(experts), "reset_us_median": us(resets)}


def _package_root() -> str:
    return os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
