"""An in-memory line: a master's port whose far end is an `Emulator` in the same thread — no TCP, no
thread (as h11's `ConnectionPair` joins a client and a server in memory).

A frame the master writes is decoded as the emulator's server decodes a TCP stream's and answered
at once by `Emulator.exchange` (its faults, its line speed); the reply waits in the port to be
read. So everything the line will ever say is in the port when `write` returns, and a read that
finds nothing is silence for good: it returns at once (after the port's `timeout`, which a `Link`
sets, so the link's own deadline is reached without spinning).

For the tests of link, read-back and emulator logic; the tests about TCP and ptys use
`Emulator.listen` (`socket://`) and `Emulator.open_pty`.
"""

from __future__ import annotations

import time

from prc3cfg.core.framing import NEED_DATA, Direction, Frame
from prc3cfg.shell.emulator.server import Emulator


class PairPort:
    """The master's end of an in-memory line to `emulator`: what a `Link` needs of a port
    (`prc3cfg.shell.link.client.Port`). `port` is its name (a scheme no TCP port has, so a link
    decodes what it reads as a UART's: every reply arrives whole, at once)."""

    def __init__(self, emulator: Emulator, name: str = "pair:test", *, timeout: float | None = 0.0) -> None:
        self.port = name
        self.timeout = timeout
        self.is_open = True
        self._emulator = emulator
        self._decoder = emulator.framing.decoder(Direction.REQUEST, emulator.line, zvz=emulator.zvz,
                                                 uart=False)
        self._replies = bytearray()

    @property
    def in_waiting(self) -> int:
        return len(self._replies)

    def write(self, data: bytes, /) -> int:
        now = time.monotonic()
        self._decoder.receive_data(data, now)
        if self._emulator.framing.name == "open-driver":
            self._decoder.line_idle()  # the line is quiet after a write: the gap that ends the frame
        while (event := self._decoder.next_event(now)) is not NEED_DATA:
            if isinstance(event, Frame) and (reply := self._emulator.exchange(event, now)) is not None:
                self._replies += reply
        return len(data)

    def read(self, size: int = 1, /) -> bytes:
        if not self._replies:
            if self.timeout:
                # a port's read waits its time-out; here nothing can arrive meanwhile
                time.sleep(self.timeout)
            return b""
        data = bytes(self._replies[:size])
        del self._replies[:size]
        return data

    def flush(self) -> None:
        pass

    def reset_input_buffer(self) -> None:
        self._replies.clear()

    def close(self) -> None:
        self.is_open = False
