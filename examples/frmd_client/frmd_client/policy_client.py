"""A chunking policy seen from a simulator loop, whichever way it runs: behind `frmd serve` over
the protocol (`ServedPolicy`), or in this process through the `frmd` wheel (`InProcessPolicy`,
`pip install ./frmd-host/python`), chosen by one flag (`open_policy(..., in_process=True)`). Both
give the same chunks for the same policy and seed. `Episode` keeps what a client of the protocol
keeps: the last M observations and the number of actions executed since the last chunk.

Nothing here knows MetaWorld: a package for another simulator uses this module as it is."""
from __future__ import annotations

import argparse
import shlex
import time
from collections import deque
from typing import Sequence

import numpy as np

from .protocol import F64, Client


class ServedPolicy:
    """A policy behind `frmd serve` (or any server of the protocol), started as a child process.
    `dt`: the client's control period; a server announcing another (non-zero) one is refused."""

    def __init__(self, command: str, stderr=None, dt: float | None = None):
        self.client = Client(command, stderr=stderr)
        info = self.client.hello()
        self.name = info.name or command
        self.history, self.horizon, self.exec_steps = info.obs_history, info.horizon, info.exec_steps
        self.float_type = "f64" if info.float_type == F64 else "f32"
        self.obs_dim, self.action_dim, self.dt = info.obs_dim, info.action_dim, info.dt
        check_dt(self.dt, dt, "the server's policy")
        self.info = info

    def reset(self, seed: int, init_action=None) -> None:
        """Starts an episode; `init_action`: the last commanded action before it (None: the
        server's default)."""
        self.client.reset(seed, [float(v) for v in init_action] if init_action is not None else ())

    def act(self, observations, executed: int):
        """(chunk [N][K], the policy's own seconds)."""
        chunk = self.client.act(executed, [np.asarray(o, dtype=np.float64).tolist() for o in observations])
        return chunk, self.client.last_policy_ns * 1e-9

    def close(self) -> None:
        self.client.close()


# `frmd serve` options that `frmd.Policy.load` takes too (the wire itself has no in-process meaning).
_SERVE = argparse.ArgumentParser(prog="frmd serve", add_help=False)
for _flag in ("--ckpt", "--baked", "--blob"):
    _SERVE.add_argument(_flag)
_SERVE.add_argument("--steps", type=int)
_SERVE.add_argument("--solver")
_SERVE.add_argument("--exec-steps", type=int)
_SERVE.add_argument("--dt", type=float)
_SERVE.add_argument("--float", choices=["f32", "f64"], default="f32")
_SERVE.add_argument("--init-action", type=lambda s: [float(v) for v in s.split(",")])


def load_options(command: str) -> tuple[str, dict]:
    """(policy path, `frmd.Policy.load` keyword arguments) of a `frmd serve ...` command line."""
    words = shlex.split(command)
    if "serve" not in words:
        raise ValueError(f"not a `frmd serve` command: {command!r}")
    args, rest = _SERVE.parse_known_args(words[words.index("serve") + 1:])
    if rest:
        raise ValueError(f"cannot run in process: `frmd serve` options {rest} have no in-process meaning")
    paths = [p for p in (args.ckpt, args.baked, args.blob) if p]
    if len(paths) != 1:
        raise ValueError(f"give one of --ckpt, --baked, --blob in {command!r}")
    options = {"steps": args.steps, "solver": args.solver, "exec_steps": args.exec_steps, "dt": args.dt,
               "init_action": args.init_action, "float64": args.float == "f64"}
    return paths[0], {k: v for k, v in options.items() if v not in (None, False)}


class InProcessPolicy:
    """The policy of a `frmd serve` command line, run in this process by the `frmd` wheel."""

    def __init__(self, command: str, dt: float | None = None):
        try:
            import frmd
        except ImportError as e:
            raise ImportError("in-process policies need the frmd wheel: pip install ./frmd-host/python "
                              "(from the repository root)") from e
        path, options = load_options(command)
        self.policy = frmd.Policy.load(path, **options)
        p = self.policy
        self.name = p.name
        self.history, self.horizon, self.exec_steps = p.obs_history, p.horizon, p.exec_steps
        self.float_type = "f64" if p.float64 else "f32"
        self.obs_dim, self.action_dim, self.dt = p.obs_dim, p.action_dim, p.dt
        check_dt(self.dt, dt, "the policy")

    def reset(self, seed: int, init_action=None) -> None:
        if init_action is None:
            self.policy.reset(seed)
        else:
            self.policy.reset(seed, init_action=[float(v) for v in init_action])

    def act(self, observations, executed: int):
        chunk = self.policy.act(np.asarray(observations, dtype=np.float64), executed=executed)
        return chunk, self.policy.last_policy_ns * 1e-9

    def close(self) -> None:
        pass


def check_dt(announced: float, expected: float | None, who: str) -> None:
    """Refuses a policy trained at another control period (0: unknown, accepted). The period is
    an f32 widened to f64: compared with a tolerance."""
    if expected is not None and announced != 0 and abs(announced - expected) > 1e-6 * expected:
        raise ValueError(f"{who} was trained at dt {announced} s, the simulator steps {expected} s")


def open_policy(command: str, in_process: bool = False, dt: float | None = None, stderr=None):
    """The policy of `frmd serve ...` `command`: over the protocol, or in process."""
    return InProcessPolicy(command, dt=dt) if in_process else ServedPolicy(command, stderr=stderr, dt=dt)


class Episode:
    """The client's side of an episode: the last M observations (oldest first; the first one
    repeated M times at the start) and the actions executed since the last chunk. `init_action`:
    the command that holds the robot where the episode starts, sent with RESET (None: the
    server's default, zeros)."""

    def __init__(self, policy, seed: int, first_obs: Sequence[float], init_action=None):
        if init_action is None:
            policy.reset(seed)
        else:
            policy.reset(seed, init_action)
        self.policy = policy
        self.history = deque([first_obs] * policy.history, maxlen=policy.history)
        self.executed = 0

    def chunk(self):
        """(the next chunk [N][K], policy seconds, round-trip seconds)."""
        t0 = time.perf_counter()
        chunk, policy_seconds = self.policy.act(list(self.history), self.executed)
        roundtrip = time.perf_counter() - t0
        self.executed = 0
        return chunk, policy_seconds, roundtrip

    def executed_action(self, obs: Sequence[float]) -> None:
        """One action of the last chunk was executed and led to `obs`."""
        self.executed += 1
        self.history.append(obs)
