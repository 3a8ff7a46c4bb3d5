"""FRMD's demonstration format (docs/design.md section 4; reader: frmd-host/src/data/dataset.rs).

A safetensors file with `obs` [T, O] float32, `action` [T, A] float32 and `episode_ends` [E]
int64 (cumulative exclusive end of each episode, strictly increasing, the last equal to T), and
string metadata `task`, `dt` (control period, seconds, parsed as a number) and `source`, and
`action_before_start` (`first` or `zero`: the command before an episode's first step, which
training uses as the previous action there: `zero` for displacement commands such as
MetaWorld's, `first` for position targets). Any other metadata key is kept and ignored by frmd;
the benchmark packages add the episode seeds, the package versions and notes on how the data was
made.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

REQUIRED_METADATA = ("task", "dt", "source")


@dataclass
class Dataset:
    obs: np.ndarray  # [T, O] float32
    action: np.ndarray  # [T, A] float32
    episode_ends: np.ndarray  # [E] int64
    task: str
    dt: float
    source: str
    extra: dict = field(default_factory=dict)  # more metadata, str -> str

    def episodes(self) -> list[slice]:
        starts = np.concatenate([[0], self.episode_ends[:-1]])
        return [slice(int(s), int(e)) for s, e in zip(starts, self.episode_ends)]

    def validate(self) -> None:
        """The checks of frmd-host's Dataset::validate, with the same wording."""
        if self.obs.dtype != np.float32 or self.action.dtype != np.float32 or self.episode_ends.dtype != np.int64:
            raise ValueError(f"dtypes are obs {self.obs.dtype}, action {self.action.dtype}, episode_ends "
                             f"{self.episode_ends.dtype}; expected float32, float32, int64")
        if self.obs.ndim != 2 or self.action.ndim != 2 or self.episode_ends.ndim != 1:
            raise ValueError("obs and action must be [T, dim], episode_ends [E]")
        if self.obs.shape[1] == 0 or self.action.shape[1] == 0:
            raise ValueError("obs_dim or action_dim is 0")
        steps = self.obs.shape[0]
        if steps != self.action.shape[0]:
            raise ValueError(f"obs has {steps} rows but action has {self.action.shape[0]} rows")
        if steps == 0:
            raise ValueError("dataset has no steps")
        if len(self.episode_ends) == 0:
            raise ValueError("episode_ends is empty")
        previous = 0
        for index, end in enumerate(self.episode_ends.tolist()):
            if end <= previous:
                raise ValueError(f"episode_ends is not strictly increasing: entry {index} is {end} after {previous}")
            previous = end
        if previous != steps:
            raise ValueError(f"last episode end is {previous} but the dataset has {steps} steps")
        for name, values in (("obs", self.obs), ("action", self.action)):
            bad = np.argwhere(~np.isfinite(values))
            if len(bad):
                row, col = bad[0]
                raise ValueError(f"tensor `{name}` has a non-finite value {values[row, col]} at row {row}, column {col}")
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt is {self.dt}, expected a positive number of seconds")
        if not self.task:
            raise ValueError("task name is empty")

    def metadata(self) -> dict:
        meta = {key: str(value) for key, value in self.extra.items()}
        meta.update(task=self.task, dt=repr(float(self.dt)), source=self.source)
        return meta

    def save(self, path) -> None:
        from safetensors.numpy import save_file
        self.validate()
        save_file({"obs": np.ascontiguousarray(self.obs), "action": np.ascontiguousarray(self.action),
                   "episode_ends": np.ascontiguousarray(self.episode_ends)}, str(path), metadata=self.metadata())

    @staticmethod
    def load(path) -> "Dataset":
        from safetensors import safe_open
        with safe_open(str(path), framework="numpy") as f:
            meta = dict(f.metadata() or {})
            names = set(f.keys())
            for name in ("obs", "action", "episode_ends"):
                if name not in names:
                    raise ValueError(f"missing tensor `{name}` (found: {', '.join(sorted(names))})")
            tensors = {name: f.get_tensor(name) for name in ("obs", "action", "episode_ends")}
        for key in REQUIRED_METADATA:
            if key not in meta:
                raise ValueError(f"missing metadata `{key}`")
        try:
            dt = float(meta["dt"])
        except ValueError:
            raise ValueError(f"metadata `dt` is {meta['dt']!r}, not a number") from None
        extra = {k: v for k, v in meta.items() if k not in REQUIRED_METADATA}
        data = Dataset(tensors["obs"], tensors["action"], tensors["episode_ends"], meta["task"], dt, meta["source"], extra)
        data.validate()
        return data

    def json_meta(self, key: str):
        """A metadata value this package stores as JSON (seeds, versions, ...)."""
        return json.loads(self.extra[key])
