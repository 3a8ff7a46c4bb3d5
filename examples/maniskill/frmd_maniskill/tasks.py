"""The benchmark's ManiSkill3 tasks, seeded environments and seed streams.

Environments are ManiSkill's own (`gym.make(TASK, obs_mode="state", sim_backend="physx_cpu",
num_envs=1)`): state observations (robot joint positions and velocities, the tool centre point's
pose, object and goal poses; 18-43 floats per task), one environment on the CPU, 20 Hz control.

Seeds: ManiSkill draws an episode's initial condition (object poses, goal, the robot's small
joint noise) from the seed given to `reset`, which must be below 2**32. Demonstrations use seeds
below EVAL_SEED_OFFSET = 2**31 (collection refuses others); evaluation episode i uses
EVAL_SEED_OFFSET + first_seed + i, so the two never share a seed (the layouts come from
continuous distributions, so different seeds give different layouts; a test checks it).
"""
from __future__ import annotations

import os
import tempfile
import warnings

import numpy as np

GROUPS = {
    "easy": ["PickCube-v1", "PushCube-v1", "PullCube-v1"],
    "medium": ["StackCube-v1", "PlaceSphere-v1", "PullCubeTool-v1"],
    "hard": ["LiftPegUpright-v1", "PlugCharger-v1", "PegInsertionSide-v1"],
}
TASKS = [t for group in GROUPS.values() for t in group]
GROUP_OF = {t: g for g, ts in GROUPS.items() for t in ts}
# The tasks issue 23 names; the others are the remaining tasks with a working motion planner.
ISSUE_TASKS = ["PickCube-v1", "PushCube-v1", "StackCube-v1", "PullCube-v1", "LiftPegUpright-v1",
               "PlugCharger-v1", "PegInsertionSide-v1"]

EVAL_SEED_OFFSET = 1 << 31
DT = 0.05  # 20 Hz control: sim_freq 100 / control_freq 20 (checked in SeededEnv)
# The controller the benchmark's datasets and policies use (README.md, "Controllers").
CONTROLLER = "pd_joint_pos"
CONTROLLERS = ("pd_joint_pos", "pd_ee_delta_pos", "pd_ee_pose")
# Evaluation step limit per task: ManiSkill's registered limits (50-200 steps) are shorter than
# some motion-planner demonstrations (which run without a limit), so evaluation allows twice the
# longest demonstration seen when the datasets were made, rounded up (demos.py reports lengths).
MAX_STEPS = {"PickCube-v1": 200, "PushCube-v1": 200, "PullCube-v1": 200, "StackCube-v1": 300,
             "PlaceSphere-v1": 300, "PullCubeTool-v1": 400, "LiftPegUpright-v1": 300,
             "PlugCharger-v1": 400, "PegInsertionSide-v1": 500}


def check_task(name: str) -> str:
    if name not in TASKS:
        raise ValueError(f"unknown task {name!r}; the benchmark's tasks are: {', '.join(TASKS)}")
    return name


def eval_seed(first_seed: int, index: int) -> int:
    return EVAL_SEED_OFFSET + first_seed + index


def check_demo_seeds(first: int, count: int) -> None:
    if first < 0 or first + count > EVAL_SEED_OFFSET:
        raise ValueError(f"demonstration seeds {first}..{first + count - 1} must lie in 0..2**31-1; seeds from "
                         "2**31 on are the evaluation stream")


def headless() -> None:
    """What SAPIEN needs without a display: a writable XDG_RUNTIME_DIR for the Vulkan loader, and
    ManiSkill's warnings about the missing GPU kept off the console."""
    if not os.environ.get("XDG_RUNTIME_DIR") or not os.access(os.environ["XDG_RUNTIME_DIR"], os.W_OK):
        os.environ["XDG_RUNTIME_DIR"] = tempfile.mkdtemp(prefix="frmd-maniskill-xdg-")
    warnings.filterwarnings("ignore")
    import logging
    logging.getLogger("mani_skill").setLevel(logging.ERROR)


def make_env(task: str, control_mode: str = CONTROLLER, obs_mode: str = "state", **kwargs):
    """ManiSkill's environment for `task` on the CPU, one at a time."""
    headless()
    import gymnasium as gym
    import mani_skill.envs  # noqa: F401 (registers the tasks)
    return gym.make(check_task(task), obs_mode=obs_mode, control_mode=control_mode, sim_backend="physx_cpu",
                    num_envs=1, render_mode=None, **kwargs)


def _numpy(x) -> np.ndarray:
    return np.asarray(x.cpu().numpy() if hasattr(x, "cpu") else x, dtype=np.float64).reshape(-1)


class SeededEnv:
    """One ManiSkill environment whose reset(seed) draws the initial condition from `seed`, with
    what the evaluation loop reads (frmd_client.evaluation): the tool centre point's position,
    the position the commanded joint targets put it at, and the initial action for RESET."""

    def __init__(self, task: str, control_mode: str = CONTROLLER):
        self.task, self.control_mode = task, control_mode
        self.env = make_env(task, control_mode, max_episode_steps=MAX_STEPS[task])
        base = self.env.unwrapped
        if abs(1.0 / base.control_freq - DT) > 1e-12:
            raise RuntimeError(f"{task}: control period {1.0 / base.control_freq} s; this package assumes {DT}")
        self.agent = base.agent
        self.model = self.agent.robot.create_pinocchio_model()
        names = [link.name for link in self.agent.robot.get_links()]
        self.tcp_index = names.index(self.agent.tcp.name)
        self.obs_dim = int(np.prod(self.env.observation_space.shape[1:]))
        self.action_dim = int(np.prod(self.env.action_space.shape))
        self.max_steps = MAX_STEPS[task]

    def reset(self, seed: int) -> np.ndarray:
        obs, _ = self.env.reset(seed=int(seed))
        self.steps = 0
        return _numpy(obs)

    def step(self, action) -> tuple[np.ndarray, bool, bool]:
        """(observation, success, truncated) after one control step; truncated at max_steps."""
        obs, _, _, _, info = self.env.step(np.asarray(action, dtype=np.float32))
        self.steps += 1
        return _numpy(obs), bool(_numpy(info["success"])[0]), self.steps >= self.max_steps

    def ee_position(self) -> np.ndarray:
        return _numpy(self.agent.tcp.pose.p)

    def commanded_position(self) -> np.ndarray:
        """Where the arm controller's joint targets put the tool centre point (forward kinematics)."""
        arm = self.agent.controller.controllers["arm"]
        target = getattr(arm, "_target_qpos", None)
        if target is None:
            return self.ee_position()
        qpos = _numpy(self.agent.robot.get_qpos()).copy()
        qpos[: len(_numpy(target))] = _numpy(target)
        self.model.compute_forward_kinematics(qpos)
        return np.asarray(self.model.get_link_pose(self.tcp_index).p, dtype=np.float64)

    def init_action(self) -> list | None:
        """The action that holds the robot where an episode starts, for RESET (absolute joint
        targets: the arm's joint positions and an open gripper); None for delta controllers,
        where the server's default, zeros, means "stay"."""
        if self.control_mode != "pd_joint_pos":
            return None
        qpos = _numpy(self.agent.robot.get_qpos())
        return qpos[:7].tolist() + [1.0]

    def unstable(self) -> bool:
        return False

    def close(self) -> None:
        self.env.close()


def package_versions() -> dict:
    import platform
    from importlib.metadata import version
    out = {name: version(name) for name in ("mani_skill", "sapien", "mplib", "torch", "numpy", "gymnasium",
                                            "safetensors", "h5py")}
    out["python"] = platform.python_version()
    return out
