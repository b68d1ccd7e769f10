"""An apply without a question between the plan and the writes, line by line: `ByLine`.

Each line is read back, planned and written in its own thread as soon as its own plan is whole, while the
other lines are still read (`prc3cfg.shell.planning.read_and_plan_lines`, `prc3cfg.shell.engine.Writing`).
What the caller shows — each line's plan before its writes, the plant's once whole — the lines' threads give
back to the caller's thread (`ByLine.run`, an iterator) and never call: the caller's loop shows it between the
stages, and the lines go on. Per line the stages run in turn — read, plan (`read_and_plan_lines`), the gate's
consent asked of the caller (`run` gives the line's plan, and is sent the `Consent` back), write and verify,
record (`Writing.write`) — the lines at once, each in its own thread.

Does not own the writes and the account (`prc3cfg.shell.engine`), nor what is read and shown (`prc3cfg.api`).
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Generator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

from prc3cfg.core.image import Key, ModuleImage
from prc3cfg.core.plant_plan import PlantPlan
from prc3cfg.core.stages import Consent, LinePlan, ReadBack
from prc3cfg.core.what_to_read import Target
from prc3cfg.errors import Interrupted
from prc3cfg.shell import line_record
from prc3cfg.shell.cancel import main_thread_only
from prc3cfg.shell.engine import Writing, Written
from prc3cfg.shell.planning import SharedPlanner, read_and_plan_lines
from prc3cfg.shell.platform import next_of, result_of, wait_for
from prc3cfg.shell.readback import LinesFailed


@dataclass(frozen=True)
class LinePlanned:
    """A line's own plan, whole (`ByLine.run`): the line writes once the caller sends the gate's `Consent`
    back."""

    plan: PlantPlan


@dataclass(frozen=True)
class WholePlanned:
    """The plant's plan (`ByLine.run`), from what was `read`: whole since `at` (`time.monotonic`), told once
    the last line's first write is acknowledged — the writes go on while it is shown."""

    plan: PlantPlan
    read: dict[Key, ModuleImage]
    at: float | None


@dataclass
class _Told:
    """A line's plan told to `ByLine.run`'s caller: the line waits for `done`, and writes with the `consent`
    the caller sent back — none: the caller stopped first."""

    planned: LinePlanned
    done: threading.Event = field(default_factory=threading.Event)
    consent: Consent | None = None


# told by the lines' threads: the plant's plan is whole; every line read (and written)
_WHOLE, _READ = "whole", "read"


class ByLine:
    """An apply with no question between the plan and the writes: each module planned as soon as it
    is read, and each line — its broadcasts decided once its last module is read — written as soon as
    its own plan is whole, while the other lines are still read and planned: no line waits for
    another. A line whose read-back or plan fails is not written; the others are, and the account says
    both (`Written.unread`).

    The lines' threads call nothing of the caller's: `run` gives back, in the caller's thread, each line's
    plan before that line's first write — the caller sends back the gate's consent — and the plant's plan once
    whole, the writes going on; `account` then."""

    def __init__(self, writing: Writing, planner: SharedPlanner, targets: Sequence[Target]) -> None:
        self.writing, self.planner, self._targets = writing, planner, targets
        self._lines = {target.bus for target in targets}  # the lines to read
        self._lock = threading.Lock()
        self.images: dict[Key, ModuleImage] = {}  # what the lines planned so far read
        self._planned: list[str] = []
        self._whole_at: float | None = None  # when the last line's plan was whole
        self._told: queue.SimpleQueue[_Told | str] = queue.SimpleQueue()
        self._whole_told = self._closed = False
        self._unread: tuple[str, ...] = ()

    def _line(self, read_back: ReadBack, line: LinePlan) -> None:
        """A line's read-back is in and planned (`read_and_plan_lines`): its plan told and gated by the
        caller, then written — a line with nothing to send needs no consent (it is only watched)."""
        bus, read = read_back.bus, read_back.images
        with self._lock:
            self.images.update(read)
            self._planned.append(bus)
            whole = len(self._planned) == len(self._lines)
            if whole:
                self._whole_at = time.monotonic()
        consent = Consent()
        if any(c.steps for c in line.changes):  # what a line's writes follow is shown and gated before them
            told = _Told(LinePlanned(self.planner.plan(read, (bus,))))
            with self._lock:
                closed = self._closed
                if not closed:
                    self._told.put(told)
            if not closed:
                wait_for(told.done)  # the caller's `run` sets it, or its end does
            if told.consent is None:  # the caller stopped before it gated the line: nothing is written on it
                raise Interrupted()
            consent = told.consent
        # the plant's plan told once the last line's first write is acknowledged: its rendering never holds
        # that frame back
        self.writing.write(line, consent, started=self._whole if whole else None)

    def _whole(self) -> None:
        """The plant's plan told (once), the writes going on."""
        with self._lock:
            if not self._whole_told and not self._closed:
                self._whole_told = True
                self._told.put(_WHOLE)

    def _read(self, by: str) -> None:
        """Every line read back, planned and written, from the lines' threads; then `_READ` told."""
        writing = self.writing
        try:
            read_and_plan_lines(self._targets, writing.links, writing.held.on_record, by, self.planner,
                                progress=writing.phases.read, then=self._line)
        finally:
            self._told.put(_READ)

    def _whole_plan(self) -> WholePlanned:
        with self._lock:
            read, done, at = dict(self.images), set(self._planned), self._whole_at
        return WholePlanned(self.planner.plan(read, done), read, at)

    def run(self) -> Generator[LinePlanned | WholePlanned, Consent | None, None]:
        """Every line read back, planned and written, its threads at work while this gives back, in the
        caller's thread, each line's plan — that line waits until the caller sends the gate's `Consent` back —
        and the plant's plan once whole (nothing is sent back). A signal must wait its turn meanwhile
        (`LineOptions.deferred`, the caller's)."""
        writing = self.writing
        with ThreadPoolExecutor(max_workers=1, initializer=main_thread_only) as reader:
            writing.phases.reading(len(self._targets))
            reading = reader.submit(self._read, line_record.who(writing.command, writing.plant.path))
            try:
                while (told := next_of(self._told)) != _READ:
                    if told == _WHOLE:
                        yield self._whole_plan()
                    elif isinstance(told, _Told):
                        try:
                            told.consent = yield told.planned
                        finally:
                            told.done.set()
            finally:
                # a line that tells its plan now writes nothing, and none waits for the caller
                with self._lock:
                    self._closed = True
                while not self._told.empty():
                    if isinstance(left := self._told.get_nowait(), _Told):
                        left.done.set()
            try:
                result_of(reading)
            except Interrupted:
                if not writing.runs:
                    writing.keeping.stopped_reading()
                    raise
                self._unread = tuple(f"bus {bus}: interrupted before its read-back and plan were whole — "
                                     "nothing was written on it"
                                     for bus in sorted(self._lines - set(self._planned)))
            except LinesFailed as error:
                if not writing.runs:
                    writing.keeping.stopped_reading()
                    raise
                self._unread = tuple(f"{said} — nothing was written on bus {bus}"
                                     for bus, said in error.failed.items())
        if len(self._planned) == len(self._lines) and not self._whole_told:
            self._whole_told = True
            yield self._whole_plan()  # not yet, when no write of the last line was acknowledged

    def account(self) -> Written:
        """Once `run` is through: the account of the writes (without the plan's `reading`, the caller's)."""
        writing = self.writing
        if writing.options.cancel is not None and not writing.runs:
            writing.options.cancel.check()
        planned = self.planner.plan(self.images, self._planned)
        if not writing.runs:
            return Written(planned)
        return writing.account(planned, unread=self._unread)


def next_stage(stages: Generator[LinePlanned | WholePlanned, Consent | None, None],
               consent: Consent | None) -> LinePlanned | WholePlanned | None:
    """What `ByLine.run` gives next, `consent` — the gate's for the line it gave last, else None — sent back;
    None once it is through."""
    try:
        return stages.send(consent)
    except StopIteration:
        return None
