"""The server side of the `frmd serve` protocol (docs/serve-protocol.md) for the mock server and
the tests: one session's rules, as frmd-host's `serve::Session` applies them, and the stream loop.
The frame codec it uses is `protocol`."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

from .protocol import (ACT, CLOSE, HEADER, HEADER_LEN, HELLO, TYPE_NAMES, ModelInfo, ProtocolError,
                       Truncated, check_header, decode_request, encode_chunk, encode_close_ok,
                       encode_error, encode_hello_ok, encode_reset_ok, first_non_finite, read_exact)

@dataclass
class Session:
    """Server-side session rules, as in frmd-host's `serve::Session`."""
    info: ModelInfo
    policy_reset: Callable[[int], None]
    # act(obs [M][O] oldest first, prev_action [K], prev_rate [K]) -> flat [N*K] actions
    policy_act: Callable[[list, list, list], Sequence[float]]
    default_init: list = field(default_factory=list)
    hello: bool = False
    episode: dict | None = None

    def handle(self, msg_type: int, payload: bytes) -> tuple[bytes, bool]:
        """(reply frame, close?) for one request whose header passed its checks."""
        try:
            return self._handle(msg_type, payload)
        except ProtocolError as e:
            return encode_error(e.code, e.text, msg_type), False

    def _handle(self, msg_type: int, payload: bytes) -> tuple[bytes, bool]:
        info, k = self.info, self.info.action_dim
        if msg_type not in (HELLO, CLOSE) and not self.hello:
            raise ProtocolError("OUT_OF_ORDER", f"{TYPE_NAMES[msg_type]} before HELLO")
        if msg_type == ACT and self.episode is None:
            raise ProtocolError("OUT_OF_ORDER", "ACT before RESET: no episode has been started")
        request = decode_request(msg_type, payload, info)
        if request[0] == "hello":
            self.hello = True
            return encode_hello_ok(info), False
        if request[0] == "close":
            return encode_close_ok(), True
        if request[0] == "reset":
            _, seed, init = request
            first_non_finite("RESET init_action", init)
            init = list(init) if init else list(self.default_init or [0.0] * k)
            self.policy_reset(seed)
            self.episode = {"chunk": None, "prev": init, "prev2": init}
            return encode_reset_ok(seed), False
        _, executed, count, flat = request
        ep = self.episode
        prev, prev2 = ep["prev"], ep["prev2"]
        if executed > 0:
            if ep["chunk"] is None:
                raise ProtocolError("BAD_VALUE", f"ACT executed is {executed} but no chunk has been sent in this episode")
            actions = [ep["chunk"][t * k:(t + 1) * k] for t in range(len(ep["chunk"]) // k)]
            if executed > len(actions):
                raise ProtocolError("BAD_VALUE",
                                    f"ACT executed is {executed} but the previous chunk has {len(actions)} actions")
            for a in actions[:executed]:
                prev, prev2 = a, prev
        first_non_finite("ACT observation", flat, info.obs_dim)
        rate = [(a - b) / info.dt if info.dt > 0 else 0.0 for a, b in zip(prev, prev2)]
        obs = [flat[i * info.obs_dim:(i + 1) * info.obs_dim] for i in range(count)]
        started = time.perf_counter_ns()
        try:
            out = [float(v) for v in self.policy_act(obs, prev, rate)]
        except Exception as e:  # the policy's own failure is reported, the session goes on
            raise ProtocolError("POLICY_FAILED", f"policy: {e}") from None
        policy_ns = time.perf_counter_ns() - started
        if len(out) != info.horizon * k:
            raise ProtocolError("POLICY_FAILED",
                                f"policy returned {len(out)} values, expected horizon x action_dim = {info.horizon * k}")
        try:
            first_non_finite("policy action", out, k)
        except ProtocolError as e:
            raise ProtocolError("POLICY_FAILED", e.text) from None
        self.episode = {"chunk": out, "prev": prev, "prev2": prev2}
        return encode_chunk(policy_ns, info, out), False


def serve_stream(read: Callable[[int], bytes], write: Callable[[bytes], None], session: Session) -> str:
    """Serves one session until CLOSE ("closed"), end of input ("eof") or a cut frame ("truncated")."""
    skip, skip_type, msg_type = 0, 0, 0
    while True:
        try:
            while skip:
                part = read(min(skip, 1 << 16))
                if not part:
                    msg_type = skip_type
                    raise Truncated(f"end of input inside {skip} bytes of a rejected frame's payload")
                skip -= len(part)
            msg_type = 0
            head = read_exact(read, HEADER_LEN)
            if not head:
                return "eof"
            try:
                msg_type, payload_len = check_header(head, requests=True)
            except ProtocolError as e:
                skip, skip_type = HEADER.unpack(head)[0], head[5]
                write(encode_error(e.code, e.text, head[5]))
                continue
            payload = read_exact(read, payload_len) if payload_len else b""
            if len(payload) != payload_len:
                raise Truncated(f"end of input after 0 of {payload_len} payload bytes of a {TYPE_NAMES[msg_type]} frame")
        except Truncated as e:
            try:
                write(encode_error("TRUNCATED", str(e), msg_type, fatal=True))
            except OSError:
                pass
            return "truncated"
        reply, close = session.handle(msg_type, payload)
        write(reply)
        if close:
            return "closed"
