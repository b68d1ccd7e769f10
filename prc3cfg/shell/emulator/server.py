"""The bus emulator as a server: an `EmulatedBus` behind a framing, over TCP and pseudo-terminals.

Owns the outside of the emulator: byte streams (TCP connections, a pty), request frames in
and reply frames out through `prc3cfg.core.framing`, one exchange at a time on the line (half
duplex), line-speed timing, fault injection (its seeded draws), making every accepted write
durable before it is answered, and the Python API tests use to change a module while it runs
(mode, fault, active program, teach-in). What a message does is `prc3cfg.core.device`; who gets
it, `bus.EmulatedBus`; what the drawn faults do to an exchange, `prc3cfg.core.exchange.FAULTS`;
how the state is kept on disk (a journal beside the state file, compacted into it), `state.Store`.

Frames from a TCP connection are decoded with `uart=False` (`prc3cfg.core.framing.base`): a
request split and delayed by the network or a paused client is taken whole by its length.
Frames from the pty are decoded as a UART's, with the framing's time-outs.

A long-running service that survives its clients:

- **At most `max_connections` TCP connections** (default 1: one client per line, as a
  gateway such as ser2net keeps by default — a client cannot always tell that two
  addresses are one gateway, so the gateway refuses the second), each served by its own
  thread. One more is accepted and closed at once, with a logged warning, never given a
  thread. A connection's slot is free again before its socket is closed, so a client that
  sees its connection end can connect again at once; and a connection whose client has
  already hung up (its end of stream waiting to be read) holds no slot, so the client that
  follows it at once is not refused. The pty is one more stream.
- **An idle time-out** (default 300 s): a connection that sends nothing for that long —
  connected and silent, or stopped in the middle of a frame — is closed. A client that
  does not take its replies is closed when a reply cannot be sent within the poll time.
- **Bounded memory**: a connection holds one framing decoder, which discards endless
  garbage and frames that never end in bounded pieces (`prc3cfg.core.framing`), and reads at
  most `RECV_SIZE` bytes at a time; the kernel's socket buffer holds back a faster
  sender. Threads of closed connections end and are forgotten.
- **Running out of file descriptors** (or kernel buffers) in `accept()` is logged once,
  retried every `ACCEPT_BACKOFF` seconds, and its end logged: the server keeps listening.
- **A write is acknowledged only once it is saved** — appended to the journal and flushed
  to disk, or written into the state file (`state.Store`), so a killed emulator loses no
  acknowledged write. When neither can take it (disk full, permissions, its folder
  replaced by a file, the file replaced by a folder), the error is logged naming the file
  and the reason, every module is put back as it was before the write — in memory as on
  disk — and the write is not answered, as if it never arrived: the master sees no reply,
  repeats it, and reports it. Reads go on being answered; the next write is saved once the
  file can be written again. On exit the state file takes everything.

Long because one file (over 500 lines): every part of the server (exchanges, streams, TCP, the pty, its
lifetime) works on one `Emulator`'s lock, closing event and sets of threads and connections.
"""

from __future__ import annotations

import contextlib
import logging
import os
import random
import select
import socket
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import cast

import serial
from serial import rfc2217
from serial.rfc2217 import PortManager

from prc3cfg.core.device import ModuleState
from prc3cfg.core.exchange import FAULTS, Fault
from prc3cfg.core.framing import NEED_DATA, Direction, Discarded, Frame, get_framing
from prc3cfg.core.line import LineSettings
from prc3cfg.core.uart import received as uart_received
from prc3cfg.errors import UserError
from prc3cfg.shell import platform
from prc3cfg.shell.cancel import main_thread_only
from prc3cfg.shell.emulator.bus import BROADCAST, EmulatedBus
from prc3cfg.shell.emulator.state import COMPACT_EVERY, Store, cannot_save

log = logging.getLogger(__name__)

POLL = 0.1  # s: how often an idle stream looks whether the emulator is closing
RECV_SIZE = 4096  # bytes read from a stream at a time
#: Bytes of replies a TCP client may leave unread before a reply waits (and, after POLL, the client is cut
#: off): a line holds no backlog, a client waits for each reply; the kernel's own would grow to megabytes,
#: which a client that takes no replies fills only after seconds of the emulator's work.
REPLY_BUFFER = 64 * 1024
ACCEPT_BACKOFF = 0.1  # s: the pause before accepting again after accept() failed (EMFILE, ENFILE, …)
MAX_CONNECTIONS = 1
IDLE_TIMEOUT = 300.0  # s


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
    """A running emulated bus. Use as a context manager, or call `close()`.

    `unserved` are modules of the state file this emulator does not serve: every save
    writes them back unchanged, so serving a few modules of a state file loses no others.
    `compact_every`: journal lines between compactions of the state file (`state.Store`).

    With `line_speed`, a module answers after its turnaround: `turnarounds[address]`, else
    `turnaround`, each exchange shifted by up to ± `jitter` (uniform, never below 0; seeded by
    the fault injection's seed, so a test run is repeatable) — a line that is not ideal, for
    `prc3cfg doctor` and the bus-time estimates to be measured against.
    """

    def __init__(
        self,
        modules: dict[int, ModuleState],
        *,
        framing: str = "crc16",
        line: LineSettings = LineSettings(),
        zvz: float = 0.020,
        turnaround: float = 0.010,
        turnarounds: Mapping[int, float] | None = None,
        jitter: float = 0.0,
        line_speed: bool = False,
        faults: FaultInjection = FaultInjection(),
        state_path: Path | None = None,
        unserved: Mapping[int, ModuleState] | None = None,
        max_connections: int = MAX_CONNECTIONS,
        idle_timeout: float = IDLE_TIMEOUT,
        compact_every: int = COMPACT_EVERY,
    ) -> None:
        if max_connections < 1:
            raise ValueError(f"max-connections must be at least 1, not {max_connections}")
        if not idle_timeout > 0:
            raise ValueError(f"idle-timeout must be more than 0 s, not {idle_timeout}")
        if jitter < 0 or turnaround < 0 or any(t < 0 for t in (turnarounds or {}).values()):
            raise ValueError("a turnaround and the jitter are at least 0 s")
        self.framing = get_framing(framing)
        self.line = line
        self.zvz = zvz
        self.turnaround = turnaround
        self.turnarounds = dict(turnarounds or {})
        self.jitter = jitter
        self.line_speed = line_speed
        self.faults = faults
        self.state_path = state_path
        self.max_connections = max_connections
        self.idle_timeout = idle_timeout
        self._bus = EmulatedBus(modules)
        self._unserved = dict(unserved or {})
        self._random = random.Random(faults.seed)
        self._jitter = random.Random(faults.seed)  # its own, so jitter leaves the faults' sequence as it was
        self._lock = threading.Lock()  # the line: one exchange at a time
        self._closing = threading.Event()
        self._guard = threading.Lock()  # the two sets below
        self._threads: set[threading.Thread] = set()  # running; each removes itself when it ends
        self._connections: set[socket.socket] = set()  # open TCP connections
        self._closers: list[Callable[[], None]] = []  # listening sockets and ptys
        self._store = None if state_path is None else Store(state_path, compact_every=compact_every)
        if self._store is not None:
            try:
                self._store.start(self._all())
            except OSError as error:
                raise UserError(f"{cannot_save(self._store.path, error)} — check the path, its folder "
                                "and the disk") from None

    # -- the Python API ----------------------------------------------------------------

    def modules(self) -> dict[int, ModuleState]:
        with self._lock:
            return dict(self._bus.modules)

    def module(self, address: int) -> ModuleState:
        with self._lock:
            return self._bus.modules[address]

    def update(self, address: int, **changes) -> ModuleState:
        """Change a module as the floor would: mode, fault, active_program, referenced.
        Raises OSError, and changes nothing, when the state file cannot be saved."""
        with self._lock:
            state = replace(self._bus.modules[address], **changes)
            self._change(address, state)
            return state

    def teach_in(self, address: int, program: int, position: int) -> ModuleState:
        """Teach In on the module's inputs (manual §2.6): a program's position changes.
        Raises OSError, and changes nothing, when the state file cannot be saved."""
        with self._lock:
            state = self._bus.modules[address]
            taught = replace(state.image.known(program), P=position)
            state = replace(state, image=state.image.with_programs({program: taught}))
            self._change(address, state)
            return state

    def _change(self, address: int, state: ModuleState) -> None:
        """A change no message says: into the state file at once (compaction)."""
        before = dict(self._bus.modules)
        self._bus.modules[address] = state
        self._saved_or_rolled_back(before, lambda store: store.compact(self._all()))

    def _all(self) -> dict[int, ModuleState]:
        """Every module the state file keeps: those served and those kept unchanged."""
        return {**self._unserved, **self._bus.modules}

    def _saved_or_rolled_back(self, before: dict[int, ModuleState], save: Callable[[Store], None]) -> None:
        """`save` into the store (if there is a state file); when that fails, put every module
        back as in `before` and raise OSError."""
        if self._store is None:
            return
        try:
            save(self._store)
        except OSError:
            self._bus.modules.update(before)
            raise

    # -- exchanges ---------------------------------------------------------------------

    def _chance(self, rate: float) -> bool:
        return rate > 0 and self._random.random() < rate

    def turnaround_of(self, address: int) -> float:
        """The time module `address` takes to answer this exchange: its turnaround ± the jitter."""
        turnaround = self.turnarounds.get(address, self.turnaround)
        if self.jitter:
            turnaround = max(0.0, turnaround + self._jitter.uniform(-self.jitter, self.jitter))
        return turnaround

    def _damage(self, frame: bytes) -> bytes:
        """`frame` with one bit flipped on the line, as the receiving UART hands it on."""
        i = self._random.randrange(len(frame))
        if self.line.parity != "none":  # a parity error: the UART drops the character
            return frame[:i] + frame[i + 1 :]
        return (frame[:i] + bytes([frame[i] ^ (1 << self._random.randrange(self.line.data_bits))])
                + frame[i + 1 :])

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
        """Serve one request frame; the reply frame to send, or None for silence. What the line
        does to it is `prc3cfg.core.exchange.FAULTS`; what a module does, `EmulatedBus`."""
        with self._lock:
            fault = self._fault()
            if fault is Fault.REQUEST_LOST:
                log.info("fault injection: request to %d lost", frame.address)
                return None
            if fault is Fault.REQUEST_DAMAGED:
                damaged = self._damaged_request(frame)
                if damaged is None:
                    return None
                frame = damaged
            answer = self._deliver(frame.address, frame.message)
            if answer is None:
                return None
            reply = self.framing.encode(Direction.REPLY, frame.address, answer)
            if self.line_speed:
                request_bytes = len(self.framing.encode(Direction.REQUEST, frame.address, frame.message))
                line_time = ((request_bytes + len(reply)) * self.line.char_time
                             + self.turnaround_of(frame.address))
                time.sleep(max(0.0, received_at + line_time - time.monotonic()))
            if fault is Fault.REPLY_LOST:
                log.info("fault injection: reply from %d lost", frame.address)
                return None
            if fault is Fault.REPLY_DAMAGED:
                log.info("fault injection: reply from %d damaged", frame.address)
                reply = self._damage(reply)
            return reply

    def _fault(self) -> Fault:
        """The fault this exchange meets, drawn (drop, corrupt, then the side) in the seeded sequence."""
        drop = self._chance(self.faults.drop_rate)
        corrupt = self._chance(self.faults.corrupt_rate)
        on_request = self._random.random() < 0.5 if (drop or corrupt) else False
        return FAULTS[drop, corrupt, on_request]

    def _damaged_request(self, frame: Frame) -> Frame | None:
        """What the modules' receivers find in `frame` with one bit flipped on the line, if anything."""
        sent = self.framing.encode(Direction.REQUEST, frame.address, frame.message)
        damaged = self._received(self._damage(sent))
        if damaged is None:
            log.info("fault injection: request to %d damaged and discarded", frame.address)
        else:
            log.info("fault injection: request damaged, delivered to %d as %s", damaged.address,
                     damaged.message.hex())
        return damaged

    def _deliver(self, address: int, message: bytes) -> bytes | None:
        """`message` to the module at `address` (or every module), the writes saved: the module's
        reply message, or None when none is sent — a broadcast, no reply, or a write not saved."""
        before = dict(self._bus.modules)
        delivery = self._bus.deliver(address, message)
        if delivery.changed:
            writes = [(a, message) for a, state in self._bus.modules.items() if state is not before[a]]
            try:
                self._saved_or_rolled_back(before, lambda store: store.record(writes, self._all()))
            except OSError as error:
                assert self._store is not None  # only a store fails to save
                to = "all modules (broadcast)" if address == BROADCAST else f"module {address}"
                log.error("%s — the write to %s is not answered and not applied",
                          cannot_save(self._store.path, error), to)
                return None
        return None if address == BROADCAST else delivery.reply

    def _serve_stream(
        self,
        recv: Callable[[float], bytes | None],
        send: Callable[[bytes], None],
        *,
        name: str,
        uart: bool,
        idle_timeout: float | None = None,
        client_line: Callable[[], LineSettings | None] = lambda: None,
    ) -> None:
        """Decode request frames from one byte stream — a UART's, or TCP's (`uart=False`) — and
        answer them until it ends, the emulator closes, or nothing arrives for `idle_timeout` seconds.
        `client_line` says the settings the client set on its end (a pty's, RFC 2217's), if any: what
        it sends at others than the emulator's arrives as a UART receives it, and so do the replies
        at its end (`prc3cfg.core.uart`)."""
        decoder = self.framing.decoder(Direction.REQUEST, self.line, zvz=self.zvz, uart=uart)
        gap = self.zvz if self.framing.name == "open-driver" else POLL
        heard = time.monotonic()
        while not self._closing.is_set():
            data = recv(gap)
            now = time.monotonic()
            if data is None:
                return
            client = client_line()
            if data:
                heard = now
                decoder.receive_data(data if client is None else uart_received(data, client, self.line), now)
            elif idle_timeout is not None and now - heard >= idle_timeout:
                log.warning("%s: nothing received for %g s — closed (idle time-out)", name, idle_timeout)
                return
            elif self.framing.name == "open-driver":
                decoder.line_idle()
            while (event := decoder.next_event(now)) is not NEED_DATA:
                if isinstance(event, Discarded):
                    if log.isEnabledFor(logging.INFO):
                        log.info("%s: discarded %s: %s", name, event.data.hex(), event.reason)
                    continue
                reply = self.exchange(event, now)
                if reply is not None:
                    send(reply if client is None else uart_received(reply, self.line, client))

    def _start(self, target: Callable[[], None], name: str) -> None:
        """Run `target` in a thread that is forgotten when it ends; RuntimeError if none can start."""

        def run() -> None:
            main_thread_only()  # an emulator in a command's process (emulator://) takes none of its signals
            try:
                target()
            finally:
                with self._guard:
                    self._threads.discard(thread)

        thread = threading.Thread(target=run, name=name, daemon=True)
        with self._guard:
            self._threads.add(thread)
        try:
            thread.start()
        except RuntimeError:
            with self._guard:
                self._threads.discard(thread)
            raise

    # -- TCP ---------------------------------------------------------------------------

    def listen(self, host: str = "127.0.0.1", port: int = 0, *, rfc2217: bool = False) -> tuple[str, int]:
        """Accept TCP connections (pyserial `socket://HOST:PORT`); returns the bound address.
        `rfc2217`: they speak RFC 2217 (`rfc2217://HOST:PORT`), as ser2net's `telnet(rfc2217)`
        accepter: the client sets the baud rate and character format of its end of the line."""
        # a burst of connections waits in the kernel
        server = socket.create_server((host, port), backlog=socket.SOMAXCONN)
        server.settimeout(POLL)

        def stop_listening() -> None:
            with contextlib.suppress(OSError):
                server.shutdown(socket.SHUT_RDWR)  # wakes the accept() waiting in another thread at once
            server.close()

        self._closers.append(stop_listening)
        self._start(lambda: self._accept(server, rfc2217), "emulator-accept")
        bound = server.getsockname()
        return bound[0], bound[1]

    def _accept(self, server: socket.socket, rfc2217: bool) -> None:
        failing = False
        while not self._closing.is_set():
            try:
                conn, peer = server.accept()
            except TimeoutError:
                continue
            except OSError as error:
                if self._closing.is_set():
                    return
                if not failing:
                    log.error("cannot accept a connection (%s) — trying again every %g s", error.strerror
                              or error, ACCEPT_BACKOFF)
                    failing = True
                self._closing.wait(ACCEPT_BACKOFF)
                continue
            if failing:
                log.warning("accepting connections again")
                failing = False
            self._admit(conn, f"{peer[0]}:{peer[1]}", rfc2217)

    def _admit(self, conn: socket.socket, name: str, rfc2217: bool) -> None:
        """Serve a new connection in its own thread, or close it at once when all slots are taken."""
        with self._guard:
            if len(self._connections) >= self.max_connections:
                self._connections -= {held for held in self._connections if _hung_up(held)}
            full = len(self._connections) >= self.max_connections
            if not full:
                self._connections.add(conn)
        if full:
            log.warning("%s: refused — the most connections allowed (%d) are open", name,
                        self.max_connections)
            conn.close()
            return
        log.info("%s: connected", name)
        try:
            self._start(lambda: self._serve_socket(conn, name, rfc2217), "emulator-conn")
        except RuntimeError as error:
            log.error("%s: refused — cannot start a thread (%s)", name, error)
            self._release(conn)

    def _release(self, conn: socket.socket) -> None:
        """Free the connection's slot, then close it: a client that sees it end can connect again."""
        with self._guard:
            self._connections.discard(conn)
        conn.close()

    def _serve_socket(self, conn: socket.socket, name: str, rfc2217: bool = False) -> None:
        def receive(timeout: float) -> bytes | None:
            conn.settimeout(timeout)  # also bounds `sendall` to a client that takes no replies
            try:
                data = conn.recv(RECV_SIZE)
            except TimeoutError:
                return b""
            except OSError:
                return None
            return data or None

        def send(data: bytes) -> None:
            conn.sendall(data)

        def no_settings() -> LineSettings | None:
            return None  # a raw TCP stream: the gateway's side fixes the line's settings

        streams = _rfc2217(receive, send) if rfc2217 else (receive, send, no_settings)
        recv, send_on, client_line = streams
        try:
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, REPLY_BUFFER)
            self._serve_stream(recv, send_on, name=name, uart=False, idle_timeout=self.idle_timeout,
                               client_line=client_line)
        except OSError as error:
            log.info("%s: %s", name, error.strerror or error)
        finally:
            self._release(conn)
            log.info("%s: closed", name)

    # -- pty ---------------------------------------------------------------------------

    def open_pty(self) -> str:
        """Serve a pseudo-terminal; returns the path any serial program can open."""
        master, slave, path = platform.open_pty()

        def close_pty() -> None:
            os.close(master)
            os.close(slave)

        self._closers.append(close_pty)

        def recv(timeout: float) -> bytes | None:
            try:
                ready, _, _ = select.select([master], [], [], timeout)
                return os.read(master, RECV_SIZE) if ready else b""
            except OSError:
                return None

        def send(data: bytes) -> None:
            os.write(master, data)

        def client_line() -> LineSettings | None:
            """The baud rate and stop bits the client set on the pty; a pty keeps no data bits or
            parity (always 8N): those are the emulator's, as if the client had set them."""
            found = platform.pty_line(master)
            if found is None:
                return None
            baud, two_stop_bits = found
            return replace(self.line, baud=baud, stop_bits=2 if two_stop_bits else 1)

        self._start(lambda: self._serve_stream(recv, send, name=path, uart=True, client_line=client_line),
                    "emulator-pty")
        return path

    # -- lifetime ----------------------------------------------------------------------

    def close(self) -> None:
        self._closing.set()
        for close in reversed(self._closers):
            with contextlib.suppress(OSError):
                close()
        with self._guard:
            threads = list(self._threads)
        for thread in threads:
            if thread.ident is not None:  # one `_start` added but a signal kept from starting never will
                thread.join(timeout=2)
        with self._lock:
            if self._store is not None:
                try:
                    self._store.close(self._all())
                except OSError as error:
                    log.error("%s — its journal keeps every write for the next start",
                              cannot_save(self._store.path, error))

    def __enter__(self) -> Emulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _RemoteEnd:
    """The settings an RFC 2217 client gave its end of the line, as `serial.rfc2217.PortManager`
    sets and reads a port's (None until the client set them). No modem lines to report."""

    baudrate: int | None = None
    bytesize: int | None = None
    parity: str | None = None
    stopbits: float | None = None
    xonxoff = rtscts = break_condition = dtr = rts = False
    cts = dsr = cd = True
    ri = False

    def reset_input_buffer(self) -> None:  # a purge asked for: a gateway has nothing to purge here
        log.info("the RFC 2217 client asked the gateway to purge its receive buffer")

    def reset_output_buffer(self) -> None:
        log.info("the RFC 2217 client asked the gateway to purge its send buffer")

    def line(self) -> LineSettings | None:
        if self.baudrate is None or self.bytesize is None or self.parity is None or self.stopbits is None:
            return None
        try:
            return LineSettings(self.baudrate, self.bytesize, PARITIES[self.parity], self.stopbits)
        except (KeyError, ValueError):
            return None  # a setting no PRC 3 line has (mark, space): as if unknown


PARITIES = {serial.PARITY_NONE: "none", serial.PARITY_EVEN: "even", serial.PARITY_ODD: "odd"}


def _rfc2217(
    recv: Callable[[float], bytes | None], send: Callable[[bytes], None]
) -> tuple[Callable[[float], bytes | None], Callable[[bytes], None], Callable[[], LineSettings | None]]:
    """A TCP stream that speaks RFC 2217: the data in it, the data sent escaped, and the client's settings."""
    end = _RemoteEnd()

    class Connection:
        def write(self, data: bytes) -> None:
            send(data)

    # what it uses of a port, and a writer
    manager = PortManager(cast(rfc2217.Serial, end), cast(rfc2217.Serial, Connection()))

    def receive(timeout: float) -> bytes | None:
        data = recv(timeout)
        return data if not data else b"".join(manager.filter(data))

    return receive, lambda data: send(b"".join(manager.escape(data))), end.line


def _hung_up(conn: socket.socket) -> bool:
    """Whether the client of `conn` has closed or reset it (its thread is about to free its slot)."""
    return platform.hung_up(conn)
