"""Diagnostics of the learned policies' failures near the goal (results in ../README.md, section
"What limits the learned policies"). Not part of the package: it patches the package's
environment and collection at run time to try two data changes without changing the package.

  python experiments/near_goal.py collect TASK OUT [--relative] [--after-success K]
  python experiments/near_goal.py eval TASK "SERVER COMMAND" OUT.json [--relative]
  python experiments/near_goal.py trace TASK "SERVER COMMAND" REPORT.json [--relative] [--episodes N]

--relative appends goal - hand, object - hand and goal - object (9 floats) to MetaWorld's 39;
the expert still reads the first 39. --after-success K records K more expert steps after the
first success (the package stops at the first success). `trace` replays the first N failed
and 2 successful episodes of a report and prints the tool-centre-to-target distance over time.
"""
from __future__ import annotations

import argparse
import json
import sys
from collections import deque
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from frmd_metaworld import collect as collect_mod, evaluate, tasks  # noqa: E402

HAND, OBJECT, GOAL = slice(0, 3), slice(4, 7), slice(36, 39)


def with_relative(obs: np.ndarray) -> np.ndarray:
    return np.concatenate([obs, obs[GOAL] - obs[HAND], obs[OBJECT] - obs[HAND], obs[GOAL] - obs[OBJECT]])


def patch_relative() -> None:
    reset, step = tasks.SeededEnv.reset, tasks.SeededEnv.step

    def step_relative(self, action):
        obs, success, truncated = step(self, action)
        return with_relative(obs), success, truncated

    tasks.SeededEnv.reset = lambda self, seed: with_relative(reset(self, seed))
    tasks.SeededEnv.step = step_relative
    expert = collect_mod.expert_policy
    collect_mod.expert_policy = lambda task: (lambda f: (lambda obs: f(obs[:39])))(expert(task))
    collect_mod.OBS_DIM = 39 + 9


def patch_after_success(extra: int) -> None:
    def expert_episode(env, expert, seed):
        obs = env.reset(seed)
        observations, actions, success, left = [], [], False, extra
        for _ in range(tasks.MAX_STEPS):
            action = expert(obs)
            observations.append(obs)
            actions.append(action)
            obs, now, truncated = env.step(action)
            success = success or now
            if truncated or (success and left == 0):
                break
            left -= success
        return np.array(observations), np.array(actions), success

    collect_mod.expert_episode = expert_episode


def trace(task: str, server: str, report: str, episodes: int) -> None:
    rows = json.loads(Path(report).read_text())["per_episode"]
    seeds = [r["seed"] for r in rows if not r["success"]][:episodes] + [r["seed"] for r in rows if r["success"]][:2]
    policy, env = evaluate.ServedPolicy(server), tasks.SeededEnv(task)
    for seed in seeds:
        obs = env.reset(seed)
        policy.reset(seed)
        history = deque([obs] * policy.history, maxlen=policy.history)
        executed, dist, dz, chunk, success = 0, [], [], [], False
        for step in range(tasks.MAX_STEPS):
            if step % policy.exec_steps == 0:
                chunk, _ = policy.act(list(history), executed)
                executed = 0
            obs, success, _ = env.step(chunk[step % policy.exec_steps])
            executed += 1
            history.append(obs)
            dist.append(float(np.linalg.norm(env.env.tcp_center - env.env._target_pos)))
            dz.append(float(obs[HAND][2] - obs[GOAL][2]))
            if success:
                break
        k = int(np.argmin(dist))
        print(f"{'success' if success else 'FAILED '} seed {seed}: {len(dist)} steps, closest tool-centre-to-target "
              f"{dist[k]:.3f} m at step {k} (hand {1000 * dz[k]:+.0f} mm above the goal), final {dist[-1]:.3f} m")
    policy.close()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("what", choices=["collect", "eval", "trace"])
    p.add_argument("task")
    p.add_argument("arg1", help="collect: output file; eval, trace: the server command")
    p.add_argument("arg2", nargs="?", help="eval: output JSON; trace: the report whose episodes to replay")
    p.add_argument("--relative", action="store_true")
    p.add_argument("--after-success", type=int, default=0)
    p.add_argument("--episodes", type=int, default=6)
    a = p.parse_args()
    if a.relative:
        patch_relative()
    if a.what == "collect":
        if a.after_success:
            patch_after_success(a.after_success)
        data, stats = collect_mod.collect(a.task, 100)
        data.extra["episode_end"] = f"first success plus {a.after_success} expert steps (experiments/near_goal.py)"
        if a.relative:
            data.extra["obs_note"] = "39 MetaWorld floats, then goal-hand, object-hand, goal-object (experiments/near_goal.py)"
        data.save(a.arg1)
        print(json.dumps(stats))
    elif a.what == "eval":
        policy = evaluate.ServedPolicy(a.arg1)
        report = evaluate.evaluate(a.task, policy, episodes=50)
        policy.close()
        Path(a.arg2).write_text(json.dumps(report, default=float))
        print(a.task, report["successes"], "/", report["episodes"])
    else:
        trace(a.task, a.arg1, a.arg2, a.episodes)


if __name__ == "__main__":
    main()
