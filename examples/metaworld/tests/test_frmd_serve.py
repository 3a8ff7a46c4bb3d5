"""The client against the real `frmd serve` (not the mock): a tiny MetaWorld-shaped student
trained for a few steps, served from its checkpoint, its int8 export and over a Unix socket;
malformed frames get error frames and the server keeps serving.

The binary is $FRMD_BIN or target/debug/frmd of this repository (`cargo build -p frmd-host`);
the tests skip, saying so, when neither exists."""
import math
import os
import struct
import subprocess
import tempfile
import time

import numpy as np
import pytest

from conftest import ROOT
from frmd_client import protocol as p
from frmd_metaworld.collect import collect

FRMD = os.environ.get("FRMD_BIN") or os.path.join(ROOT, "..", "..", "target", "debug", "frmd")
ENV = {**os.environ, "RAYON_NUM_THREADS": "1"}
pytestmark = pytest.mark.skipif(not os.path.exists(FRMD), reason=f"no frmd binary at {FRMD} (cargo build -p frmd-host)")


def frmd(*args):
    subprocess.run([FRMD, *args], check=True, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


@pytest.fixture(scope="module")
def models():
    with tempfile.TemporaryDirectory() as d:
        data, _ = collect("reach-v3", 2, 0)
        data.save(os.path.join(d, "reach.safetensors"))
        common = ["--data", os.path.join(d, "reach.safetensors"), "--steps", "3", "--warmup", "1", "--log-every", "1"]
        frmd("train", "teacher", *common, "--backbone", "mlp:32,32", "--out", os.path.join(d, "teacher"))
        frmd("train", "student", "--teacher", os.path.join(d, "teacher"), *common, "--out", os.path.join(d, "student"))
        frmd("export", "--ckpt", os.path.join(d, "student"), "--out", os.path.join(d, "baked"))
        yield d


def start(*args):
    return p.Client([FRMD, "serve", *args], env=ENV, stderr=subprocess.DEVNULL)


@pytest.mark.parametrize("which", ["ckpt", "baked"])
def test_session_with_the_real_server(models, which):
    c = start(f"--{which}", os.path.join(models, "student" if which == "ckpt" else "baked"))
    info = c.hello()
    assert (info.obs_dim, info.action_dim, info.obs_history, info.horizon, info.exec_steps, info.float_type) == \
        (39, 4, 2, 12, 8, p.F32)
    assert abs(info.dt - 0.0125) < 1e-9
    obs = [np.linspace(-0.5, 0.5, 39).tolist()] * 2
    c.reset(7)
    first = c.act(0, obs)
    assert len(first) == 12 and all(len(a) == 4 and all(math.isfinite(v) for v in a) for a in first)
    assert c.last_policy_ns > 0
    c.act(8, obs)
    c.reset(7)
    assert c.act(0, obs) == first  # the same seed and inputs give the same chunk
    assert c.close() == 0


def test_every_kind_of_bad_input_gets_an_error_and_the_server_keeps_serving(models):
    c = start("--ckpt", os.path.join(models, "student"))
    obs = [[0.0] * 39] * 2

    def expect(code, data):
        c.send_raw(data)
        with pytest.raises(p.ServerError) as e:
            c.read_reply()
        assert e.value.name == code and not e.value.fatal, e.value
        assert e.value.text

    expect("OUT_OF_ORDER", p.encode_reset(1))  # before HELLO
    c.hello()
    expect("OUT_OF_ORDER", p.encode_act(0, obs))  # before RESET
    c.reset(1)
    expect("UNSUPPORTED_VERSION", p.frame(p.HELLO, b"FRMD", version=9))
    expect("UNKNOWN_TYPE", p.frame(0x42))
    expect("FRAME_TOO_LARGE", struct.pack("<IBBH", (1 << 20) + 1, 1, p.ACT, 0) + b"\0" * ((1 << 20) + 1))
    expect("BAD_LENGTH", p.frame(p.ACT, b"\0" * 11))
    expect("BAD_VALUE", p.frame(p.HELLO, b"NOPE"))
    expect("NON_FINITE", p.encode_act(0, [[float("nan")] + [0.0] * 38, [0.0] * 39]))
    expect("BAD_VALUE", p.encode_act(99, obs))  # more executed than the chunk had
    assert len(c.act(0, obs)) == 12  # still serving
    assert c.close() == 0


def test_truncated_input_and_socket(models):
    proc = subprocess.Popen([FRMD, "serve", "--ckpt", os.path.join(models, "student")], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=ENV)
    out, _ = proc.communicate(p.encode_hello()[:5], timeout=60)
    assert proc.returncode == 1 and out[5] == p.ERROR and out[8 + 3] == 1  # TRUNCATED, fatal
    path = os.path.join(models, "serve.sock")
    server = subprocess.Popen([FRMD, "serve", "--baked", os.path.join(models, "baked"), "--socket", path,
                               "--connections", "2"], stderr=subprocess.DEVNULL, env=ENV)
    try:
        for _ in range(300):
            if os.path.exists(path):
                break
            time.sleep(0.1)
        for seed in (1, 2):
            c = p.Client(socket_path=path)
            assert c.hello().obs_dim == 39
            c.reset(seed)
            assert len(c.act(0, [[0.0] * 39] * 2)) == 12
            c.close()
        assert server.wait(timeout=60) == 0
    finally:
        if server.poll() is None:
            server.kill()


def _wheel():
    """The frmd wheel, or a skip (a failure with FRMD_REQUIRE_WHEEL=1, as in CI)."""
    if os.environ.get("FRMD_REQUIRE_WHEEL") == "1":
        import frmd
        return frmd
    return pytest.importorskip("frmd", reason="the frmd wheel is not installed (pip install ./frmd-host/python)")


@pytest.mark.parametrize("which", ["ckpt", "baked"])
def test_in_process_and_over_the_protocol_give_the_same_episodes(models, which):
    from frmd_metaworld.evaluate import evaluate
    from frmd_client.policy_client import InProcessPolicy, open_policy
    from frmd_metaworld.tasks import DT
    _wheel()
    command = f"{FRMD} serve --{which} {os.path.join(models, 'student' if which == 'ckpt' else 'baked')} --exec-steps 6"
    reports = []
    for in_process in (False, True):
        policy = open_policy(command, in_process=in_process, dt=DT)
        assert isinstance(policy, InProcessPolicy) == in_process
        try:
            reports.append(evaluate("reach-v3", policy, episodes=2, warmup_calls=1))
        finally:
            policy.close()
    served, local = reports
    assert local["per_episode"] == served["per_episode"]
    assert (local["exec_steps"], local["history"], local["horizon"]) == (6, 2, 12)
    assert local["chunk_calls"] == served["chunk_calls"] and local["latency_us_median"] > 0
