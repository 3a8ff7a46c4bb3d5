"""The `frmd` module against `frmd serve`: the same policy and seed give bit-identical chunks in
process and over the pipe, for a blob, a baked export and checkpoints, in f32 and f64; the
HELLO_OK fields as attributes; batches; errors as exceptions with the Rust message; `act` lets
other Python threads run."""
import os
import threading
import time

import numpy as np
import pytest

import frmd
from conftest import ENV
from frmd_client import protocol as p

KINDS = {  # name -> (Policy.load path, frmd serve arguments), relative to the models directory
    "blob": ("s.blob", ["--blob", "s.blob"]),
    "baked": ("baked", ["--baked", "baked"]),
    "student": ("s", ["--ckpt", "s"]),
    "teacher": ("t", ["--ckpt", "t"]),
}


def served(models, frmd_bin, args):
    return p.Client([frmd_bin, "serve", args[0], os.path.join(models, args[1]), *args[2:]], env=ENV)


def observations(rng, policy, n):
    return [rng.uniform(-1, 1, (policy.obs_history, policy.obs_dim)) for _ in range(n)]


@pytest.mark.parametrize("kind", list(KINDS))
@pytest.mark.parametrize("float64", [False, True])
def test_chunks_are_bit_identical_to_frmd_serve(models, frmd_bin, kind, float64):
    path, args = KINDS[kind]
    policy = frmd.Policy.load(os.path.join(models, path), float64=float64)
    client = served(models, frmd_bin, args + ["--float", "f64" if float64 else "f32"])
    info = client.hello()
    assert (policy.obs_dim, policy.action_dim, policy.obs_history, policy.horizon, policy.exec_steps) == \
        (info.obs_dim, info.action_dim, info.obs_history, info.horizon, info.exec_steps)
    assert policy.dt == info.dt and policy.float64 == (info.float_type == p.F64)
    assert policy.name == info.name
    # dt (the rate of the previous action) is known for all but the bare blob.
    assert (policy.dt > 0) == (kind != "blob")
    rng = np.random.default_rng(3)
    for seed, init, executed in [(7, None, [0, 8, 3, 0, 5]), (2**63 + 5, [0.25, -0.5], [0, 8, 8])]:
        policy.reset(seed, init)
        client.reset(seed, init or ())
        for done, obs in zip(executed, observations(rng, policy, len(executed))):
            if not float64:  # the pipe carries f32: hand both sides the same values
                obs = obs.astype(np.float32).astype(np.float64)
            ours = policy.act(obs, executed=done)
            theirs = np.array(client.act(done, obs.tolist()))
            assert ours.shape == (policy.horizon, policy.action_dim) and ours.dtype == np.float64
            assert np.array_equal(ours, theirs), f"{kind} seed {seed} executed {done}"
    assert client.close() == 0


def test_default_executed_and_the_same_seed_repeat(models):
    policy = frmd.Policy.load(os.path.join(models, "baked"))
    obs = np.linspace(-0.5, 0.5, policy.obs_history * policy.obs_dim).reshape(policy.obs_history, -1)
    policy.reset(11)
    first = policy.act(obs)  # executed defaults to 0 on an episode's first chunk
    second = policy.act(obs)  # ... and to exec_steps after it
    policy.reset(11)
    assert np.array_equal(policy.act(obs, executed=0), first)
    assert np.array_equal(policy.act(obs, executed=policy.exec_steps), second)
    assert policy.last_policy_ns > 0
    # A flat list of the right length is accepted too.
    policy.reset(11)
    assert np.array_equal(policy.act(obs.ravel().tolist()), first)


def test_a_batch_is_independent_episodes(models):
    path = os.path.join(models, "s")
    batch = frmd.Policy.load(path, batch=3)
    single = frmd.Policy.load(path)
    assert batch.batch == 3 and single.batch == 1
    rng = np.random.default_rng(5)
    obs = rng.uniform(-1, 1, (3, batch.obs_history, batch.obs_dim))
    seeds = [1, 2, 3]
    batch.reset_batch(seeds, init_actions=np.full((3, batch.action_dim), 0.1))
    chunks = batch.act_batch(obs)
    assert chunks.shape == (3, batch.horizon, batch.action_dim)
    nexts = batch.act_batch(obs[::-1], executed=[8, 2, 0])
    for i, seed in enumerate(seeds):
        single.reset(seed, [0.1] * single.action_dim)
        assert np.array_equal(single.act(obs[i]), chunks[i])
        assert np.array_equal(single.act(obs[2 - i], executed=[8, 2, 0][i]), nexts[i])
    assert not np.array_equal(chunks[0], chunks[1])


def test_errors_are_exceptions_with_the_rust_message(models, tmp_path):
    with pytest.raises(frmd.FrmdError, match="no-such-policy"):
        frmd.Policy.load(str(tmp_path / "no-such-policy"))
    (tmp_path / "junk.blob").write_bytes(b"not a blob")
    with pytest.raises(frmd.FrmdError, match="junk.blob"):
        frmd.Policy.load(str(tmp_path / "junk.blob"))
    with pytest.raises(frmd.FrmdError, match="exec-steps 99"):
        frmd.Policy.load(os.path.join(models, "baked"), exec_steps=99)
    with pytest.raises(ValueError, match="solver"):
        frmd.Policy.load(os.path.join(models, "t"), solver="rk45")
    policy = frmd.Policy.load(os.path.join(models, "baked"))
    obs = np.zeros((policy.obs_history, policy.obs_dim))
    with pytest.raises(frmd.FrmdError, match="OUT_OF_ORDER: ACT before RESET"):
        policy.act(obs)
    policy.reset(1)
    with pytest.raises(frmd.FrmdError, match="BAD_VALUE: ACT executed is 3 but no chunk"):
        policy.act(obs, executed=3)
    bad = obs.copy()
    bad[1, 2] = np.nan
    with pytest.raises(frmd.FrmdError, match="NON_FINITE: ACT observation 1 element 2 is NaN"):
        policy.act(bad)
    bad[1, 2] = 1e300  # finite in f64, infinite as f32: refused as the f32 wire refuses it
    with pytest.raises(frmd.FrmdError, match="NON_FINITE"):
        policy.act(bad)
    with pytest.raises(ValueError, match=r"obs has shape \[3, 6\]"):
        policy.act(np.zeros((3, 6)))
    with pytest.raises(frmd.FrmdError, match="NON_FINITE: RESET init_action"):
        policy.reset(1, [float("inf"), 0.0])
    with pytest.raises(ValueError, match="batch=1"):
        frmd.Policy.load(os.path.join(models, "baked"), batch=0)
    with pytest.raises(ValueError, match="reset_batch and act_batch"):
        frmd.Policy.load(os.path.join(models, "baked"), batch=2).act(obs)
    # A rejected call changed nothing: the episode goes on.
    assert policy.act(obs).shape == (policy.horizon, policy.action_dim)


def test_act_releases_the_gil(models):
    """A Python thread keeps running while one long `act_batch` (256 DDPM-100 chunks) runs."""
    policy = frmd.Policy.load(os.path.join(models, "dp"), batch=256, steps=100)
    obs = np.zeros((256, policy.obs_history, policy.obs_dim))
    policy.reset_batch(list(range(256)))
    ticks, stop = [], threading.Event()

    def tick():
        while not stop.is_set():
            ticks.append(time.perf_counter())

    thread = threading.Thread(target=tick)
    thread.start()
    try:
        time.sleep(0.05)
        t0 = time.perf_counter()
        policy.act_batch(obs)
        t1 = time.perf_counter()
    finally:
        stop.set()
        thread.join()
    inside = [t for t in ticks if t0 <= t <= t1]
    assert t1 - t0 > 0.1, f"the call took {t1 - t0:.3f} s, too short to tell"
    gaps = np.diff([t0] + inside + [t1])
    # With the GIL held the thread would stall for the whole call.
    assert gaps.max() < 0.5 * (t1 - t0), f"longest stall {gaps.max():.3f} s of a {t1 - t0:.3f} s call"
