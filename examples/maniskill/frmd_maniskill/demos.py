"""Demonstrations made on this machine: ManiSkill's own motion-planning solutions, replayed to
state observations in the benchmark's controller, in FRMD's dataset format.

1. Plan: for seeds `seed, seed + 1, ...` (below 2**31, the evaluation stream's start) run the
   task's motion-planning solution (mani_skill.examples.motionplanning.panda.solutions) in
   `pd_joint_pos`, recording actions and environment states with ManiSkill's RecordEpisode;
   keep the successful episodes until `episodes` of them exist (or `max_tries` seeds were tried).
2. Replay: ManiSkill's replay_trajectory re-runs each kept episode from its seed with state
   observations, converting the actions to `controller` (for another controller than
   `pd_joint_pos` it steers that controller along the planned joint path); episodes whose replay
   does not succeed are dropped and listed.
3. Write: each episode up to and including its first successful step (evaluation stops there
   too), rows = (observation, the action then executed), float32; metadata: task, dt, source,
   action_before_start (`first` for absolute joint targets, `zero` for deltas), controller, seeds
   (kept, planner failures, replay failures), lengths and package versions.
"""
from __future__ import annotations

import contextlib
import io
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from frmd_client.dataset import Dataset

from .tasks import CONTROLLER, DT, check_demo_seeds, check_task, headless, package_versions

SOLUTIONS = {"PickCube-v1": "solvePickCube", "PushCube-v1": "solvePushCube", "PullCube-v1": "solvePullCube",
             "StackCube-v1": "solveStackCube", "PlaceSphere-v1": "solvePlaceSphere",
             "PullCubeTool-v1": "solvePullCubeTool", "LiftPegUpright-v1": "solveLiftPegUpright",
             "PlugCharger-v1": "solvePlugCharger", "PegInsertionSide-v1": "solvePegInsertionSide"}


def plan(task: str, episodes: int, seed: int, out_dir: Path, max_tries: int, progress=None) -> dict:
    """Runs the motion planner until `episodes` successes; returns the recorded file and seeds."""
    import gymnasium as gym
    import mani_skill.envs  # noqa: F401
    from mani_skill.examples.motionplanning.panda import solutions
    from mani_skill.utils.wrappers.record import RecordEpisode
    solve = getattr(solutions, SOLUTIONS[check_task(task)])
    env = gym.make(task, obs_mode="none", control_mode="pd_joint_pos", render_mode="rgb_array",
                   sim_backend="physx_cpu")
    env = RecordEpisode(env, output_dir=str(out_dir), trajectory_name="planned", save_video=False,
                        source_type="motionplanning", source_desc="ManiSkill's motion planning solution",
                        record_reward=False, save_on_reset=False)
    kept, failed, lengths = [], [], []
    s = seed
    while len(kept) < episodes and s - seed < max_tries:
        check_demo_seeds(s, 1)
        try:
            with contextlib.redirect_stdout(io.StringIO()):
                res = solve(env, seed=s, debug=False, vis=False)
            ok = res != -1 and bool(res[-1]["success"].item())
        except Exception:  # the planner found no path (mplib raises on some layouts)
            ok = False
        if ok:
            env.flush_trajectory()
            kept.append(s)
            lengths.append(int(res[-1]["elapsed_steps"].item()))
        else:
            env.flush_trajectory(save=False)
            failed.append(s)
        if progress:
            progress(len(kept), len(kept) + len(failed))
        s += 1
    env.close()
    return {"h5": str(out_dir / "planned.h5"), "kept": kept, "failed": failed, "lengths": lengths}


def replay(h5: str, controller: str) -> str:
    """ManiSkill's replay_trajectory to state observations in `controller`; the written file."""
    from mani_skill.trajectory import replay_trajectory as rt
    args = rt.Args(traj_path=h5, obs_mode="state", target_control_mode=controller, save_traj=True,
                   sim_backend="physx_cpu", num_envs=1)
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        rt.main(args)
    out = h5[:-len(".h5")] + f".state.{controller}.physx_cpu.h5"
    if not os.path.exists(out):
        raise RuntimeError(f"replay_trajectory wrote no {out}")
    return out


def read_replayed(path: str, seeds_by_id: dict) -> tuple[list, list, list]:
    """(episodes as (seed, obs [T, O], action [T, A]) cut after the first success, replay
    failures, full lengths) from a replayed file."""
    import h5py
    meta = json.loads(Path(path[:-len(".h5")] + ".json").read_text())
    out, lengths, replayed = [], [], set()
    with h5py.File(path, "r") as f:
        for ep in meta["episodes"]:
            g = f[f"traj_{ep['episode_id']}"]
            obs, act, success = np.asarray(g["obs"]), np.asarray(g["actions"]), np.asarray(g["success"]).reshape(-1)
            seed = int(ep["reset_kwargs"]["seed"]) if "seed" in ep.get("reset_kwargs", {}) else int(ep["episode_seed"])
            replayed.add(seed)
            if not success.any():
                continue
            end = int(np.argmax(success)) + 1
            out.append((seed, obs[:end].reshape(end, -1), act[:end].reshape(end, -1)))
            lengths.append(len(act))
    return out, sorted(set(seeds_by_id) - {s for s, _, _ in out}), lengths


def collect(task: str, episodes: int = 100, seed: int = 0, controller: str = CONTROLLER, max_tries: int | None = None,
            progress=None) -> tuple[Dataset, dict]:
    """`episodes` successful demonstrations of `task` (fewer if the planner or the replay fails
    too often; the statistics say how many) as a Dataset, and statistics."""
    headless()
    check_task(task)
    check_demo_seeds(seed, episodes)
    max_tries = max_tries or 3 * episodes + 20
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="frmd-maniskill-demos-") as tmp:
        planned = plan(task, episodes, seed, Path(tmp), max_tries, progress)
        if not planned["kept"]:
            raise RuntimeError(f"{task}: the motion planner succeeded on none of seeds {seed}..{seed + max_tries - 1}")
        plan_seconds = time.perf_counter() - started
        replayed = replay(planned["h5"], controller)
        rows, replay_failed, full_lengths = read_replayed(replayed, {s: i for i, s in enumerate(planned["kept"])})
    if not rows:
        raise RuntimeError(f"{task}: no demonstration replayed successfully in {controller}")
    rows.sort(key=lambda r: r[0])
    obs = np.concatenate([o for _, o, _ in rows]).astype(np.float32)
    action = np.concatenate([a for _, _, a in rows]).astype(np.float32)
    ends = np.cumsum([len(a) for _, _, a in rows]).astype(np.int64)
    lengths = [len(a) for _, _, a in rows]
    extra = {
        "maniskill_task": task,
        "controller": controller,
        "obs_mode": "state",
        "action_before_start": "first" if controller == "pd_joint_pos" else "zero",
        "episode_seeds": json.dumps([s for s, _, _ in rows]),
        "planner_failed_seeds": json.dumps(planned["failed"]),
        "replay_failed_seeds": json.dumps(replay_failed),
        "versions": json.dumps(package_versions()),
        "notes": "ManiSkill3 motion-planning solutions (pd_joint_pos) replayed with replay_trajectory to state "
                 f"observations in {controller}; each episode cut after its first successful step; seeds < 2**31 "
                 "(evaluation uses 2**31 + i); PhysX CPU, one environment",
    }
    data = Dataset(obs, action, ends, f"maniskill/{task}", DT, "ManiSkill motion planner (frmd_maniskill demos)", extra)
    data.validate()
    stats = {"task": task, "controller": controller, "episodes": len(rows), "steps": int(len(obs)),
             "obs_dim": int(obs.shape[1]), "action_dim": int(action.shape[1]),
             "seeds_tried": len(planned["kept"]) + len(planned["failed"]), "planner_failed": len(planned["failed"]),
             "replay_failed": len(replay_failed), "mean_length": float(np.mean(lengths)), "max_length": int(max(lengths)),
             "planned_max_length": int(max(planned["lengths"])), "replayed_max_length": int(max(full_lengths)),
             "plan_seconds": round(plan_seconds, 1), "seconds": round(time.perf_counter() - started, 1)}
    return data, stats
