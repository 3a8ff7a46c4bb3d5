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

import time

from frmd_client import evaluation
from frmd_client.evaluation import EPISODE_FIELDS, FRMD_EVAL_FIELDS  # noqa: F401 (this module's names before)
from frmd_client.policy_client import ServedPolicy  # noqa: F401 (this module's name before)
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
    """One episode (frmd_client.evaluation.rollout with MetaWorld's step limit and period)."""
    return evaluation.rollout(env, policy, seed, exec_steps, MAX_STEPS, DT, timings,
                              observe=lambda obs: observe(obs, obs_layout))


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
    exec_steps = evaluation.check_exec_steps(policy, exec_steps, episodes)
    env = SeededEnv(task)
    if warmup_calls:
        seed = eval_seed(first_seed, 0)
        evaluation.warm_up(policy, seed, observe(env.reset(seed), obs_layout), warmup_calls)
    timings = evaluation.new_timings()
    records = []
    for index in range(episodes):
        records.append(rollout(env, policy, eval_seed(first_seed, index), exec_steps, timings, obs_layout))
        if progress:
            progress(index + 1, records[-1])
    return evaluation.report(task, policy, records, timings, exec_steps, first_seed,
                             extra_before={"obs_layout": obs_layout},
                             extra_after={"seed_stream": "episode i runs on seed 2**63 + first_seed + i; "
                                                         "demonstrations use seeds < 2**63",
                                          "versions": package_versions()})
