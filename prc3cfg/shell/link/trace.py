"""`--trace FILE`: every frame on every line, both directions, with timestamps, in hex.

One line per event, tab-separated, so it greps and diffs well:

    2026-11-21T05:12:01.123456+00:00  booth-a  >  a501015000e1c3
    2026-11-21T05:12:01.150012+00:00  booth-a  <  0501 ...
    2026-11-21T05:12:01.650000+00:00  booth-a  !  timeout after 0.500 s (attempt 1 of 4)

`>` request sent, `<` reply frame received, `x` bytes the decoder discarded (and why),
`!` a time-out, retry or other remark. Thread-safe: buses run in parallel.
"""

from __future__ import annotations

import threading
from datetime import UTC, datetime
from typing import TextIO


class Trace:
    def __init__(self, stream: TextIO) -> None:
        self._stream = stream
        self._lock = threading.Lock()

    def write(self, bus: str, direction: str, text: str) -> None:
        stamp = datetime.now(UTC).isoformat(timespec="microseconds")
        with self._lock:
            self._stream.write(f"{stamp}\t{bus}\t{direction}\t{text}\n")
            self._stream.flush()

    def sent(self, bus: str, frame: bytes) -> None:
        self.write(bus, ">", frame.hex())

    def received(self, bus: str, frame: bytes) -> None:
        self.write(bus, "<", frame.hex())

    def discarded(self, bus: str, data: bytes, reason: str) -> None:
        self.write(bus, "x", f"{data.hex()}\t{reason}")

    def remark(self, bus: str, text: str) -> None:
        self.write(bus, "!", text)
