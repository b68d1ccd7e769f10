"""Test support: a master on an emulated line (real framing; real pyserial, or the in-memory
line of `pair`), plain sockets for clients that misbehave, and a real `prc3cfg emulator serve`
process to point them at."""

from __future__ import annotations

import contextlib
import socket
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import serial
from pair import PairPort

from prc3cfg.core.framing import NEED_DATA, Direction, Frame, get_framing
from prc3cfg.core.line import LineSettings


class Client:
    """A master on the line, built from the real framing and pyserial — or on an in-memory line
    (`PairPort`), where silence is known at once."""

    def __init__(self, url: str | PairPort, framing: str = "crc16", *, timeout: float = 0.3,
                 **settings) -> None:
        self.framing = get_framing(framing)
        self.port = url if isinstance(url, PairPort) else serial.serial_for_url(url, timeout=timeout,
                                                                                **settings)
        self.line = LineSettings(parity="none") if settings.get("parity") == "N" else LineSettings()

    def send_raw(self, frame: bytes) -> bytes | None:
        """Write bytes; the reply message, or None when nothing valid arrives within the time-out."""
        self.port.write(frame)
        decoder = self.framing.decoder(Direction.REPLY, self.line, zvz=0.02)
        while chunk := self.port.read(max(1, self.port.in_waiting)):
            decoder.receive_data(chunk, 0.0)
            event = decoder.next_event(0.0)
            if isinstance(event, Frame):
                return event.message
        decoder.line_idle()
        event = decoder.next_event(0.0)
        return event.message if isinstance(event, Frame) else None

    def send(self, address: int, message: bytes) -> bytes | None:
        return self.send_raw(self.framing.encode(Direction.REQUEST, address, message))

    def close(self) -> None:
        self.port.close()


def answered(conn: socket.socket, address: int, message: bytes, framing: str = "crc16") -> bytes:
    """Send `message` to `address` on a plain socket; the first reply message that comes back
    (the stream must not end first)."""
    encoding = get_framing(framing)
    conn.sendall(encoding.encode(Direction.REQUEST, address, message))
    decoder = encoding.decoder(Direction.REPLY, LineSettings())
    while (event := decoder.next_event()) is NEED_DATA:
        data = conn.recv(4096)
        assert data, "the server closed the connection instead of answering"
        decoder.receive_data(data, 0.0)
    assert isinstance(event, Frame), event
    return event.message


def hang_up(conn: socket.socket) -> None:
    """Close a connection once the server has let go of it: it frees a connection's slot before
    it closes the socket, so the end of the stream says the slot is free again."""
    with conn:
        conn.shutdown(socket.SHUT_WR)
        assert conn.recv(1) == b""


@dataclass
class Served:
    """A running `prc3cfg emulator serve`: its process, TCP port and log (its stderr)."""

    process: subprocess.Popen
    port: int
    log: Path

    @property
    def url(self) -> str:
        return f"socket://127.0.0.1:{self.port}"

    def rss_kib(self) -> int:
        """The process's resident set size (VmRSS), in KiB."""
        for line in Path(f"/proc/{self.process.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
        raise AssertionError("no VmRSS in /proc/PID/status")

    def open_fds(self) -> int:
        return len(list(Path(f"/proc/{self.process.pid}/fd").iterdir()))

    def threads(self) -> int:
        return len(list(Path(f"/proc/{self.process.pid}/task").iterdir()))


def spawn(directory: Path, *options: str) -> tuple[subprocess.Popen, Path]:
    """Start `prc3cfg emulator serve --listen 127.0.0.1:0 OPTIONS`; the process and its log.

    Its stderr goes to a file, never a pipe: a pipe nobody reads would stall its logging."""
    log = directory / "serve.log"
    with log.open("w") as stderr:
        process = subprocess.Popen(
            [sys.executable, "-m", "prc3cfg", "emulator", "serve", "--listen", "127.0.0.1:0", *options],
            stdout=subprocess.PIPE, stderr=stderr, text=True,
        )
    return process, log


def listening(process: subprocess.Popen, log: Path) -> Served:
    """A spawned emulator once it listens (its banner read)."""
    banner = process.stdout.readline()
    assert banner.startswith("listening on 127.0.0.1:"), banner + log.read_text()
    return Served(process, int(banner.split()[2].rsplit(":", 1)[1]), log)


@contextlib.contextmanager
def serve(directory: Path, *options: str) -> Iterator[Served]:
    """A spawned emulator while it listens, stopped with SIGTERM (which must exit 0)."""
    process, log = spawn(directory, *options)
    try:
        yield listening(process, log)
    finally:
        process.terminate()
        assert process.wait(timeout=10) == 0, log.read_text()
