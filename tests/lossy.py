"""Test support: a lossy TCP proxy between the link client and an emulator.

The proxy decodes the client's request frames with the real framing, forwards each one to the emulator and its
reply back — unless its rule says to lose the request or the reply. Losing a reply after the module executed
the request is the fault a checksum cannot help with: the module did it, the master never heard so. The rule
sees every request frame with its running number (1-based) and answers a set of `Loss`es: `REFUSAL` replaces
the module's reply with a well-formed error code 32 (what a damaged reply can look like on a line without a
checksum), `FLIP` flips one bit of the reply, `FLOOD` answers with bytes that never stop (a line that never
goes quiet).
"""

from __future__ import annotations

import contextlib
import enum
import random
import socket
import threading
import time
from collections.abc import Callable

from prc3cfg.core.framing import NEED_DATA, Direction, Frame, get_framing
from prc3cfg.core.line import LineSettings

POLL = 0.01


class Loss(enum.Enum):
    REQUEST = "request"  # the emulator never sees the request
    REPLY = "reply"  # the emulator executes it, its reply is swallowed
    REFUSAL = "refusal"  # the emulator executes it, the client hears code 32 instead
    FLOOD = "flood"  # the client hears bytes that never stop instead of a reply
    # what a line without error detection (open-driver, no parity) lets a flipped bit do to a request:
    AS_INIT = "as-init"  # the module receives 10h [10 00] (a 50h's bit 6 flipped) and executes it
    TO_BROADCAST = "to-broadcast"  # it arrives at address 0: every module executes it, none answers
    # what a gateway or a radio link that holds frames does: frames sent after it overtake it
    FLIP = "flip"  # the emulator executes it, one bit of its reply is flipped (`LossyProxy.seed` draws which)
    LATE = "late"  # held, then delivered late (`LossyProxy.hold`, `until`)
    DUPLICATE = "duplicate"  # delivered at once, and a copy of it delivered late as LATE is


FAKE_CODE = 32


Rule = Callable[[Frame, int], set[Loss]]
#: Whether the frames held so far are delivered before this request (its running number).
Until = Callable[[Frame, int], bool]


def lose_replies_to(
    message_id: int | None, *, address: int | None = None, times: int | None = None, loss: Loss = Loss.REPLY
) -> Rule:
    """A rule: `loss` for requests with this message ID (any: None) to `address` (any: None), the first
    `times`."""
    seen = 0

    def rule(frame: Frame, _: int) -> set[Loss]:
        nonlocal seen
        if message_id is not None and frame.message[:1] != bytes([message_id]):
            return set()
        if address is not None and frame.address != address:
            return set()
        seen += 1
        return {loss} if times is None or seen <= times else set()

    return rule


class LossyProxy:
    """Listens on loopback and forwards each client's frames through the rule over ONE connection to
    `upstream`, held for the proxy's life — as a gateway holds its serial line whoever its client is
    (an emulator takes one client per line: a connection per client would race the last one's close)."""

    def __init__(self, upstream: tuple[str, int], rule: Rule, *, framing: str = "crc16",
                 line: LineSettings = LineSettings(), zvz: float = 0.020, hold: float = 0.45,
                 until: Until = lambda frame, n: False, seed: int = 0) -> None:
        self.upstream = upstream
        self.rule = rule
        self.framing = get_framing(framing)
        self.line = line
        self.zvz = zvz
        self.requests = 0
        self.lost: list[tuple[Loss, Frame]] = []
        self._closing = threading.Event()
        self._sockets: list[socket.socket] = []
        self._threads: list[threading.Thread] = []
        self._line: socket.socket | None = None  # the one connection upstream
        self._client: socket.socket | None = None  # who the replies go to
        self._swallow, self._flooding = threading.Event(), threading.Event()
        self.hold, self.until = hold, until
        self._held: list[tuple[float, bytes]] = []  # (when it was held, its frame): `LATE`, `DUPLICATE`
        self._held_lock = threading.Lock()
        self.delivered_late = 0  # held frames delivered so far
        self._flip, self._draw = threading.Event(), random.Random(seed)

    def listen(self) -> str:
        server = socket.create_server(("127.0.0.1", 0))
        server.settimeout(POLL)
        self._sockets.append(server)
        self._start(self._accept, server)
        host, port = server.getsockname()[:2]
        return f"socket://{host}:{port}"

    def _start(self, target: Callable[..., None], *args: object) -> None:
        thread = threading.Thread(target=target, args=args, daemon=True)
        self._threads.append(thread)
        thread.start()

    def _accept(self, server: socket.socket) -> None:
        while not self._closing.is_set():
            try:
                client, _ = server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            if self._line is None:
                self._line = socket.create_connection(self.upstream)
                self._sockets.append(self._line)
                self._start(self._replies, self._line)
            self._sockets.append(client)
            self._client = client
            self._swallow.clear()
            self._flooding.clear()
            self._start(self._requests, client, self._line, self._swallow, self._flooding)
            self._start(self._flood, client, self._flooding)

    def _requests(self, client: socket.socket, upstream: socket.socket, swallow: threading.Event,
                  flood: threading.Event) -> None:
        decoder = self.framing.decoder(Direction.REQUEST, self.line, zvz=self.zvz)
        client.settimeout(self.zvz if self.framing.name == "open-driver" else POLL)
        while not self._closing.is_set():
            try:
                data = client.recv(4096)
                if not data:
                    return
                decoder.receive_data(data, time.monotonic())
            except TimeoutError:
                decoder.line_idle()
                self._deliver(upstream, time.monotonic() - self.hold)
            except OSError:
                return
            while (event := decoder.next_event()) is not NEED_DATA:
                if not isinstance(event, Frame):
                    continue
                self.requests += 1
                self._deliver(upstream, time.monotonic() if self.until(event, self.requests)
                              else time.monotonic() - self.hold)
                losses = self.rule(event, self.requests)
                self.lost += [(loss, event) for loss in sorted(losses, key=lambda x: x.value)]
                flood.set() if Loss.FLOOD in losses else flood.clear()
                if losses & {Loss.LATE, Loss.DUPLICATE}:
                    with self._held_lock:
                        self._held.append((time.monotonic(),
                                           self.framing.encode(Direction.REQUEST, event.address,
                                                               event.message)))
                if losses & {Loss.REQUEST, Loss.LATE}:
                    continue
                swallow.set() if losses & {Loss.REPLY, Loss.REFUSAL, Loss.FLOOD} else swallow.clear()
                self._flip.set() if Loss.FLIP in losses else self._flip.clear()
                address = 0 if Loss.TO_BROADCAST in losses else event.address
                message = bytes([0x10, 0]) if Loss.AS_INIT in losses else event.message
                upstream.sendall(self.framing.encode(Direction.REQUEST, address, message))
                if Loss.REFUSAL in losses:
                    client.sendall(self.framing.encode(Direction.REPLY, event.address, bytes([FAKE_CODE, 0])))

    def _deliver(self, upstream: socket.socket, held_since: float) -> None:
        """The held frames held since `held_since` or before, to the emulator, in the order they came."""
        with self._held_lock:
            due = [frame for when, frame in self._held if when <= held_since]
            self._held = [(when, frame) for when, frame in self._held if when > held_since]
        for frame in due:
            upstream.sendall(frame)
            self.delivered_late += 1

    def flush(self) -> None:
        """Every frame still held, to the emulator now: the latest a held frame can come (after the client is
        done)."""
        if self._line is not None:
            self._deliver(self._line, time.monotonic())

    @property
    def holding(self) -> int:
        """Frames held, not delivered yet."""
        with self._held_lock:
            return len(self._held)

    def _replies(self, upstream: socket.socket) -> None:
        while not self._closing.is_set():
            try:
                data = upstream.recv(4096)
            except OSError:
                return
            if not data:
                return
            if self._flip.is_set():  # one bit of the reply's first piece
                self._flip.clear()
                bit = self._draw.randrange(8 * len(data))
                data = data[: bit // 8] + bytes([data[bit // 8] ^ (1 << bit % 8)]) + data[bit // 8 + 1 :]
            if not self._swallow.is_set() and self._client is not None:
                with contextlib.suppress(OSError):  # a client gone: its reply is lost, as on a line
                    self._client.sendall(data)

    def _flood(self, client: socket.socket, flood: threading.Event) -> None:
        while not self._closing.is_set():
            if not flood.wait(POLL):
                continue
            try:
                client.sendall(b"\x55" * 8)
            except OSError:
                return
            time.sleep(0.001)  # a steady stream: never a gap of a character delay time

    def close(self) -> None:
        self._closing.set()
        for sock in self._sockets:
            with contextlib.suppress(OSError):
                sock.close()
        for thread in self._threads:
            thread.join(timeout=2)

    def __enter__(self) -> LossyProxy:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
