"""The benchmark's 12 MetaWorld v3 tasks, seeded environments, scripted experts and seed streams.

Initial conditions: one goal-observable v3 environment per task with `_freeze_rand_vec = False`
and `seeded_rand_vec = True`; before each episode `env.seed(s)` then `env.reset()`, so the object
and goal positions are a function of the episode seed `s` alone (not of the order of episodes).

Seeds (the same convention as `frmd collect` / `frmd eval`): demonstrations use seeds below
EVAL_SEED_OFFSET = 2**63 (collection refuses others); evaluation episode i uses
EVAL_SEED_OFFSET + first_seed + i. The two streams never share a seed, so evaluation initial
conditions are disjoint from the demonstrations' by construction (the positions are drawn
uniformly from continuous ranges, so different seeds give different layouts).
"""
from __future__ import annotations

import warnings

import numpy as np

GROUPS = {
    "easy": ["reach-v3", "button-press-topdown-v3", "drawer-close-v3", "plate-slide-v3"],
    "medium": ["push-v3", "drawer-open-v3", "door-open-v3", "window-open-v3", "pick-place-v3"],
    "hard": ["peg-insert-side-v3", "assembly-v3", "hammer-v3"],
}
TASKS = [t for group in GROUPS.values() for t in group]
GROUP_OF = {t: g for g, ts in GROUPS.items() for t in ts}

EVAL_SEED_OFFSET = 1 << 63
OBS_DIM, ACTION_DIM = 39, 4
DT = 0.0125  # frame_skip 5 x timestep 0.0025 s (checked against env.dt in make_env)
MAX_STEPS = 500  # max_path_length of every v3 environment


# What the policy observes (`collect --obs`, `eval --obs`): MetaWorld's 39 floats ("raw"), or those
# followed by goal - hand, object - hand and goal - object ("relative", 48 floats). The expert
# always reads the raw 39. Measured on all 12 tasks in README.md, "Data options".
OBS_LAYOUTS = ("raw", "relative")
HAND, OBJECT, GOAL = slice(0, 3), slice(4, 7), slice(36, 39)
RELATIVE_DIM = 9


def layout_dim(layout: str) -> int:
    """Observation length of a layout."""
    if layout not in OBS_LAYOUTS:
        raise ValueError(f"unknown observation layout {layout!r} ({', '.join(OBS_LAYOUTS)})")
    return OBS_DIM + (RELATIVE_DIM if layout == "relative" else 0)


def layout_of_dim(dim: int) -> str:
    """The layout whose observations have `dim` floats (each layout has its own length)."""
    for layout in OBS_LAYOUTS:
        if layout_dim(layout) == dim:
            return layout
    raise ValueError(f"no observation layout has {dim} floats "
                     f"({', '.join(f'{l}: {layout_dim(l)}' for l in OBS_LAYOUTS)})")


def observe(obs: np.ndarray, layout: str) -> np.ndarray:
    """The policy's observation of the simulator's raw one."""
    if layout == "raw":
        return obs
    if layout != "relative":
        layout_dim(layout)  # raises with the list of layouts
    return np.concatenate([obs, obs[GOAL] - obs[HAND], obs[OBJECT] - obs[HAND], obs[GOAL] - obs[OBJECT]])


def eval_seed(first_seed: int, index: int) -> int:
    return EVAL_SEED_OFFSET + first_seed + index


def check_task(name: str) -> str:
    if name not in TASKS:
        raise ValueError(f"unknown task {name!r}; the benchmark's tasks are: {', '.join(TASKS)}")
    return name


class SeededEnv:
    """One MetaWorld v3 environment whose reset(seed) draws the initial condition from `seed`."""

    def __init__(self, task: str):
        from metaworld.env_dict import ALL_V3_ENVIRONMENTS_GOAL_OBSERVABLE
        check_task(task)
        self.task = task
        self.env = ALL_V3_ENVIRONMENTS_GOAL_OBSERVABLE[f"{task}-goal-observable"](seed=0)
        self.env._freeze_rand_vec = False
        self.env.seeded_rand_vec = True
        if abs(self.env.dt - DT) > 1e-12 or self.env.max_path_length != MAX_STEPS:
            raise RuntimeError(f"{task}: dt {self.env.dt}, max_path_length {self.env.max_path_length}; "
                               f"this package assumes {DT} and {MAX_STEPS}")

    def reset(self, seed: int) -> np.ndarray:
        self.env.seed(seed)
        obs, _ = self.env.reset()
        self.last_obs = obs
        return obs

    def step(self, action) -> tuple[np.ndarray, bool, bool]:
        """(observation, success, truncated) after one control step."""
        obs, _, _, truncated, info = self.env.step(np.asarray(action, dtype=np.float64))
        self.last_obs = obs
        return obs, bool(info["success"]), bool(truncated)

    def ee_position(self) -> np.ndarray:
        """The hand position of the last observation, obs[0:3] (the evaluation's end-effector path)."""
        return self.last_obs[:3].copy()

    def unstable(self) -> bool:
        """True once the simulator became unstable in this episode (MetaWorld then freezes it)."""
        return bool(self.env._did_see_sim_exception)

    def commanded_position(self) -> np.ndarray:
        """Where the hand is being driven to: the mocap target that the actions move."""
        return np.array(self.env.data.mocap_pos[0], dtype=np.float64)

    def initial_condition(self) -> np.ndarray:
        """The random vector of the last reset (object and goal positions)."""
        return np.array(self.env._last_rand_vec, dtype=np.float64)


def expert_policy(task: str):
    """MetaWorld's scripted expert: obs (float64, 39) -> action clipped to [-1, 1] (float32, 4).

    The experts' proportional terms can exceed 1 (the environment clips the hand command), so
    the clipped action is what the environment executes; it is also what datasets record.
    """
    from metaworld.policies import ENV_POLICY_MAP
    policy = ENV_POLICY_MAP[check_task(task)]()

    def act(obs: np.ndarray) -> np.ndarray:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "Constant(s) may be too high" on every large step
            action = policy.get_action(obs)
        return np.clip(np.asarray(action, dtype=np.float32), -1.0, 1.0)

    return act


def package_versions() -> dict:
    import platform
    from importlib.metadata import version
    out = {name: version(name) for name in ("metaworld", "mujoco", "gymnasium", "numpy", "safetensors")}
    out["python"] = platform.python_version()
    return out
