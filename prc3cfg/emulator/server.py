"""The bus emulator as a server: a `Bus` behind a framing, over TCP and pseudo-terminals.

Owns the outside of the emulator: byte streams (TCP connections, a pty), request frames in
and reply frames out through `prc3cfg.framing`, one exchange at a time on the line (half
duplex), line-speed timing, fault injection, saving the state file after every accepted
write, and the Python API tests use to change a module while it runs (mode, fault, active
program, teach-in). What a message does is `prc3cfg.device`; who gets it, `bus.Bus`.
"""

from __future__ import annotations

import logging
import os
import random
import select
import socket
import threading
import time
import tty
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from prc3cfg.device import ModuleState
from prc3cfg.emulator.bus import BROADCAST, Bus
from prc3cfg.emulator.state import save_state
from prc3cfg.framing import NEED_DATA, Direction, Discarded, Frame, get_framing
from prc3cfg.line import LineSettings

log = logging.getLogger(__name__)

POLL = 0.1  # s: how often an idle stream looks whether the emulator is closing


@dataclass(frozen=True, slots=True)
class FaultInjection:
    """Damage on the line, for tests: each exchange is lost with `drop_rate` (the request or
    the reply, at even odds) and damaged with `corrupt_rate` (one bit of the request or the
    reply frame flipped). Seeded, so a test run is repeatable.

    A flipped bit is what the receiving UART makes of it: on a line with parity it is a
    parity error and the character is dropped; without parity it is a valid, different
    byte. A damaged request reaches the modules only if the framing still finds a frame
    in what is left (never on crc16 or stx: their checksums catch one flipped bit)."""

    drop_rate: float = 0.0
    corrupt_rate: float = 0.0
    seed: int | None = None

    def __post_init__(self) -> None:
        for name in ("drop_rate", "corrupt_rate"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name.replace('_', '-')} must lie in 0..1")


class Emulator:
    """A running emulated bus. Use as a context manager, or call `close()`."""

    def __init__(
        self,
        modules: dict[int, ModuleState],
        *,
        framing: str = "crc16",
        line: LineSettings = LineSettings(),
        zvz: float = 0.020,
        turnaround: float = 0.010,
        line_speed: bool = False,
        faults: FaultInjection = FaultInjection(),
        state_path: Path | None = None,
    ) -> None:
        self.framing = get_framing(framing)
        self.line = line
        self.zvz = zvz
        self.turnaround = turnaround
        self.line_speed = line_speed
        self.faults = faults
        self.state_path = state_path
        self._bus = Bus(modules)
        self._random = random.Random(faults.seed)
        self._lock = threading.Lock()  # the line: one exchange at a time
        self._closing = threading.Event()
        self._threads: list[threading.Thread] = []
        self._closers: list[Callable[[], None]] = []
        if state_path is not None and not state_path.exists():
            save_state(state_path, self._bus.modules)

    # -- the Python API ----------------------------------------------------------------

    def modules(self) -> dict[int, ModuleState]:
        with self._lock:
            return dict(self._bus.modules)

    def module(self, address: int) -> ModuleState:
        with self._lock:
            return self._bus.modules[address]

    def update(self, address: int, **changes) -> ModuleState:
        """Change a module as the floor would: mode, fault, active_program, referenced."""
        with self._lock:
            state = replace(self._bus.modules[address], **changes)
            self._store(address, state)
            return state

    def teach_in(self, address: int, program: int, position: int) -> ModuleState:
        """Teach In on the module's inputs (manual §2.6): a program's position changes."""
        with self._lock:
            state = self._bus.modules[address]
            taught = replace(state.image.program(program), P=position)
            state = replace(state, image=state.image.with_programs({program: taught}))
            self._store(address, state)
            return state

    def _store(self, address: int, state: ModuleState) -> None:
        self._bus.modules[address] = state
        if self.state_path is not None:
            save_state(self.state_path, self._bus.modules)

    # -- exchanges ---------------------------------------------------------------------

    def _chance(self, rate: float) -> bool:
        return rate > 0 and self._random.random() < rate

    def _damage(self, frame: bytes) -> bytes:
        """`frame` with one bit flipped on the line, as the receiving UART hands it on."""
        i = self._random.randrange(len(frame))
        if self.line.parity != "none":  # a parity error: the UART drops the character
            return frame[:i] + frame[i + 1 :]
        return frame[:i] + bytes([frame[i] ^ (1 << self._random.randrange(self.line.data_bits))]) + frame[i + 1 :]

    def _received(self, data: bytes) -> Frame | None:
        """The request frame a module's receiver finds in damaged bytes, if any."""
        decoder = self.framing.decoder(Direction.REQUEST, self.line, zvz=self.zvz)
        decoder.receive_data(data, 0.0)
        decoder.line_idle()
        while (event := decoder.next_event()) is not NEED_DATA:
            if isinstance(event, Frame):
                return event
        return None

    def exchange(self, frame: Frame, received_at: float) -> bytes | None:
        """Serve one request frame; the reply frame to send, or None for silence."""
        with self._lock:
            drop = self._chance(self.faults.drop_rate)
            corrupt = self._chance(self.faults.corrupt_rate)
            damage_request = self._random.random() < 0.5 if (drop or corrupt) else False
            if damage_request and drop:
                log.info("fault injection: request to %d lost", frame.address)
                return None
            if damage_request and corrupt:
                sent = self.framing.encode(Direction.REQUEST, frame.address, frame.message)
                damaged = self._received(self._damage(sent))
                if damaged is None:
                    log.info("fault injection: request to %d damaged and discarded", frame.address)
                    return None
                log.info("fault injection: request damaged, delivered to %d as %s", damaged.address, damaged.message.hex())
                frame = damaged
            address, message = frame.address, frame.message
            delivery = self._bus.deliver(address, message)
            if delivery.changed and self.state_path is not None:
                save_state(self.state_path, self._bus.modules)
            if delivery.reply is None or address == BROADCAST:
                return None
            reply = self.framing.encode(Direction.REPLY, address, delivery.reply)
            if self.line_speed:
                request_bytes = len(self.framing.encode(Direction.REQUEST, frame.address, frame.message))
                line_time = (request_bytes + len(reply)) * self.line.char_time + self.turnaround
                time.sleep(max(0.0, received_at + line_time - time.monotonic()))
            if not damage_request and drop:
                log.info("fault injection: reply from %d lost", address)
                return None
            if not damage_request and corrupt:
                log.info("fault injection: reply from %d damaged", address)
                reply = self._damage(reply)
            return reply

    def _serve_stream(self, recv: Callable[[float], bytes | None], send: Callable[[bytes], None]) -> None:
        """Decode request frames from one byte stream and answer them until it ends."""
        decoder = self.framing.decoder(Direction.REQUEST, self.line, zvz=self.zvz)
        gap = self.zvz if self.framing.name == "open-driver" else POLL
        while not self._closing.is_set():
            data = recv(gap)
            now = time.monotonic()
            if data is None:
                return
            if data:
                decoder.receive_data(data, now)
            elif self.framing.name == "open-driver":
                decoder.line_idle()
            while (event := decoder.next_event(now)) is not NEED_DATA:
                if isinstance(event, Discarded):
                    log.info("discarded %s: %s", event.data.hex(), event.reason)
                    continue
                reply = self.exchange(event, now)
                if reply is not None:
                    send(reply)

    def _start(self, target: Callable[[], None], name: str) -> None:
        thread = threading.Thread(target=target, name=name, daemon=True)
        self._threads.append(thread)
        thread.start()

    # -- TCP ---------------------------------------------------------------------------

    def listen(self, host: str = "127.0.0.1", port: int = 0) -> tuple[str, int]:
        """Accept TCP connections (pyserial `socket://HOST:PORT`); returns the bound address."""
        server = socket.create_server((host, port), reuse_port=False)
        server.settimeout(POLL)
        self._closers.append(server.close)
        self._start(lambda: self._accept(server), "emulator-accept")
        bound = server.getsockname()
        return bound[0], bound[1]

    def _accept(self, server: socket.socket) -> None:
        while not self._closing.is_set():
            try:
                conn, _ = server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._closers.append(conn.close)
            self._start(lambda c=conn: self._serve_socket(c), "emulator-conn")

    def _serve_socket(self, conn: socket.socket) -> None:
        def recv(timeout: float) -> bytes | None:
            conn.settimeout(timeout)
            try:
                data = conn.recv(4096)
            except TimeoutError:
                return b""
            except OSError:
                return None
            return data or None

        try:
            self._serve_stream(recv, conn.sendall)
        except OSError:
            pass
        finally:
            conn.close()

    # -- pty ---------------------------------------------------------------------------

    def open_pty(self) -> str:
        """Serve a pseudo-terminal; returns the path any serial program can open."""
        master, slave = os.openpty()
        tty.setraw(slave)
        self._closers.append(lambda: (os.close(master), os.close(slave)))

        def recv(timeout: float) -> bytes | None:
            try:
                ready, _, _ = select.select([master], [], [], timeout)
                return os.read(master, 4096) if ready else b""
            except OSError:
                return None

        def send(data: bytes) -> None:
            os.write(master, data)

        self._start(lambda: self._serve_stream(recv, send), "emulator-pty")
        return os.ttyname(slave)

    # -- lifetime ----------------------------------------------------------------------

    def close(self) -> None:
        self._closing.set()
        for close in reversed(self._closers):
            try:
                close()
            except OSError:
                pass
        for thread in self._threads:
            thread.join(timeout=2)

    def __enter__(self) -> Emulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
