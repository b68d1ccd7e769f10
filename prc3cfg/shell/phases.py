"""An apply's phases on the clock and on the progress display: writing n/N, then verifying n/N.

`execute` (`prc3cfg.shell.apply`) runs the lines at once, each writing its modules and then
verifying them; `Phases` takes its events from every line's thread — a write acknowledged, a
line's writes ended, a module verified — and shows one phase at a time: "writing" until every
line has written, then "verifying" (with the modules some line verified already counted). It
measures each phase with `time.monotonic`, as the plan's estimate (`PlantPlan.phases`) prices it:
the wait for the slowest line.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable


class Phases:
    """The writing and verifying phases of one apply: `start(what, total)` and `advance()` are the
    progress display's (`prc3cfg.api.Progress`)."""

    def __init__(self, start: Callable[[str, int], None], advance: Callable[[], None], messages: int, modules: int, lines: int) -> None:
        self._start, self._advance = start, advance
        self._modules, self._lines_writing = modules, lines
        self._verified = 0
        self._lock = threading.Lock()
        self._began = time.monotonic()
        self._written_at: float | None = None
        start("writing", messages)

    def wrote(self) -> None:
        """A write acknowledged (a repair's too: it shows in the phase it happens in)."""
        with self._lock:
            self._advance()

    def line_written(self) -> None:
        """One line's writes ended: when it is the last, verifying begins."""
        with self._lock:
            self._lines_writing -= 1
            if self._lines_writing == 0:
                self._written_at = time.monotonic()
                self._start("verifying", self._modules)
                for _ in range(self._verified):
                    self._advance()

    def verified(self) -> None:
        """One module's verification (and repairs) ended."""
        with self._lock:
            self._verified += 1
            if self._written_at is not None:
                self._advance()

    def took(self) -> dict[str, float]:
        """Seconds each phase took, once the apply ended."""
        ended = time.monotonic()
        written = self._written_at if self._written_at is not None else ended
        return {"writing": written - self._began, "verifying": ended - written}
