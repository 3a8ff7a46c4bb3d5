"""Expert demonstrations of one MetaWorld task in FRMD's dataset format.

Episode seeds are `seed, seed + 1, ...` (below 2**63, the evaluation stream). An episode runs the
scripted expert on float64 observations until `info["success"]` first becomes true (that step
included) or 500 steps; only successful episodes are recorded, so every demonstration ends in
success, as `frmd collect` does. Failed seeds are listed in the metadata. Each row holds the
observation the expert saw (rounded to float32, as the format requires) and the action it then
executed (clipped to [-1, 1], which changes nothing in the simulation: the environment clips too).
"""
from __future__ import annotations

import json
import time

import numpy as np

from frmd_client.dataset import Dataset
from .tasks import (ACTION_DIM, DT, EVAL_SEED_OFFSET, MAX_STEPS, SeededEnv, check_task, expert_policy,
                    layout_dim, observe, package_versions)


def check_collection_seeds(seed: int, count: int) -> None:
    """`count` episode seeds from `seed` must stay below the evaluation stream."""
    if seed < 0 or seed + count > EVAL_SEED_OFFSET:
        raise ValueError(f"collection seeds must lie in [0, 2**63) (the evaluation stream starts at 2**63); seed {seed}")


def expert_episode(env: SeededEnv, expert, seed: int, obs_layout: str = "raw", after_success: int = 0):
    """(observations, actions, success) of one expert episode, stopping at the first success, or
    `after_success` steps later (the expert keeps acting; the episode still counts as a success).
    Observations are recorded in `obs_layout`; the expert reads the raw ones."""
    obs = env.reset(seed)
    observations, actions, success, left = [], [], False, after_success
    for _ in range(MAX_STEPS):
        action = expert(obs)
        observations.append(observe(obs, obs_layout))
        actions.append(action)
        obs, now, truncated = env.step(action)
        if success:
            left -= 1
        success = success or now
        if truncated or (success and left <= 0):
            break
    return np.array(observations), np.array(actions), success


def collect(task: str, episodes: int, seed: int = 0, max_attempts: int | None = None, progress=None,
            obs_layout: str = "raw", after_success: int = 0):
    """(Dataset, stats) with `episodes` successful demonstrations of `task`, observations in
    `obs_layout` (tasks.OBS_LAYOUTS), each recorded until `after_success` steps past its first
    success."""
    check_task(task)
    obs_dim = layout_dim(obs_layout)
    if not 0 <= after_success <= MAX_STEPS:
        raise ValueError(f"after_success must be in 0..{MAX_STEPS}, got {after_success}")
    if episodes < 1:
        raise ValueError("at least one episode must be collected")
    max_attempts = max_attempts or episodes + 10 + episodes // 5
    check_collection_seeds(seed, max_attempts)
    started = time.perf_counter()
    env, expert = SeededEnv(task), expert_policy(task)
    obs_rows, action_rows, ends, seeds, failed, lengths = [], [], [], [], [], []
    attempt, steps, step_time = 0, 0, 0.0
    while len(ends) < episodes:
        if attempt >= max_attempts:
            raise RuntimeError(f"the {task} expert failed {len(failed)} of {attempt} episodes; giving up")
        episode_seed = seed + attempt
        attempt += 1
        t0 = time.perf_counter()
        obs, act, success = expert_episode(env, expert, episode_seed, obs_layout, after_success)
        step_time += time.perf_counter() - t0
        steps += len(act)
        if not success:
            failed.append(episode_seed)
            continue
        obs_rows.append(obs.astype(np.float32))
        action_rows.append(act.astype(np.float32))
        ends.append((ends[-1] if ends else 0) + len(act))
        seeds.append(episode_seed)
        lengths.append(len(act))
        if progress:
            progress(len(ends))
    data = Dataset(
        obs=np.concatenate(obs_rows), action=np.concatenate(action_rows), episode_ends=np.array(ends, dtype=np.int64),
        task=f"metaworld/{task}", dt=DT,
        source=(f"frmd_metaworld collect: MetaWorld {task} scripted expert (metaworld.policies), seeds "
                f"{seed}..{seed + attempt} ({len(failed)} failed episodes skipped)"),
        extra={
            # MetaWorld actions are end-effector displacements: before an episode the arm is at
            # rest, i.e. the zero action, which is also what `frmd serve` resets a policy with.
            "action_before_start": "zero",
            "metaworld_task": task,
            "episode_seeds": json.dumps(seeds),
            "failed_seeds": json.dumps(failed),
            "versions": json.dumps(package_versions()),
            "environment": "goal-observable v3, _freeze_rand_vec=False, seeded_rand_vec=True, env.seed(s) then reset()",
            "episode_end": (f"first step with info['success'] true (inclusive), then {after_success} more expert "
                            "steps; max 500 steps"),
            "after_success": str(after_success),
            "obs_layout": obs_layout,
            "obs_note": ("float32 copy of the float64 observation the expert acted on" +
                         ("" if obs_layout == "raw" else ", then goal - hand, object - hand, goal - object")),
            "action_note": "expert action clipped to [-1, 1]: hand displacement (x 1 cm) xyz, gripper",
            "eval_seeds": "evaluation uses seeds 2**63 + i, disjoint from these",
        },
    )
    data.validate()
    if data.obs.shape[1] != obs_dim or data.action.shape[1] != ACTION_DIM:
        raise RuntimeError(f"unexpected shapes {data.obs.shape} {data.action.shape}")
    stats = {"task": task, "episodes": episodes, "attempted": attempt, "failed": len(failed),
             "steps": int(len(data.obs)), "mean_length": float(np.mean(lengths)),
             "seconds": time.perf_counter() - started, "us_per_step": step_time / max(steps, 1) * 1e6}
    return data, stats


def record_policy(task: str, policy, episodes: int, seed: int, progress=None, obs_layout: str | None = None):
    """(Dataset, stats): `episodes` rollouts of a served `policy` (frmd_client.policy_client) on
    collection seeds `seed, seed + 1, ...`, every episode kept, successful or not, with the
    actions executed (clipped to [-1, 1] as the demonstrations are): on-policy states for
    `frmd train student --on-policy-data`, where the teacher labels them."""
    from frmd_client import evaluation
    from .tasks import layout_of_dim
    check_task(task)
    if episodes < 1:
        raise ValueError("at least one episode must be recorded")
    check_collection_seeds(seed, episodes)
    obs_layout = obs_layout or layout_of_dim(policy.obs_dim)
    started = time.perf_counter()
    env = SeededEnv(task)
    obs_rows, action_rows, ends, successes = [], [], [], 0
    for index in range(episodes):
        rows = []
        record = evaluation.rollout(env, policy, seed + index, policy.exec_steps, MAX_STEPS, DT,
                                    evaluation.new_timings(), observe=lambda obs: observe(obs, obs_layout),
                                    record=lambda o, a: rows.append((o, a)))
        successes += bool(record["success"])
        obs_rows.append(np.array([o for o, _ in rows], dtype=np.float32))
        action_rows.append(np.clip(np.array([a for _, a in rows], dtype=np.float32), -1.0, 1.0))
        ends.append((ends[-1] if ends else 0) + len(rows))
        if progress:
            progress(index + 1)
    data = Dataset(
        obs=np.concatenate(obs_rows), action=np.concatenate(action_rows), episode_ends=np.array(ends, dtype=np.int64),
        task=f"metaworld/{task}", dt=DT,
        source=(f"frmd_metaworld collect --policy-server: {policy.name}, seeds {seed}..{seed + episodes}, "
                f"{successes} of {episodes} episodes successful, every episode kept"),
        extra={
            "action_before_start": "zero",
            "metaworld_task": task,
            "obs_layout": obs_layout,
            "versions": json.dumps(package_versions()),
            "action_note": "the policy's executed action clipped to [-1, 1]",
            "eval_seeds": "evaluation uses seeds 2**63 + i, disjoint from these",
        },
    )
    data.validate()
    stats = {"task": task, "episodes": episodes, "successes": successes, "steps": int(len(data.obs)),
             "seconds": time.perf_counter() - started}
    return data, stats

