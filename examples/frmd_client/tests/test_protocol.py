"""The Python codec against the specification's worked examples, and the client against the mock
server (stdio and Unix socket), including every kind of error frame."""
import math
import os
import random
import re
import struct
import subprocess
import sys
import tempfile
import time

import pytest

from conftest import ROOT
from frmd_client import protocol as p
from frmd_client import session as session_mod

DOC = os.path.join(ROOT, "..", "..", "docs", "serve-protocol.md")
TOY = p.ModelInfo(obs_dim=3, action_dim=2, obs_history=2, horizon=3, exec_steps=2, float_type=p.F32, dt=0.0125,
                  name="toy")
OBS = [[0.5, -1.0, 2.0], [0.5, -1.0, 2.0]]
MOCK = [sys.executable, "-m", "frmd_client.mock_server"]
ENV = {**os.environ, "PYTHONPATH": ROOT}


def doc_blocks():
    text = open(DOC).read()
    return [bytes.fromhex(re.sub(r"[^0-9a-fA-F]", "", b)) for b in re.findall(r"```hex\n(.*?)```", text, re.S)]


def decode_frame(data, float_type=p.F32):
    msg_type, n = p.check_header(data[:8], requests=data[5] in p.REQUEST_TYPES)
    assert n == len(data) - 8
    if msg_type in p.REQUEST_TYPES:
        return p.decode_request(msg_type, data[8:], TOY)
    return p.decode_reply(msg_type, data[8:], float_type)


def test_worked_examples_of_the_specification():
    blocks = doc_blocks()
    decoded = [decode_frame(b) for b in blocks]
    nan_obs = decoded[7][3]
    assert math.isnan(nan_obs[3])
    assert decoded[:7] == [
        ("hello",), ("hello_ok", TOY), ("reset", 7, []), ("reset", 7, [0.0, 0.5]), ("reset_ok", 7),
        ("act", 0, 2, [0.5, -1.0, 2.0, 0.5, -1.0, 2.0]),
        ("chunk", 15000, 3, 2, 2, [0.0, 0.25, 0.5, 0.75, 1.0, -1.0])]
    assert decoded[7][:3] == ("act", 2, 2)
    assert decoded[8:] == [("error", 6, 0x03, False, "ACT observation 1 element 0 is NaN"), ("close",), ("close_ok",)]
    # Re-encoded by this codec: the same bytes.
    assert [p.encode_hello(), p.encode_hello_ok(TOY), p.encode_reset(7), p.encode_reset(7, [0.0, 0.5]),
            p.encode_reset_ok(7), p.encode_act(0, OBS), p.encode_chunk(15000, TOY, decoded[6][5]),
            p.encode_act(2, [OBS[0], [float("nan"), -1.0, 2.0]]),
            p.encode_error("NON_FINITE", decoded[8][4], 0x03), p.encode_close(), p.encode_close_ok()] == blocks
    # The same session replayed against the mock session rules gives the document's ERROR frame.
    out = []
    session = session_mod.Session(TOY, lambda seed: None, lambda obs, prev, rate: [0.0] * 6)
    stream = iter([b"".join(blocks[i] for i in (0, 2, 5, 7))])
    buf = bytearray(next(stream))
    session_mod.serve_stream(lambda n: bytes([buf.pop(0) for _ in range(min(n, len(buf)))]), out.append, session)
    assert out[-1] == blocks[8]


@pytest.mark.parametrize("float_type", [p.F32, p.F64])
def test_round_trip(float_type):
    info = p.ModelInfo(3, 2, 2, 3, 2, float_type, 0.0125, "toy é")
    for frame_bytes, expected in [
        (p.encode_reset(2**64 - 1, [0.25, -1.5], float_type), ("reset", 2**64 - 1, [0.25, -1.5])),
        (p.encode_act(4, OBS, float_type), ("act", 4, 2, OBS[0] + OBS[1])),
    ]:
        assert p.decode_request(frame_bytes[5], frame_bytes[8:], info) == expected
    chunk = p.encode_chunk(99, info, [0.1] * 6)
    got = p.decode_reply(p.CHUNK, chunk[8:], float_type)
    assert got[:5] == ("chunk", 99, 3, 2, 2)
    assert got[5] == pytest.approx([0.1] * 6, abs=1e-7 if float_type == p.F32 else 0)
    assert p.decode_reply(p.HELLO_OK, p.encode_hello_ok(info)[8:], None) == ("hello_ok", info)


@pytest.fixture
def server():
    clients = []

    def start(*args):
        c = p.Client(MOCK + list(args), env=ENV)
        clients.append(c)
        return c

    yield start
    for c in clients:
        if c.proc.poll() is None:
            c.proc.kill()
            c.proc.wait()


def test_client_and_mock_server_session(server):
    c = server("--policy", "hold", "--history", "2", "--horizon", "12", "--exec-steps", "8")
    info = c.hello()
    assert (info.obs_dim, info.action_dim, info.obs_history, info.horizon, info.exec_steps, info.float_type) == \
        (39, 4, 2, 12, 8, p.F32)
    assert info.dt == 0.0125 and info.name == "mock hold"
    c.reset(3, [0.5, -0.25, 0.0, 1.0])
    obs = [[0.1] * 39] * 2
    chunk = c.act(0, obs)
    assert len(chunk) == 12 and chunk[0] == [0.5, -0.25, 0.0, 1.0]
    assert c.last_policy_ns > 0
    c.act(8, obs)
    assert c.close() == 0


def test_every_error_frame_and_the_server_keeps_serving(server):
    c = server("--history", "2", "--horizon", "12", "--exec-steps", "8")
    obs = [[0.0] * 39] * 2

    def expect(code, data, text=""):
        c.send_raw(data)
        with pytest.raises(p.ServerError) as e:
            c.read_reply()
        assert e.value.name == code and text in e.value.text and not e.value.fatal
        return e.value

    expect("OUT_OF_ORDER", p.encode_reset(1), "RESET before HELLO")
    c.hello()
    expect("OUT_OF_ORDER", p.encode_act(0, obs), "ACT before RESET")
    c.reset(1)
    expect("UNSUPPORTED_VERSION", p.frame(p.HELLO, p.MAGIC, version=2), "version 2")
    expect("UNKNOWN_TYPE", p.frame(0x05, b"abc"), "0x05")
    expect("UNKNOWN_TYPE", p.frame(p.CHUNK), "not a request type")
    # Too large: answered at once; the payload that follows is skipped and the stream stays in sync.
    big = p.MAX_PAYLOAD + 3
    c.send_raw(struct.pack("<IBBH", big, 1, p.ACT, 0))
    with pytest.raises(p.ServerError) as e:
        c.read_reply()
    assert e.value.name == "FRAME_TOO_LARGE"
    c.send_raw(b"\0" * big)
    expect("BAD_VALUE", p.frame(p.HELLO, p.MAGIC, reserved=7), "reserved")
    expect("BAD_LENGTH", p.frame(p.HELLO, b"FRMDX"), "HELLO payload is 5 bytes")
    expect("BAD_VALUE", p.frame(p.HELLO, b"frmd"), "magic")
    expect("BAD_LENGTH", p.frame(p.ACT, p.encode_act(0, obs)[8:-4]), "ACT payload is 316 bytes, expected 8 + 2 x 39 x 4 = 320")
    expect("BAD_VALUE", p.encode_act(0, obs[:1]), "obs_count is 1")
    expect("BAD_VALUE", p.encode_act(3, obs), "no chunk")
    expect("BAD_VALUE", p.encode_reset(1, [0.0]), "init_count is 1")
    nan = [[0.0] * 39, [0.0] * 38 + [float("nan")]]
    expect("NON_FINITE", p.encode_act(0, nan), "ACT observation 1 element 38 is NaN")
    expect("NON_FINITE", p.encode_reset(1, [0.0, float("inf"), 0.0, 0.0]), "init_action element 1 is inf")
    expect("BAD_LENGTH", p.frame(p.CLOSE, b"x"), "CLOSE payload")
    assert len(c.act(0, obs)) == 12
    expect("BAD_VALUE", p.encode_act(13, obs), "previous chunk has 12 actions")
    assert len(c.act(12, obs)) == 12
    assert c.close() == 0


def test_policy_failure_is_reported():
    session = session_mod.Session(TOY, lambda s: None, lambda obs, prev, rate: 1 / 0)
    out = []
    data = bytearray(p.encode_hello() + p.encode_reset(1) + p.encode_act(0, OBS))
    session_mod.serve_stream(lambda n: bytes([data.pop(0) for _ in range(min(n, len(data)))]), out.append, session)
    reply = p.decode_reply(p.ERROR, out[-1][8:], p.F32)
    assert reply[1] == p.ERROR_CODES["POLICY_FAILED"] and "division by zero" in reply[4]


def test_end_of_input(server):
    # Clean end at a frame boundary: no reply, status 0.
    c = server()
    c.hello()
    c.proc.stdin.close()
    assert c.proc.wait(10) == 0 and c.proc.stdout.read() == b""
    # Inside a frame: TRUNCATED (fatal), status 1.
    c = server()
    c.send_raw(p.encode_hello()[:5])
    c.proc.stdin.close()
    with pytest.raises(p.ServerError) as e:
        c.read_reply()
    assert e.value.name == "TRUNCATED" and e.value.fatal and "after 5 of 8" in e.value.text
    assert c.proc.wait(10) == 1


def test_unix_socket_sessions():
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "s")
        proc = subprocess.Popen(MOCK + ["--socket", path], env=ENV)
        try:
            for _ in range(50):
                if os.path.exists(path):
                    break
                time.sleep(0.1)
            for seed in (1, 2):  # two connections, each a fresh session
                c = p.Client(socket_path=path)
                c.send_raw(p.encode_reset(seed))  # before HELLO in this connection
                with pytest.raises(p.ServerError, match="OUT_OF_ORDER"):
                    c.read_reply()
                c.hello()
                c.reset(seed)
                assert len(c.act(0, [[0.0] * 39] * 2)) == 12
                c.close()
        finally:
            proc.kill()
            proc.wait()


def test_fuzz_session_rules():
    """Random and mutated streams: serve_stream ends, and every reply decodes."""
    rng = random.Random(5)
    valid = (p.encode_hello() + p.encode_reset(3, [0.5, 0.5]) + p.encode_act(0, OBS) + p.encode_act(2, OBS)
             + p.encode_act(3, OBS) + p.encode_close())
    for round_ in range(400):
        if round_ % 2:
            data = bytearray(rng.randbytes(rng.randrange(120)))
        else:
            data = bytearray(valid)
            for _ in range(rng.randrange(1, 4)):
                if not data:
                    break
                i = rng.randrange(len(data))
                data[i] = rng.randrange(256) if rng.random() < 0.7 else data[i]
                if rng.random() < 0.2:
                    del data[i:]
        out = []
        session = session_mod.Session(TOY, lambda s: None, lambda obs, prev, rate: [0.0] * 6)
        end = session_mod.serve_stream(lambda n: bytes([data.pop(0) for _ in range(min(n, len(data)))]), out.append, session)
        assert end in ("closed", "eof", "truncated")
        for frame_bytes in out:
            msg_type, n = p.check_header(frame_bytes[:8], requests=False)
            p.decode_reply(msg_type, frame_bytes[8:], p.F32)
