"""The protocol's cost from Python: HELLO, RESET, warm-up ACTs, then timed ACTs (by default of
MetaWorld's shapes: 2 observations of 39 values in, 12 x 4 actions out, f32) against
`mock_server --policy zeros` or any server command; reported as client round trip, the server's
policy_ns and their difference (the overhead). `cpu` pins this process and the server (taskset)
to one CPU.
"""
from __future__ import annotations

import os
import shlex
import sys
import time

import numpy as np

from . import metrics
from .protocol import Client


def protocol_roundtrip(calls: int = 2000, warmup: int = 200, cpu: int | None = None, history: int = 2,
                       horizon: int = 12, server: str | None = None, obs_dim: int = 39, action_dim: int = 4) -> dict:
    """`server`: a server command (e.g. `frmd serve --ckpt DIR --zeros`) instead of the mock."""
    command = shlex.split(server) if server else [
        sys.executable, "-m", "frmd_client.mock_server", "--policy", "zeros", "--history", str(history),
        "--horizon", str(horizon), "--exec-steps", str(min(8, horizon)), "--obs-dim", str(obs_dim),
        "--action-dim", str(action_dim)]
    previous = os.sched_getaffinity(0)
    if cpu is not None:
        command = ["taskset", "-c", str(cpu)] + command
        os.sched_setaffinity(0, {cpu})
    try:
        client = Client(command, env={**os.environ, "PYTHONPATH": _package_root()})
        info = client.hello()
        client.reset(1)
        obs = [np.linspace(-1, 1, info.obs_dim).tolist()] * info.obs_history
        roundtrip, policy = [], []
        for i in range(warmup + calls):
            t0 = time.perf_counter_ns()
            client.act(0, obs)
            elapsed = time.perf_counter_ns() - t0
            if i >= warmup:
                roundtrip.append(elapsed / 1e3)
                policy.append(client.last_policy_ns / 1e3)
        status = client.close()
    finally:
        os.sched_setaffinity(0, previous)
    overhead = [r - p for r, p in zip(roundtrip, policy)]
    return {"server": server or "mock_server --policy zeros", "pinned_cpu": cpu, "calls": calls, "roundtrip_us_median": metrics.quantile(roundtrip, 0.5),
            "roundtrip_us_p99": metrics.quantile(roundtrip, 0.99), "policy_us_median": metrics.quantile(policy, 0.5),
            "overhead_us_median": metrics.quantile(overhead, 0.5), "overhead_us_p99": metrics.quantile(overhead, 0.99),
            "server_exit_status": status}


def _package_root() -> str:
    """The directory holding frmd_client (for the mock server's PYTHONPATH)."""
    return os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
