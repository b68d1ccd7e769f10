"""An apply's phases on the clock and on the progress display: reading n/N, writing n/N, then verifying n/N.

`execute` (`prc3cfg.shell.apply`) runs the lines at once, each writing its modules and then
verifying them; `Phases` takes its events from every line's thread — a module read, a write
acknowledged, a line's writes ended, a module verified — and shows one phase at a time:
"reading modules" until every line is read and the plan is whole, "writing" until every line has
written, then "verifying" — each with what some line did already counted (a line is written as
soon as its own plan is whole when no question stands between: `prc3cfg.shell.by_line`). It measures each
phase with `time.monotonic`, as the plan's estimate (`PlantPlan.phases`) prices it: the wait for
the slowest line. `Progress` is what a progress display implements (`Quiet`: none).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Protocol


class Progress(Protocol):
    """Where long work reports: a phase with its total, each step done, a line to show."""

    def start(self, what: str, total: int) -> None: ...

    def advance(self) -> None: ...

    def note(self, text: str) -> None: ...


class Quiet:
    """A `Progress` that reports nothing."""

    def start(self, what: str, total: int) -> None:
        pass

    def advance(self) -> None:
        pass

    def note(self, text: str) -> None:
        pass


class Phases:
    """The phases of one apply: `start(what, total)` and `advance()` are the progress display's
    (`Progress`). `reading(total)` first when the reading is measured here; `writing`
    once the plan is whole (after its questions, if any)."""

    def __init__(self, start: Callable[[str, int], None], advance: Callable[[], None]) -> None:
        self._start, self._advance = start, advance
        self._phase = ""
        self._lines = self._lines_written = self._wrote = self._verified = self._modules = self._messages = 0
        self._lock = threading.Lock()
        self._began = time.monotonic()
        self._read_at: float | None = None
        self._writing_at: float | None = None
        self._written_at: float | None = None

    def reading(self, modules: int) -> None:
        """The read-back begins: `modules` to read."""
        with self._lock:
            self._phase, self._began = "reading", time.monotonic()
            self._start("reading modules", modules)

    def read(self) -> None:
        """One module read."""
        with self._lock:
            if self._phase == "reading":
                self._advance()

    def writing(self, messages: int, modules: int, lines: int, at: float | None = None) -> None:
        """The plan is whole — `messages` to write to `modules` on `lines` — and the writes begin (or
        go on: those some line made already are counted). `at`: when the plan became whole
        (`time.monotonic`), if that was before now."""
        now = time.monotonic() if at is None else at
        with self._lock:
            if self._phase == "reading":
                self._read_at = now
            self._phase, self._writing_at = "writing", now
            self._modules, self._lines, self._messages = modules, lines, messages
            self._start("writing", messages)
            for _ in range(min(self._wrote, messages)):
                self._advance()
            self._writes_ended()

    def wrote(self) -> None:
        """A write acknowledged: one of the plan's messages written, up to their number — a repair's write
        (a line verifying while another still writes) is part of its module's verification, which counts
        modules: the display never says more done than there is."""
        with self._lock:
            self._wrote += 1
            if self._phase == "writing" and self._wrote <= self._messages:
                self._advance()

    def line_written(self) -> None:
        """One line's writes ended: when it is the last, verifying begins."""
        with self._lock:
            self._lines_written += 1
            if self._phase == "writing":
                self._writes_ended()

    def _writes_ended(self) -> None:
        if self._lines_written == self._lines:
            self._phase, self._written_at = "verifying", time.monotonic()
            self._start("verifying", self._modules)
            for _ in range(self._verified):
                self._advance()

    def verified(self) -> None:
        """One module's verification (and repairs) ended."""
        with self._lock:
            self._verified += 1
            if self._phase == "verifying":
                self._advance()

    def took(self) -> dict[str, float]:
        """Seconds each phase took, once the apply ended: reading (when measured here) until the plan
        was whole, writing from then — or from the answers to its questions — until every line had
        written, verifying the rest."""
        ended = time.monotonic()
        writing = self._writing_at if self._writing_at is not None else ended
        written = self._written_at if self._written_at is not None else ended
        read = {"reading": self._read_at - self._began} if self._read_at is not None else {}
        return read | {"writing": written - writing, "verifying": ended - written}
