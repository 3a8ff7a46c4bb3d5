"""Per-call cost of one policy in process (the `frmd` module) and over the pipe protocol
(`frmd serve`), measured in the same run, in alternating rounds, beside the policy's own time
as `frmd bench` reports it.

    python frmd-host/python/bench.py --policy RUN/baked --frmd target/debug/frmd \\
        [--bench-dir RUN] [--calls 1000] [--rounds 5] [--batch 8]

`--policy`: what both sides load (a blob, a baked export or a checkpoint directory; `frmd serve`
gets `--blob`, `--baked` or `--ckpt` accordingly). `--bench-dir`: a run directory with
`student/` whose `frmd bench` table (frmd-core int8 1-step) is run and shown too. Every call is
an ACT with `executed` 0 on fixed observations after one RESET; medians over all rounds."""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

import frmd

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "examples", "frmd_client"))
from frmd_client.protocol import Client  # noqa: E402  (the pure-Python pipe client)


def serve_args(path):
    if os.path.isfile(path):
        return ["--blob", path]
    return ["--ckpt", path] if os.path.exists(os.path.join(path, "frmd.json")) else ["--baked", path]


def timed(call, n):
    """(round trip us, policy us) of n calls of `call() -> policy ns`."""
    trips, policy = [], []
    for _ in range(n):
        t0 = time.perf_counter_ns()
        ns = call()
        trips.append((time.perf_counter_ns() - t0) / 1e3)
        policy.append(ns / 1e3)
    return trips, policy


def frmd_bench(frmd_bin, run_dir, calls):
    """The `frmd bench` rows of RUN/student (frmd-core int8 1-step first)."""
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "bench.json")
        subprocess.run([frmd_bin, "bench", "--dir", run_dir, "--policy", os.path.join(run_dir, "student") + ":1",
                        "--calls", str(calls), "--json", out], check=True, stdout=subprocess.DEVNULL,
                       env={**os.environ, "RAYON_NUM_THREADS": "1"})
        return json.load(open(out))["results"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--policy", required=True)
    ap.add_argument("--frmd", required=True, help="the frmd binary")
    ap.add_argument("--bench-dir", help="run directory with student/ for `frmd bench`")
    ap.add_argument("--calls", type=int, default=1000, help="timed calls per side and round")
    ap.add_argument("--warmup", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--batch", type=int, default=8, help="also time act_batch of this many episodes (0: no)")
    args = ap.parse_args()

    policy = frmd.Policy.load(args.policy)
    client = Client([args.frmd, "serve", *serve_args(args.policy)], env={**os.environ, "RAYON_NUM_THREADS": "1"})
    info = client.hello()
    obs = np.linspace(-0.5, 0.5, policy.obs_history * policy.obs_dim).reshape(policy.obs_history, policy.obs_dim)
    obs = obs.astype(np.float32).astype(np.float64)
    obs_list = obs.tolist()
    policy.reset(1)
    client.reset(1)
    assert np.array_equal(policy.act(obs, executed=0), np.array(client.act(0, obs_list))), "the two sides differ"

    def local():
        policy.act(obs, executed=0)
        return policy.last_policy_ns

    def piped():
        client.act(0, obs_list)
        return client.last_policy_ns

    sides = {"in process": local, "pipe protocol": piped}
    if args.batch:
        batch = frmd.Policy.load(args.policy, batch=args.batch)
        batch.reset_batch(list(range(args.batch)))
        many = np.repeat(obs[None], args.batch, axis=0)

        def batched():
            batch.act_batch(many, executed=[0])
            return batch.last_policy_ns

        sides[f"in process, act_batch of {args.batch} (per call)"] = batched
    results = {name: ([], []) for name in sides}
    for name, call in sides.items():
        timed(call, args.warmup)
    for _ in range(args.rounds):
        for name, call in sides.items():
            trips, pol = timed(call, args.calls)
            results[name][0].extend(trips)
            results[name][1].extend(pol)
    status = client.close()

    rows = {}
    for name, (trips, pol) in results.items():
        rows[name] = {"roundtrip_us_median": float(np.median(trips)), "roundtrip_us_p99": float(np.percentile(trips, 99)),
                      "policy_us_median": float(np.median(pol)), "calls": len(trips)}
    bench = frmd_bench(args.frmd, args.bench_dir, args.calls) if args.bench_dir else None
    print(f"policy {policy.name} (obs {policy.obs_history} x {policy.obs_dim}, chunk {policy.horizon} x "
          f"{policy.action_dim}); {args.rounds} alternating rounds of {args.calls} calls, medians; "
          f"server exit status {status}")
    print(f"{'':48} {'round trip us':>14} {'p99 us':>10} {'policy us':>10}")
    for name, r in rows.items():
        print(f"{name:48} {r['roundtrip_us_median']:14.1f} {r['roundtrip_us_p99']:10.1f} {r['policy_us_median']:10.1f}")
    local_us, pipe_us = rows["in process"]["roundtrip_us_median"], rows["pipe protocol"]["roundtrip_us_median"]
    summary = {"rows": rows, "pipe_over_in_process": pipe_us / local_us}
    print(f"pipe / in process round trip: {pipe_us / local_us:.2f}x")
    if bench:
        core = bench[0]
        print(f"frmd bench `{core['label']}`: {core['median_us']:.1f} us median; in-process round trip / that: "
              f"{local_us / core['median_us']:.2f}x")
        summary.update(frmd_bench=bench, in_process_over_frmd_bench=local_us / core["median_us"])
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
