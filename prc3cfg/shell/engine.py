"""The apply engine: an apply's writes, from the lines' threads, and what it keeps of them.

`Keeping` is the journal and the records of axis releases (and E12), and stops every line when
one of them cannot be kept; `Writing` takes the snapshot, writes and verifies (`execute`) a line's
or the whole plan's changes, and keeps the account (`Written`); `ByLine` plans and writes each
line as soon as its own read-back is in, while the other lines are still read.

Does not own what is read and planned, nor the questions asked before writing and what an apply's
outcome means (`prc3cfg.api`), nor how a module is written and verified (`prc3cfg.shell.apply`).
"""

from __future__ import annotations

import contextlib
import re
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from prc3cfg.core import codec, what_to_read
from prc3cfg.core.apply_states import Event
from prc3cfg.core.image import Key, ModuleImage, Wanted
from prc3cfg.core.outcome import ModuleOutcome, to_travel
from prc3cfg.core.plant_plan import ModuleChange, PlantPlan, Reading
from prc3cfg.core.what_to_read import Known, Target
from prc3cfg.errors import Interrupted, NotSent, UserError
from prc3cfg.plant import Bus, Plant
from prc3cfg.shell import line_record, pending_records
from prc3cfg.shell.apply import ModuleRun, Verify, execute
from prc3cfg.shell.cancel import main_thread_only
from prc3cfg.shell.link.client import Exchange
from prc3cfg.shell.phases import Phases
from prc3cfg.shell.planning import SharedPlanner
from prc3cfg.shell.platform import result_of
from prc3cfg.shell.readback import LineRead, LinesFailed
from prc3cfg.shell.records import Journal, LineTaken, Snapshot
from prc3cfg.shell.sessions import LineOptions, Lines, line_cost


@dataclass(frozen=True)
class Written:
    """What an apply's writes came to: the plan, every module's outcome in the plan's order, the snapshot, the
    seconds of each phase — and why it stopped short: lines not written (`unread`, one line each),
    a record that could not be kept midway (`trouble`, the first; `lost`, every one), Ctrl-C or
    SIGTERM (`interrupted`)."""

    plan: PlantPlan
    runs: tuple[ModuleOutcome, ...] = ()
    snapshot: Path | None = None
    took: dict[str, float] = field(default_factory=dict)
    unread: tuple[str, ...] = ()
    trouble: str | None = None
    interrupted: bool = False
    lost: tuple[str, ...] = ()

    @property
    def verified(self) -> bool:
        """Every module the plan changes written and verified, and every record kept: nothing stopped short."""
        return bool(self.runs) and all(run.verified for run in self.runs) and not (self.unread or self.trouble or self.interrupted)


class Keeping:
    """What an apply keeps as it writes — its journal, its records of axis releases (and E12), its
    snapshot, the lines' records and the copy of the plant file applied in full — and what becomes of
    it when the disk refuses one of them midway (full, read-only, over a quota or the file-size limit,
    gone): the first failure is kept (`trouble`: the record, its file and the OS error), every record
    not kept is listed (`lost`), every line stops before its next frame (`stop`, the links' cancel
    event), and the account that follows says what each module was sent. A record that belongs before
    a frame keeps that frame back (`announce` raises `NotSent`); a journal that refused a record is
    written no more (a later record would follow a cut one), the others go on being kept."""

    def __init__(self, plant: Plant, buses: dict[str, Bus], keys: dict[str, tuple[str, ...]], journal: Journal,
                 records: pending_records.Releases, stop: threading.Event) -> None:  # fmt: skip
        self.journal, self.records, self._keys, self._stop = journal, records, keys, stop
        self._names = {(bus.name, m.address): m.name for bus, m in plant.modules()}
        self._buses = buses
        self._lock = threading.Lock()
        self.trouble: str | None = None
        self.lost: list[str] = []
        self._journal_lost = False

    def failed(self, what: str, error: OSError | UserError, path: Path | None = None) -> None:
        """`what` (its file at `path`, where the error does not name it) could not be kept: the lines
        stop before their next frame."""
        with self._lock:
            if self.trouble is None:
                self.trouble = f"could not keep {what} ({_refusal(error, path)})"
            if what not in self.lost:
                self.lost.append(what)
        self._stop.set()

    def _journal_failed(self, error: OSError) -> None:
        self._journal_lost = True
        self.failed(JOURNAL, error, self.journal.path)

    def announce(self, exchange: Exchange) -> None:
        """Before a frame leaves: the attempt journalled, and a 10h/20h recorded durably as an axis
        release not yet told (a broadcast's for every module on the line) — else it stays back, as
        does every frame once a record could not be kept."""
        if self.trouble is not None:
            raise NotSent()
        try:
            self.journal.request(exchange)
        except OSError as error:
            self._journal_failed(error)
            raise NotSent() from None
        if codec.MESSAGE_TYPES[exchange.request[0]].RELEASES_AXES:
            name = self._names.get((exchange.bus, exchange.address)) if exchange.address else \
                ", ".join(m.name for m in self._buses[exchange.bus].modules)  # fmt: skip
            self.record(self._keys[exchange.bus], exchange.bus, exchange.address, name or f"address {exchange.address}")
            if self.trouble is not None:
                raise NotSent()

    def observe(self, exchange: Exchange) -> None:
        """An exchange that happened, journalled (a failure stops the lines before their next frame)."""
        if not self._journal_lost:
            try:
                self.journal.exchange(exchange)
            except OSError as error:
                self._journal_failed(error)

    def note(self, event: str, **fields: Any) -> None:
        """A record of the apply (not of an exchange) in the journal, while the journal is kept."""
        if not self._journal_lost:
            try:
                self.journal.record(event, **fields)
            except OSError as error:
                self._journal_failed(error)

    def record(self, keys: tuple[str, ...], bus: str, address: int, name: str, kind: str = pending_records.RELEASE,
               code: int | None = None) -> None:  # fmt: skip
        """`pending_records.Releases.record`, a failure kept as the apply's trouble."""
        try:
            self.records.record(keys, bus, address, name, kind, code)
        except (OSError, UserError) as error:
            self.failed(RELEASE_RECORD if kind == pending_records.RELEASE else FAULT_RECORD, error, self.records.path)

    def stopped_reading(self) -> None:
        """Where the disk refused the journal a read-back's record (that read stayed back, `announce`)
        before any write began: that is what stopped the apply, not an interruption — a `UserError` saying so."""
        if self.trouble is not None:
            raise UserError(f"{self.trouble} while the modules were read back — nothing was written to any module; "
                            "free the space (or fix the folder), then apply again") from None

    def close(self) -> None:
        with contextlib.suppress(OSError):  # already kept as the trouble, or the journal was whole
            self.journal.close()


#: The records an apply keeps, as its account names one it could not keep.
JOURNAL, SNAPSHOT, LINE_RECORD = "the journal", "the snapshot", "the line's record of what its modules hold"
RELEASE_RECORD, FAULT_RECORD, APPLIED = ("the record of an axis release", "the record of a module in a fault state (E12, E21, …)",
                                         "the copy of the plant file applied in full")


def _refusal(error: OSError | UserError, path: Path | None) -> str:
    """What the disk said, and of which file: "PATH: No space left on device". The file is the record's
    own, not the temporary name an atomic write refused; a `UserError` of the lines' and releases'
    records ("cannot keep … (WHERE: WHY) — what to do") gives its WHERE: WHY."""
    if isinstance(error, UserError):
        said = str(error)
        return inner[1] if (inner := re.fullmatch(r"cannot keep .*? \((.*)\) — .*", said)) else said
    where = path or error.filename
    return f"{where}: {error.strerror}" if where and error.strerror else (error.strerror or str(error))


def _keep_faults(keeping: Keeping, keys: dict[str, tuple[str, ...]], runs: Sequence[ModuleOutcome]) -> None:
    """The fault states the writes revealed, recorded; those a write since shows gone, cleared. E12: kept for
    the next plan, which writes the system parameters first, cleared once verified; any other (E09, E21, …):
    told by every command on the line until a write to the module is acknowledged (a read cannot see it)."""
    for run in runs:
        if run.system_unset:
            keeping.record(keys[run.bus], run.bus, run.address, run.name, pending_records.E12)
        elif run.fault is not None:
            keeping.record(keys[run.bus], run.bus, run.address, run.name, pending_records.FAULT, run.fault)
    every = [k for ks in keys.values() for k in ks]
    pending_records.cleared(r for r in pending_records.of_line(every, pending_records.E12)
                     if any(run.verified and (run.bus, run.address) == (r.bus, r.address) for run in runs))
    pending_records.cleared(r for r in pending_records.of_line(every, pending_records.FAULT)
                     if any(run.written and (run.bus, run.address) == (r.bus, r.address) for run in runs))


class Writing:
    """An apply's writes, a line or the whole plan at a time, from any line's thread: the runs of
    the modules a plan changes, the snapshot of those modules saved before the first write on
    their line — added to the apply's one snapshot file, written whole and atomically each time —
    and journalled, then written and verified (`execute`); then the account of every run."""

    def __init__(self, plant: Plant, keys: dict[str, tuple[str, ...]], buses: dict[str, Bus], held: Lines, keeping: Keeping,
                 verify: Verify, options: LineOptions, command: str) -> None:  # fmt: skip
        self.plant, self.keys, self.buses, self.keeping = plant, keys, buses, keeping
        self.held, self.links, self.records = held, held.links, held.on_record.records
        self.journal = keeping.journal
        self.verify, self.options, self.command = verify, options, command
        self.phases = Phases(options.progress.start, options.progress.advance)
        self.runs: list[ModuleRun] = []
        self.snapshot: Path | None = None
        self._taken: Snapshot | None = None
        self._whole = False
        self._lock = threading.Lock()
        # on a line without error detection every module is watched, the unchanged ones too: a damaged
        # frame meant for another can release its axes
        self._exposed = {name for name, bus in buses.items() if not bus.detects_damage}
        self._costs = {name: line_cost(bus) for name, bus in buses.items()}

    def _runs(self, changes: Iterable[ModuleChange]) -> list[ModuleRun]:
        return [ModuleRun(c.bus, c.address, c.name, c.actual, c.desired, c.steps, c.plan.predicted, c.broadcasts, c.bus in self._exposed,
                          frozenset(c.assumed))
                for c in changes if c.steps or c.bus in self._exposed or c.assumed]  # fmt: skip

    def whole(self, the_plan: PlantPlan, show: Callable[[PlantPlan], None] | None = None, at: float | None = None) -> None:
        """The plant's plan is whole (`show`n, the display held still) — since `at`, if not now: the
        writing phase, and the snapshot's path told once it holds every module the plan writes."""
        runs = self._runs(the_plan.modules)
        self.phases.writing(the_plan.message_count, len(runs), len({r.bus for r in runs}), lambda: show(the_plan) if show else None, at)
        with self._lock:
            self._whole = True
            self._tell_snapshot(len(runs))

    def _tell_snapshot(self, modules: int) -> None:
        if self._whole and self._taken is not None and len(self._taken.images) == modules:
            self.options.progress.note(f"Snapshot of the modules before writing: {self.snapshot}")

    def write(self, changes: Sequence[ModuleChange], images: Mapping[Key, ModuleImage], allow_axis_release: bool,
              started: Callable[[], None] | None = None) -> None:  # fmt: skip
        """Write and verify these changes — one line's, or every line's — once their modules are in
        the snapshot and the journal. Consent is per module: the releases of these changes, if allowed
        (a repair may not add one). `started()` at each write acknowledged, or at once with none to make."""
        started = started or _nothing
        runs = self._runs(changes)
        if not runs:
            started()
            return
        known = self._before_writing(runs, images)
        if self.keeping.trouble is not None:
            for run in runs:
                run.process(Event.CANCELLED)
                run.problem = "nothing was sent to it"
            started()
            return
        consented = frozenset((c.bus, c.address) for c in changes if c.releases_axes) if allow_axis_release else frozenset()

        def wrote() -> None:
            self.phases.wrote()
            started()

        try:
            execute(runs, self.links, self._costs, tick=wrote,
                    written=self.phases.line_written, verified=self.phases.verified, consented=consented, verify=self.verify)  # fmt: skip
        finally:
            self._verified(runs, known)

    def _before_writing(self, runs: list[ModuleRun], images: Mapping[Key, ModuleImage]) -> dict[str, dict[int, Known]]:
        """The runs' modules dropped from their lines' records — not known until verified; what was
        known is given back, for then — and added to the snapshot, journalled. When either cannot be
        kept, that is the apply's trouble (`Keeping.failed`): these writes stay back, as do every
        other line's next frames."""
        known = {bus: self.records[bus].known() for bus in {r.bus for r in runs}}
        with self._lock:
            self.runs.extend(runs)
            try:
                for bus in known:
                    self.records[bus].forget([r.address for r in runs if r.bus == bus])
            except UserError as error:  # another line's writes may have begun: this one's stay back
                self.keeping.failed(LINE_RECORD, error)
                return known
            try:
                self.snapshot, written = self._snapshot_with(runs, images)
            except OSError as error:  # the snapshot on disk, if any, holds the modules of the lines written before
                self.keeping.failed(SNAPSHOT, error, self._taken.path if self._taken is not None else None)
                return known
            # under the lock: the last snapshot record is the file's
            self.keeping.note("snapshot", path=self.snapshot.name, sha256=written)
            if self._whole:
                self._tell_snapshot(len(self._taken.images) if self._taken is not None else 0)
        self.keeping.note("apply", plant=self.plant.name, plant_sha256=self.plant.sha256, snapshot=str(self.snapshot),
                          modules=[f"{r.bus}/{r.address}" for r in runs])  # fmt: skip
        return known

    def _snapshot_with(self, runs: list[ModuleRun], images: Mapping[Key, ModuleImage]) -> tuple[Path, str]:
        """The apply's one snapshot, with the runs' modules as read before writing, saved whole: its path and digest.
        A factory-fresh module's programs planned as the factory's (`ModuleRun.assumed`) hold the factory's there:
        not read, what a restore puts back — the undo of a commissioning."""
        if self._taken is None:
            taken_on = {name: LineTaken(bus.port, bus.framing, self.keys[name]) for name, bus in self.buses.items()}
            self._taken = Snapshot.take(self.plant.path, self.plant.sha256, {}, taken_on, self.journal.header)
        self._taken.images.update({(r.bus, r.address): what_to_read.from_factory(images[(r.bus, r.address)], r.assumed) for r in runs})
        return self._taken.saved()

    def _verified(self, runs: list[ModuleRun], known: dict[str, dict[int, Known]]) -> None:
        """What the modules that verified hold, back into their lines' records: the read-back with the
        steps' effect, and what the record knew of the rest (`what_to_read.verified`)."""
        when, by = line_record.now(), line_record.who(self.command, self.plant.path)
        for bus, held in known.items():
            done = {r.address: r for r in runs if r.bus == bus and r.verified}
            try:
                self.records[bus].update({a: what_to_read.verified(held.get(a), _holds(run), when, by) for a, run in done.items()})
            except UserError as error:  # they stay unknown (forgotten before the writes): the next plan reads them in full
                self.keeping.failed(LINE_RECORD, error)

    def account(self, the_plan: PlantPlan, took: dict[str, float] | None = None, unread: tuple[str, ...] = ()) -> Written:
        """What the writes came to, every module's outcome in the plan's order — recorded (E12 kept for the next
        plan, cleared once verified) and journalled, with the travel to the reference point and, when
        a signal stopped the lines, that it did."""
        order = {(c.bus, c.address): index for index, c in enumerate(the_plan.modules)}
        keys, keeping = self.keys, self.keeping
        stopped = None if keeping.trouble is None else "a record could not be kept"
        runs = tuple(run.outcome(stopped) for run in sorted(self.runs, key=lambda run: order[(run.bus, run.address)]))
        for record in self.records.values():  # what a line left as it was read: kept here, where a failure is
            try:  # the account's trouble (`RecordsFailed`, every run said), not an error after it that hides it
                record.write()
            except UserError as error:
                keeping.failed(LINE_RECORD, error)
        _keep_faults(keeping, keys, runs)
        for run in runs:
            keeping.note(
                "result", bus=run.bus, address=run.address, verified=run.verified, failure=run.failure,
                released_axes=run.released.value, written=[s.message.hex() for s in run.written],
                interrupted=run.interrupted,
            )  # fmt: skip
        if released := to_travel(runs):
            keeping.note("travel_to_reference_point", modules=[f"{r.bus}/{r.address}" for r in released])
        interrupted = keeping.trouble is None and self.options.cancel is not None and self.options.cancel.requested
        if interrupted:
            keeping.note("interrupted")
        return Written(the_plan, runs, self.snapshot, (took or {}) | self.phases.took(), unread, keeping.trouble, interrupted,
                       tuple(keeping.lost))


class ByLine:
    """An apply with no question between the plan and the writes: each module planned as soon as it
    is read, and each line — its broadcasts decided once its last module is read — written as soon as
    its own plan is whole, while the other lines are still read and planned: no line waits for
    another. The plant's plan is shown once whole, the writes going on. A line whose read-back or
    plan fails is not written; the others are, and the account says both (`Written.unread`).

    `line` is called from each line's thread with its read-back; what the lines have read and
    planned so far is shared under one lock."""

    def __init__(self, writing: Writing, planner: SharedPlanner, want: list[Wanted], targets: Sequence[Target], *,
                 reading: Callable[[dict[Key, ModuleImage]], Reading | None],
                 show: Callable[[PlantPlan], None] | None = None, show_line: Callable[[PlantPlan], None] | None = None) -> None:  # fmt: skip
        self.writing, self.planner, self.want, self._reading = writing, planner, want, reading
        self._show, self._show_line = show, show_line
        self._modules = len(targets)
        self._lines = {target.bus for target in targets}  # the lines to read
        self._lock = threading.Lock()
        self._images: dict[Key, ModuleImage] = {}
        self._planned: list[str] = []
        self._whole_at: float | None = None  # when the last line's plan was whole
        self._shown: list[Future[None]] = []
        self._showing: ThreadPoolExecutor | None = None

    def plan(self) -> PlantPlan:
        """The plan of the lines planned so far, with what they read."""
        with self._lock:
            read, done = dict(self._images), set(self._planned)
        return replace(self.planner.plan([w for w in self.want if w.bus in done], read), reading=self._reading(read))

    def line(self, bus: str, read: dict[Key, ModuleImage]) -> None:
        """A line's read-back is in: plan it, then write it."""
        self.planner.plan_line(bus, self.want, read, self.writing.links[bus])
        with self._lock:
            self._images.update(read)
            self._planned.append(bus)
            whole = len(self._planned) == len(self._lines)
            if whole:
                self._whole_at = time.monotonic()
        changes = self.planner.line_changes(bus)
        if self._show_line is not None and any(c.steps for c in changes):  # what a line's writes follow is shown before them
            self._show_line(self.planner.plan([w for w in self.want if w.bus == bus], read))
        # the plant's plan shown once the last line's first write is acknowledged: its rendering never holds that frame back
        self.writing.write(changes, read, True, started=self._whole if whole else None)

    def _whole(self) -> None:
        """The plant's plan shown (once), beside the writes; the writing phase began when it became whole."""
        with self._lock:
            if not self._shown and self._showing is not None:
                self._shown.append(self._showing.submit(lambda: self.writing.whole(self.plan(), self._show, self._whole_at)))

    def run(self, read: Callable[[LineRead], object]) -> Written:
        """`read(line)` reads every line back, calling `line` with each line's read-back as soon as it is
        in; then the account. A signal must wait its turn meanwhile (`LineOptions.deferred`, the caller's)."""
        writing = self.writing
        unread: tuple[str, ...] = ()
        with ThreadPoolExecutor(max_workers=1, initializer=main_thread_only) as self._showing:
            writing.phases.reading(self._modules)
            try:
                read(self.line)
            except Interrupted:
                if not writing.runs:
                    writing.keeping.stopped_reading()
                    raise
                unread = tuple(f"bus {bus}: interrupted before its read-back and plan were whole — nothing was written on it"
                               for bus in sorted(self._lines - set(self._planned)))  # fmt: skip
            except LinesFailed as error:
                if not writing.runs:
                    writing.keeping.stopped_reading()
                    raise
                unread = tuple(f"{said} — nothing was written on bus {bus}" for bus, said in error.failed.items())
            if len(self._planned) == len(self._lines):
                self._whole()  # not yet, when no write of the last line was acknowledged
            for future in self._shown:
                result_of(future)
            if writing.options.cancel is not None and not writing.runs:
                writing.options.cancel.check()
            planned = self.plan()
            if not writing.runs:
                return Written(planned)
            return writing.account(planned, unread=unread)


def _nothing() -> None:
    pass


def _holds(run: ModuleRun) -> ModuleImage:
    """What a verified module holds: its last read-back, and the device model's prediction where that read nothing."""
    final = run.final or run.predicted
    return replace(final, programs=tuple(f if f is not None else p for f, p in zip(final.programs, run.predicted.programs)))
