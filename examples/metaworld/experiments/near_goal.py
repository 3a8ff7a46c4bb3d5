"""Diagnostics of the learned policies' failures near the goal (results in ../README.md, section
"What limits the learned policies").

  python experiments/near_goal.py TASK "SERVER COMMAND" REPORT.json [--episodes N]

replays the first N failed and 2 successful episodes of an evaluation report and prints the
tool-centre-to-target distance over time. The two data changes this study tried are options of
the package now (`collect --obs relative --after-success K`; `eval` reads the layout from the
server).
"""
from __future__ import annotations

import argparse
import json
import sys
from collections import deque
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from frmd_metaworld import evaluate, tasks  # noqa: E402

def trace(task: str, server: str, report: str, episodes: int) -> None:
    rows = json.loads(Path(report).read_text())["per_episode"]
    seeds = [r["seed"] for r in rows if not r["success"]][:episodes] + [r["seed"] for r in rows if r["success"]][:2]
    policy, env = evaluate.ServedPolicy(server), tasks.SeededEnv(task)
    layout = tasks.layout_of_dim(policy.obs_dim)
    for seed in seeds:
        obs = env.reset(seed)
        policy.reset(seed)
        history = deque([tasks.observe(obs, layout)] * policy.history, maxlen=policy.history)
        executed, dist, dz, chunk, success = 0, [], [], [], False
        for step in range(tasks.MAX_STEPS):
            if step % policy.exec_steps == 0:
                chunk, _ = policy.act(list(history), executed)
                executed = 0
            obs, success, _ = env.step(chunk[step % policy.exec_steps])
            executed += 1
            history.append(tasks.observe(obs, layout))
            dist.append(float(np.linalg.norm(env.env.tcp_center - env.env._target_pos)))
            dz.append(float(obs[tasks.HAND][2] - obs[tasks.GOAL][2]))
            if success:
                break
        k = int(np.argmin(dist))
        print(f"{'success' if success else 'FAILED '} seed {seed}: {len(dist)} steps, closest tool-centre-to-target "
              f"{dist[k]:.3f} m at step {k} (hand {1000 * dz[k]:+.0f} mm above the goal), final {dist[-1]:.3f} m")
    policy.close()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("task")
    p.add_argument("server", help="the policy server command")
    p.add_argument("report", help="the evaluation report whose episodes to replay")
    p.add_argument("--episodes", type=int, default=6)
    a = p.parse_args()
    trace(a.task, a.server, a.report, a.episodes)


if __name__ == "__main__":
    main()
