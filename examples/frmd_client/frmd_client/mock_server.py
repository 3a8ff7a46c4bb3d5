"""A small policy server speaking the `frmd serve` protocol, for tests and overhead measurements.

    python -m frmd_client.mock_server --policy zeros [--obs-dim 39 --horizon 12 --exec-steps 8 ...]

Policies: `zeros` (a chunk of zeros: measures the protocol alone), `hold` (repeats the last
commanded action: shows the server's `executed` bookkeeping), and `expert` when a simulator
package passes `expert=` to `main` (`python -m frmd_metaworld.mock_server --policy expert --task
push-v3`: MetaWorld's scripted expert, horizon 1, f64 by default). The server keeps standard
output for frames only (anything a library prints goes to standard error).
"""
from __future__ import annotations

import argparse
import os
import socket
import sys

from . import protocol as p
from . import session as session_mod


def make_session(args, expert=None) -> session_mod.Session:
    """`expert(args, float_type) -> (ModelInfo, act)`: the simulator package's `--policy expert`."""
    float_type = p.F64 if args.float == "f64" else p.F32
    if args.policy == "expert":
        info, act = expert(args, float_type)
    else:
        info = p.ModelInfo(args.obs_dim, args.action_dim, args.history, args.horizon, args.exec_steps, float_type,
                           args.dt, f"mock {args.policy}")
        if args.policy == "zeros":
            zeros = [0.0] * (info.horizon * info.action_dim)
            act = lambda obs, prev, rate: zeros
        else:  # hold
            act = lambda obs, prev, rate: list(prev) * info.horizon
    info.validate()
    return session_mod.Session(info, policy_reset=lambda seed: None, policy_act=act)


def main(argv=None, expert=None, default_task: str | None = None, prog: str | None = None) -> int:
    """The server's command line. `expert(args, float_type) -> (ModelInfo, act)` adds `--policy
    expert` (a simulator package's scripted expert for `--task`, default `default_task`)."""
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.splitlines()[0])
    ap.add_argument("--policy", choices=["zeros", "hold"] + (["expert"] if expert else []), default="zeros",
                    help="zeros: a chunk of zeros; hold: repeat the last commanded action"
                    + ("; expert: the simulator's scripted expert for --task" if expert else ""))
    if expert:
        ap.add_argument("--task", default=default_task, help="task of --policy expert")
    ap.add_argument("--float", choices=["f32", "f64"], default=None, help="value type (default: f64 for the expert, else f32)")
    ap.add_argument("--obs-dim", type=int, default=39, help="values per observation (zeros, hold)")
    ap.add_argument("--action-dim", type=int, default=4, help="values per action (zeros, hold)")
    ap.add_argument("--history", type=int, default=2, help="observations per ACT (zeros, hold)")
    ap.add_argument("--horizon", type=int, default=12, help="actions per chunk (zeros, hold)")
    ap.add_argument("--exec-steps", type=int, default=8, help="actions to execute per chunk (zeros, hold)")
    ap.add_argument("--dt", type=float, default=0.0125, help="control period announced, seconds (zeros, hold)")
    ap.add_argument("--socket", help="serve on this Unix socket path instead of stdin/stdout")
    args = ap.parse_args(argv)
    if args.float is None:
        args.float = "f64" if args.policy == "expert" else "f32"
    # Frames go to the original standard output; stray prints of libraries go to standard error.
    frames_fd = os.dup(1)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    session = make_session(args, expert)

    def write_to(fd):
        def write(data: bytes) -> None:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view):]
        return write

    if args.socket is None:
        end = session_mod.serve_stream(lambda n: os.read(0, n), write_to(frames_fd), session)
        return 1 if end == "truncated" else 0
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(args.socket)
    server.listen(1)
    while True:
        conn, _ = server.accept()
        with conn:
            fresh = session_mod.Session(session.info, session.policy_reset, session.policy_act)
            try:
                session_mod.serve_stream(conn.recv, write_to(conn.fileno()), fresh)
            except OSError as e:
                print(f"connection ended: {e}", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
