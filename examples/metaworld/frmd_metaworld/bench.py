"""Costs of the Python side: the protocol round trip against the mock server (frmd_client.bench),
and one simulator step, expert call and reset.
"""
from __future__ import annotations

import time

from frmd_client import metrics
from frmd_client.bench import protocol_roundtrip  # noqa: F401 (cli: bench protocol)


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
