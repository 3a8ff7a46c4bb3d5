"""The `frmd serve` protocol, version 1 (docs/serve-protocol.md): frame codec for both
directions and a client over a child process's pipes or a Unix socket. The server-side session
rules (for the mock server in `mock_server.py`) are in `session.py`.

Messages are plain tuples of values; floats travel as f32 or f64 as HELLO_OK announces.
"""
from __future__ import annotations

import math
import os
import shlex
import socket
import struct
import subprocess
from dataclasses import dataclass
from typing import Callable, Sequence

VERSION = 1
HEADER = struct.Struct("<IBBH")  # payload_len, version, type, reserved
HEADER_LEN = HEADER.size
MAX_PAYLOAD = 1 << 20
MAGIC = b"FRMD"
MAX_NAME = 256
MAX_TEXT = 1024

HELLO, RESET, ACT, CLOSE = 0x01, 0x02, 0x03, 0x04
HELLO_OK, RESET_OK, CHUNK, CLOSE_OK, ERROR = 0x81, 0x82, 0x83, 0x84, 0xFF
TYPE_NAMES = {HELLO: "HELLO", RESET: "RESET", ACT: "ACT", CLOSE: "CLOSE", HELLO_OK: "HELLO_OK",
              RESET_OK: "RESET_OK", CHUNK: "CHUNK", CLOSE_OK: "CLOSE_OK", ERROR: "ERROR"}
REQUEST_TYPES = (HELLO, RESET, ACT, CLOSE)

ERROR_NAMES = {1: "UNSUPPORTED_VERSION", 2: "UNKNOWN_TYPE", 3: "FRAME_TOO_LARGE", 4: "BAD_LENGTH",
               5: "BAD_VALUE", 6: "NON_FINITE", 7: "OUT_OF_ORDER", 8: "POLICY_FAILED",
               9: "TRUNCATED"}
ERROR_CODES = {name: code for code, name in ERROR_NAMES.items()}

F32, F64 = 1, 2
_VALUE = {F32: "f", F64: "d"}
HELLO_OK_FIXED = struct.Struct("<HHHHHBBIdH")  # 26 bytes before the name
CHUNK_FIXED = struct.Struct("<QHHHH")  # 16 bytes before the actions
ERROR_FIXED = struct.Struct("<HBBH")  # 6 bytes before the text


class ProtocolError(Exception):
    """A protocol violation with its ERROR code name (`BAD_LENGTH`, ...)."""

    def __init__(self, code: str, text: str):
        super().__init__(f"{code}: {text}")
        self.code, self.text = code, text


class ServerError(Exception):
    """An ERROR frame received from the server."""

    def __init__(self, code: int, request_type: int, fatal: bool, text: str):
        name = ERROR_NAMES.get(code, f"code {code}")
        super().__init__(f"server error {name} on {TYPE_NAMES.get(request_type, hex(request_type))}: {text}")
        self.code, self.name, self.request_type, self.fatal, self.text = code, name, request_type, fatal, text


@dataclass(frozen=True)
class ModelInfo:
    """What HELLO_OK announces."""
    obs_dim: int
    action_dim: int
    obs_history: int
    horizon: int
    exec_steps: int
    float_type: int = F32
    dt: float = 0.0
    name: str = ""
    max_payload: int = MAX_PAYLOAD

    @property
    def width(self) -> int:
        return 4 if self.float_type == F32 else 8

    def validate(self) -> None:
        for key in ("obs_dim", "action_dim", "obs_history", "horizon"):
            if not 1 <= getattr(self, key) <= 0xFFFF:
                raise ProtocolError("BAD_VALUE", f"{key} is {getattr(self, key)}, expected 1..=65535")
        if not 1 <= self.exec_steps <= self.horizon:
            raise ProtocolError("BAD_VALUE", f"exec_steps {self.exec_steps} is outside 1..={self.horizon}")
        if self.float_type not in (F32, F64):
            raise ProtocolError("BAD_VALUE", f"float_type is {self.float_type}, expected 1 or 2")
        if self.max_payload != MAX_PAYLOAD:
            raise ProtocolError("BAD_VALUE", f"max_payload is {self.max_payload}, version 1 uses {MAX_PAYLOAD}")
        if not (math.isfinite(self.dt) and self.dt >= 0):
            raise ProtocolError("BAD_VALUE", f"dt is {self.dt}, expected seconds >= 0")
        if len(self.name.encode()) > MAX_NAME:
            raise ProtocolError("BAD_VALUE", f"name is longer than {MAX_NAME} bytes")
        if 8 + self.obs_history * self.obs_dim * self.width > MAX_PAYLOAD or \
                16 + self.horizon * self.action_dim * self.width > MAX_PAYLOAD:
            raise ProtocolError("BAD_VALUE", "ACT or CHUNK payloads of this model exceed the limit")


def _values(values: Sequence[float], float_type: int) -> bytes:
    return struct.pack(f"<{len(values)}{_VALUE[float_type]}", *[float(v) for v in values])


def _unpack_values(payload: bytes, offset: int, count: int, float_type: int) -> list[float]:
    return list(struct.unpack_from(f"<{count}{_VALUE[float_type]}", payload, offset))


def frame(msg_type: int, payload: bytes = b"", version: int = VERSION, reserved: int = 0) -> bytes:
    return HEADER.pack(len(payload), version, msg_type, reserved) + payload


def _truncate(text: str, limit: int) -> bytes:
    raw = text.encode()
    if len(raw) <= limit:
        return raw
    return raw[:limit].decode(errors="ignore").encode()


# ---- encoding -------------------------------------------------------------------------------

def encode_hello() -> bytes:
    return frame(HELLO, MAGIC)


def encode_reset(seed: int, init_action: Sequence[float] = (), float_type: int = F32) -> bytes:
    return frame(RESET, struct.pack("<QI", seed, len(init_action)) + _values(init_action, float_type))


def encode_act(executed: int, observations: Sequence[Sequence[float]], float_type: int = F32) -> bytes:
    flat = [v for obs in observations for v in obs]
    return frame(ACT, struct.pack("<II", executed, len(observations)) + _values(flat, float_type))


def encode_close() -> bytes:
    return frame(CLOSE)


def encode_hello_ok(info: ModelInfo) -> bytes:
    name = _truncate(info.name, MAX_NAME)
    return frame(HELLO_OK, HELLO_OK_FIXED.pack(info.obs_dim, info.action_dim, info.obs_history, info.horizon,
                                               info.exec_steps, info.float_type, 0, info.max_payload, info.dt,
                                               len(name)) + name)


def encode_reset_ok(seed: int) -> bytes:
    return frame(RESET_OK, struct.pack("<Q", seed))


def encode_chunk(policy_ns: int, info: ModelInfo, actions: Sequence[float]) -> bytes:
    return frame(CHUNK, CHUNK_FIXED.pack(policy_ns, info.horizon, info.action_dim, info.exec_steps, 0)
                 + _values(actions, info.float_type))


def encode_close_ok() -> bytes:
    return frame(CLOSE_OK)


def encode_error(code: str, text: str, request_type: int = 0, fatal: bool = False) -> bytes:
    raw = _truncate(text, MAX_TEXT)
    return frame(ERROR, ERROR_FIXED.pack(ERROR_CODES[code], request_type, int(fatal), len(raw)) + raw)


# ---- decoding -------------------------------------------------------------------------------

def check_header(head: bytes, requests: bool) -> tuple[int, int]:
    """(type, payload_len) of an 8-byte header, checked in the specification's order."""
    payload_len, version, msg_type, reserved = HEADER.unpack(head)
    if version != VERSION:
        raise ProtocolError("UNSUPPORTED_VERSION",
                            f"protocol version {version} is not supported; this server speaks version {VERSION}")
    if payload_len > MAX_PAYLOAD:
        raise ProtocolError("FRAME_TOO_LARGE", f"payload of {payload_len} bytes exceeds the limit of {MAX_PAYLOAD}")
    if reserved != 0:
        raise ProtocolError("BAD_VALUE", f"header reserved field is {reserved:#06x}, must be 0")
    kind = "request" if requests else "reply"
    if msg_type not in TYPE_NAMES:
        raise ProtocolError("UNKNOWN_TYPE", f"unknown {kind} type {msg_type:#04x}")
    if (msg_type in REQUEST_TYPES) != requests:
        raise ProtocolError("UNKNOWN_TYPE", f"type {msg_type:#04x} ({TYPE_NAMES[msg_type]}) is not a {kind} type")
    return msg_type, payload_len


def _expect_len(what: str, payload: bytes, expected: int, formula: str) -> None:
    if len(payload) != expected:
        raise ProtocolError("BAD_LENGTH", f"{what} payload is {len(payload)} bytes, expected {formula}")


def _expect_at_least(what: str, payload: bytes, minimum: int) -> None:
    if len(payload) < minimum:
        raise ProtocolError("BAD_LENGTH", f"{what} payload is {len(payload)} bytes, expected at least {minimum}")


def decode_request(msg_type: int, payload: bytes, info: ModelInfo) -> tuple:
    """("hello",) | ("reset", seed, init_action) | ("act", executed, obs_count, flat_obs) | ("close",)"""
    w = info.width
    if msg_type == HELLO:
        _expect_len("HELLO", payload, 4, "4")
        if payload != MAGIC:
            raise ProtocolError("BAD_VALUE", f"HELLO magic is {payload.hex(' ')}, expected \"FRMD\" (46 52 4d 44)")
        return ("hello",)
    if msg_type == RESET:
        _expect_at_least("RESET", payload, 12)
        seed, count = struct.unpack_from("<QI", payload)
        _expect_len("RESET", payload, 12 + count * w, f"12 + {count} x {w} = {12 + count * w}")
        if count not in (0, info.action_dim):
            raise ProtocolError("BAD_VALUE", f"RESET init_count is {count}, expected 0 or action_dim {info.action_dim}")
        return ("reset", seed, _unpack_values(payload, 12, count, info.float_type))
    if msg_type == ACT:
        _expect_at_least("ACT", payload, 8)
        executed, count = struct.unpack_from("<II", payload)
        expected = 8 + count * info.obs_dim * w
        _expect_len("ACT", payload, expected, f"8 + {count} x {info.obs_dim} x {w} = {expected}")
        if count != info.obs_history:
            raise ProtocolError("BAD_VALUE", f"ACT obs_count is {count}, the policy takes {info.obs_history} observations")
        return ("act", executed, count, _unpack_values(payload, 8, count * info.obs_dim, info.float_type))
    if msg_type == CLOSE:
        _expect_len("CLOSE", payload, 0, "0")
        return ("close",)
    raise ProtocolError("UNKNOWN_TYPE", f"{TYPE_NAMES.get(msg_type, hex(msg_type))} is not a request")


def decode_reply(msg_type: int, payload: bytes, float_type: int | None) -> tuple:
    """("hello_ok", ModelInfo) | ("reset_ok", seed) | ("chunk", policy_ns, horizon, action_dim,
    exec_steps, flat_actions) | ("close_ok",) | ("error", code, request_type, fatal, text)"""
    try:
        if msg_type == HELLO_OK:
            _expect_at_least("HELLO_OK", payload, 26)
            o, k, m, n, e, ft, reserved, max_payload, dt, name_len = HELLO_OK_FIXED.unpack_from(payload)
            _expect_len("HELLO_OK", payload, 26 + name_len, f"26 + {name_len}")
            if reserved:
                raise ProtocolError("BAD_VALUE", f"HELLO_OK reserved byte is {reserved}, must be 0")
            info = ModelInfo(o, k, m, n, e, ft, dt, payload[26:].decode(), max_payload)
            info.validate()
            return ("hello_ok", info)
        if msg_type == RESET_OK:
            _expect_len("RESET_OK", payload, 8, "8")
            return ("reset_ok", struct.unpack("<Q", payload)[0])
        if msg_type == CHUNK:
            if float_type is None:
                raise ProtocolError("OUT_OF_ORDER", "CHUNK before HELLO_OK: value type unknown")
            _expect_at_least("CHUNK", payload, 16)
            policy_ns, n, k, e, reserved = CHUNK_FIXED.unpack_from(payload)
            w = 4 if float_type == F32 else 8
            _expect_len("CHUNK", payload, 16 + n * k * w, f"16 + {n} x {k} x {w} = {16 + n * k * w}")
            if reserved:
                raise ProtocolError("BAD_VALUE", f"CHUNK reserved field is {reserved}, must be 0")
            return ("chunk", policy_ns, n, k, e, _unpack_values(payload, 16, n * k, float_type))
        if msg_type == CLOSE_OK:
            _expect_len("CLOSE_OK", payload, 0, "0")
            return ("close_ok",)
        if msg_type == ERROR:
            _expect_at_least("ERROR", payload, 6)
            code, request_type, fatal, text_len = ERROR_FIXED.unpack_from(payload)
            _expect_len("ERROR", payload, 6 + text_len, f"6 + {text_len}")
            if fatal > 1:
                raise ProtocolError("BAD_VALUE", f"ERROR fatal flag is {fatal}, expected 0 or 1")
            return ("error", code, request_type, bool(fatal), payload[6:].decode())
    except UnicodeDecodeError:
        raise ProtocolError("BAD_VALUE", f"{TYPE_NAMES[msg_type]} text is not valid UTF-8") from None
    raise ProtocolError("UNKNOWN_TYPE", f"{TYPE_NAMES.get(msg_type, hex(msg_type))} is not a reply")


def first_non_finite(what: str, values: Sequence[float], row_len: int = 0) -> None:
    for i, v in enumerate(values):
        if not math.isfinite(v):
            kind = "NaN" if math.isnan(v) else ("inf" if v > 0 else "-inf")
            place = f"{what} {i // row_len} element {i % row_len}" if row_len else f"{what} element {i}"
            raise ProtocolError("NON_FINITE", f"{place} is {kind}")


# ---- byte streams ---------------------------------------------------------------------------

class Truncated(Exception):
    """End of input inside a frame."""


def read_exact(read: Callable[[int], bytes], n: int) -> bytes:
    """n bytes, b"" at end of input before the first byte, Truncated after a partial read."""
    parts, got = [], 0
    while got < n:
        part = read(n - got)
        if not part:
            if got == 0:
                return b""
            raise Truncated(f"end of input after {got} of {n} bytes")
        parts.append(part)
        got += len(part)
    return b"".join(parts)


# ---- client side ----------------------------------------------------------------------------

class Client:
    """A protocol client over a child process (`command`) or a Unix socket (`socket_path`).

    `hello()` must come first; then `reset(seed)`, `act(executed, observations)` per chunk and
    `close()`. ERROR replies raise ServerError; the client stays usable after non-fatal ones.
    """

    def __init__(self, command: str | Sequence[str] | None = None, socket_path: str | None = None,
                 env: dict | None = None, stderr=None):
        self.proc, self.sock = None, None
        if command is not None:
            argv = shlex.split(command) if isinstance(command, str) else list(command)
            self.proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=stderr,
                                         bufsize=0, env=env)
            self._out, self._in = self.proc.stdin.fileno(), self.proc.stdout.fileno()
        elif socket_path is not None:
            self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            self.sock.connect(socket_path)
            self._out = self._in = self.sock.fileno()
        else:
            raise ValueError("give a server command or a socket path")
        self.info: ModelInfo | None = None
        self.last_policy_ns = 0

    def _read(self, n: int) -> bytes:
        return os.read(self._in, n)

    def send_raw(self, data: bytes) -> None:
        """Writes bytes as they are (tests send malformed frames with it)."""
        view = memoryview(data)
        while view:
            view = view[os.write(self._out, view):]

    def read_reply(self) -> tuple:
        head = read_exact(self._read, HEADER_LEN)
        if not head:
            raise ConnectionError("server closed the stream")
        msg_type, payload_len = check_header(head, requests=False)
        payload = read_exact(self._read, payload_len) if payload_len else b""
        if len(payload) != payload_len:
            raise ConnectionError("server closed the stream inside a frame")
        reply = decode_reply(msg_type, payload, self.info.float_type if self.info else None)
        if reply[0] == "error":
            raise ServerError(*reply[1:])
        return reply

    def request(self, data: bytes, expect: str) -> tuple:
        self.send_raw(data)
        reply = self.read_reply()
        if reply[0] != expect:
            raise ProtocolError("BAD_VALUE", f"expected {expect}, got {reply[0]}")
        return reply

    def hello(self) -> ModelInfo:
        self.info = self.request(encode_hello(), "hello_ok")[1]
        return self.info

    def reset(self, seed: int, init_action: Sequence[float] = ()) -> None:
        reply = self.request(encode_reset(seed, init_action, self.info.float_type), "reset_ok")
        if reply[1] != seed:
            raise ProtocolError("BAD_VALUE", f"RESET_OK answers seed {reply[1]}, sent {seed}")

    def act(self, executed: int, observations: Sequence[Sequence[float]]) -> list[list[float]]:
        """The chunk as N actions of K values; the server's policy time is in last_policy_ns."""
        info = self.info
        _, policy_ns, n, k, _, flat = self.request(encode_act(executed, observations, info.float_type), "chunk")
        if (n, k) != (info.horizon, info.action_dim):
            raise ProtocolError("BAD_VALUE", f"CHUNK is {n} x {k}, HELLO_OK announced {info.horizon} x {info.action_dim}")
        self.last_policy_ns = policy_ns
        return [flat[t * k:(t + 1) * k] for t in range(n)]

    def close(self, timeout: float = 10.0) -> int | None:
        """CLOSE, then wait for the process (its exit status) or close the socket."""
        try:
            self.request(encode_close(), "close_ok")
        except (OSError, ConnectionError, ServerError, ProtocolError):
            pass
        if self.sock is not None:
            self.sock.close()
            return None
        self.proc.stdin.close()
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return self.proc.wait()
