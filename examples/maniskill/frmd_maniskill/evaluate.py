"""Closed-loop evaluation on ManiSkill with the report fields of `frmd eval --json` (the loop and
the report are frmd_client.evaluation's, as for MetaWorld).

A policy is any server of docs/serve-protocol.md (`frmd serve ...`), the policy of such a command
run in this process by the `frmd` wheel, or a `ReplayPolicy` (a recorded demonstration played
back open loop: the pipeline check without a trained model). Episode i runs on seed
EVAL_SEED_OFFSET + first_seed + i (2**31 + ...), disjoint from the demonstrations' seeds. RESET
carries the initial joint positions and an open gripper for absolute joint targets
(`pd_joint_pos`), so the first chunk starts where the robot is. An episode succeeds when
ManiSkill's `info["success"]` is true at some step (its "success once"); it stops there, or
after the task's step limit (tasks.MAX_STEPS). End-effector path: the tool centre point; the
commanded path (`non_smooth_action`): where the arm's joint targets put it (forward kinematics).
"""
from __future__ import annotations

import json
import time

import numpy as np

from frmd_client import evaluation, metrics
from frmd_client.dataset import Dataset

from .tasks import DT, SeededEnv, check_task, eval_seed, package_versions


class ReplayPolicy:
    """One demonstration's actions as chunks of `horizon` (ignores observations); for tests."""

    def __init__(self, actions, horizon: int = 12, exec_steps: int = 8, obs_dim: int = 0):
        self.actions = [list(map(float, a)) for a in actions]
        self.name, self.history, self.horizon, self.exec_steps = "replay", 1, horizon, exec_steps
        self.float_type, self.obs_dim, self.action_dim, self.dt = "f64", obs_dim, len(self.actions[0]), DT

    def reset(self, seed: int, init_action=None) -> None:
        self.next = 0

    def act(self, observations, executed: int):
        t0 = time.perf_counter()
        self.next += executed
        chunk = [self.actions[min(self.next + k, len(self.actions) - 1)] for k in range(self.horizon)]
        return chunk, time.perf_counter() - t0

    def close(self) -> None:
        pass


def evaluate(task: str, policy, episodes: int = 50, first_seed: int = 0, exec_steps: int | None = None,
             warmup_calls: int = 5, progress=None, env: SeededEnv | None = None) -> dict:
    """The report of `frmd eval --json` plus round-trip timing and provenance fields."""
    check_task(task)
    env = env or SeededEnv(task)
    if policy.obs_dim and policy.obs_dim != env.obs_dim:
        raise ValueError(f"the policy observes {policy.obs_dim} floats, {task}'s state observation has {env.obs_dim}")
    if getattr(policy, "action_dim", env.action_dim) != env.action_dim:
        raise ValueError(f"the policy commands {policy.action_dim} values, {task} in {env.control_mode} takes "
                         f"{env.action_dim}")
    exec_steps = evaluation.check_exec_steps(policy, exec_steps, episodes)
    if warmup_calls:
        seed = eval_seed(first_seed, 0)
        first = env.reset(seed)
        evaluation.warm_up(policy, seed, first, warmup_calls, env.init_action())
    timings = evaluation.new_timings()
    records = []
    for index in range(episodes):
        records.append(evaluation.rollout(env, policy, eval_seed(first_seed, index), exec_steps, env.max_steps, DT,
                                          timings))
        if progress:
            progress(index + 1, records[-1])
    return evaluation.report(task, policy, records, timings, exec_steps, first_seed,
                             extra_before={"controller": env.control_mode, "max_steps": env.max_steps},
                             extra_after={"seed_stream": "episode i runs on seed 2**31 + first_seed + i; "
                                                         "demonstrations use seeds < 2**31",
                                          "versions": package_versions()})


def demo_metrics(path, episodes: int | None = None) -> dict:
    """The evaluation's end-effector metrics on a dataset's own demonstrations: each episode's
    actions replayed open loop from its seed (the reference the policies' numbers sit beside)."""
    data = Dataset.load(path)
    for key in ("maniskill_task", "controller", "episode_seeds"):
        if key not in data.extra:
            raise ValueError(f"{path}: metadata field {key!r} is missing (not written by frmd_maniskill demos)")
    seeds = json.loads(data.extra["episode_seeds"])
    env = SeededEnv(data.extra["maniskill_task"], data.extra["controller"])
    non_smooth, steps, jerk, successes = 0, 0, [], 0
    try:
        for seed, rows in list(zip(seeds, data.episodes()))[:episodes]:
            env.reset(seed)
            ee, success = [env.ee_position()], False
            for action in data.action[rows]:
                _, success, _ = env.step(action)
                ee.append(env.ee_position())
            successes += success
            non_smooth += metrics.non_smooth_transitions(ee)
            steps += len(ee) - 1
            jerk.append(metrics.rms_jerk(ee, DT))
    finally:
        env.close()
    n = len(jerk)
    return {"path": str(path), "controller": data.extra["controller"], "episodes": n,
            "success_at_last_row": successes, "non_smooth_ee_mean": non_smooth / n,
            "non_smooth_per_step": non_smooth / steps, "rms_jerk_mean": float(np.mean(jerk)), "steps": steps}
