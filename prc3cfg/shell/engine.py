"""The apply engine: an apply's writes, from the lines' threads, and what it keeps of them.

`Keeping` is the journal and the records of axis releases (and E12), and stops every line when one of them
cannot be kept; `Writing` runs the write stages of a line's or the whole plan's changes
(`prc3cfg.core.stages.LinePlan`, with the gate's `Consent`) — `ready` (a 10h/20h to a module the consent does
not name refused: `NotConsented`; the snapshot, the journal), `write_and_verify` (`execute`), `record` — and
keeps the account (`Written`). A line written as soon as its own plan is whole: `prc3cfg.shell.by_line`.

Does not own what is read and planned, nor the questions asked before writing and what an apply's
outcome means (`prc3cfg.api`), nor how a module is written and verified (`prc3cfg.shell.apply`).
"""

from __future__ import annotations

import contextlib
import re
import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from prc3cfg.core import codec, what_to_read
from prc3cfg.core.apply_states import Event
from prc3cfg.core.image import Key, ModuleImage
from prc3cfg.core.outcome import ModuleOutcome, to_travel
from prc3cfg.core.plant_plan import ModuleChange, PlantPlan
from prc3cfg.core.stages import Consent, LinePlan
from prc3cfg.core.what_to_read import Known
from prc3cfg.errors import NotSent, UserError
from prc3cfg.plant import Bus, Plant
from prc3cfg.shell import line_record, pending_records
from prc3cfg.shell.apply import ModuleRun, Verify, execute
from prc3cfg.shell.link.client import Exchange
from prc3cfg.shell.phases import Phases
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
        """Every module the plan changes written and verified, and every record kept: nothing stopped
        short."""
        stopped = self.unread or self.trouble or self.interrupted
        return bool(self.runs) and all(run.verified for run in self.runs) and not stopped


@dataclass(frozen=True)
class Sending:
    """A plan's writes made ready (`Writing.ready`): the runs of its modules — each filled in as it is written
    and verified — what their lines' records knew of them before (given back once verified, `Writing.record`),
    and the modules whose axes a repair may release."""

    runs: tuple[ModuleRun, ...]
    known: dict[str, dict[int, Known]]
    consented: frozenset[Key]


class NotConsented(UserError):
    """The write stage was given a change that releases axes (10h/20h) of a module its consent does not name:
    nothing was sent."""


class Keeping:
    """What an apply keeps as it writes — its journal, its records of axis releases (and E12), its
    snapshot, the lines' records and the copy of the plant file applied in full — and what becomes of
    it when the disk refuses one of them midway (full, read-only, over a quota or the file-size limit,
    gone): the first failure is kept (`trouble`: the record, its file and the OS error), every record
    not kept is listed (`lost`), every line stops before its next frame (`stop`, the links' cancel
    event), and the account that follows says what each module was sent. A record that belongs before
    a frame keeps that frame back (`announce` raises `NotSent`); a journal that refused a record is
    written no more (a later record would follow a cut one), the others go on being kept."""

    def __init__(self, plant: Plant, buses: dict[str, Bus], keys: dict[str, tuple[str, ...]],
                 journal: Journal,
                 records: pending_records.Releases, stop: threading.Event) -> None:
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
                ", ".join(m.name for m in self._buses[exchange.bus].modules)
            self.record(self._keys[exchange.bus], exchange.bus, exchange.address, name
                        or f"address {exchange.address}")
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

    def record(self, keys: tuple[str, ...], bus: str, address: int, name: str,
               kind: str = pending_records.RELEASE,
               code: int | None = None) -> None:
        """`pending_records.Releases.record`, a failure kept as the apply's trouble."""
        try:
            self.records.record(keys, bus, address, name, kind, code)
        except (OSError, UserError) as error:
            self.failed(RELEASE_RECORD if kind == pending_records.RELEASE else FAULT_RECORD, error,
                        self.records.path)

    def stopped_reading(self) -> None:
        """Where the disk refused the journal a read-back's record (that read stayed back, `announce`)
        before any write began: that is what stopped the apply, not an interruption — a `UserError` saying so.
        """
        if self.trouble is not None:
            raise UserError(f"{self.trouble} while the modules were read back — nothing was written to "
                            "any module; "
                            "free the space (or fix the folder), then apply again") from None

    def close(self) -> None:
        with contextlib.suppress(OSError):  # already kept as the trouble, or the journal was whole
            self.journal.close()


#: The records an apply keeps, as its account names one it could not keep.
JOURNAL, SNAPSHOT, LINE_RECORD = "the journal", "the snapshot", "the line's record of what its modules hold"
RELEASE_RECORD, FAULT_RECORD, APPLIED = ("the record of an axis release",
                                         "the record of a module in a fault state (E12, E21, …)",
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
    """An apply's writes, a line or the whole plan at a time, from any line's thread (`write`: its stages in
    turn): the runs of the modules a plan changes, the snapshot of those modules saved before the first write
    on their line — added to the apply's one snapshot file, written whole and atomically each time — and
    journalled (`ready`), then written and verified (`write_and_verify`) and recorded (`record`); then the
    account of every run."""

    def __init__(self, plant: Plant, keys: dict[str, tuple[str, ...]], buses: dict[str, Bus], held: Lines,
                 keeping: Keeping,
                 verify: Verify, options: LineOptions, command: str) -> None:
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
        return [ModuleRun(c.bus, c.address, c.name, c.actual, c.desired, c.steps, c.plan.predicted,
                          c.broadcasts, c.bus in self._exposed,
                          frozenset(c.assumed))
                for c in changes if c.steps or c.bus in self._exposed or c.assumed]

    def whole(self, the_plan: PlantPlan, at: float | None = None) -> None:
        """The plant's plan is whole (and shown) — since `at`, if not now: the writing phase, and the
        snapshot's path told once it holds every module the plan writes."""
        runs = self._runs(the_plan.modules)
        self.phases.writing(the_plan.message_count, len(runs), len({r.bus for r in runs}), at)
        with self._lock:
            self._whole = True
            self._tell_snapshot(len(runs))

    def _tell_snapshot(self, modules: int) -> None:
        if self._whole and self._taken is not None and len(self._taken.images) == modules:
            self.options.progress.note(f"Snapshot of the modules before writing: {self.snapshot}")

    def write(self, line: LinePlan, consent: Consent, started: Callable[[], None] | None = None) -> None:
        """The write stages of a line's plan — or the whole plan's — in turn: `ready`, `write_and_verify`,
        `record` (also when writing and verifying ended early: what verified is known). `started()` at each
        write acknowledged, or at once with none to make."""
        started = started or _nothing
        sending = self.ready(line, consent)
        if sending is None:
            started()
            return
        try:
            self.write_and_verify(sending, started)
        finally:
            self.record(sending)

    def ready(self, line: LinePlan, consent: Consent) -> Sending | None:
        """The runs of the changes, once their modules are in the snapshot and the journal — or None: nothing
        to send, or the writes stay back (a record could not be kept, each run says "nothing was sent to it").
        `consent`: the modules whose axes the operator agreed to release (with the plan shown, or up front): a
        change that releases another's is refused, before anything — `NotConsented`."""
        if refused := [c for c in line.changes if c.releases_axes
                       and (c.bus, c.address) not in consent.releases]:
            modules = ", ".join(f"bus {c.bus}, module {c.address} ({c.name})" for c in refused)
            raise NotConsented(f"{modules}: the plan releases the axes (10h/20h), and no consent to that "
                               "was given with it — nothing was sent to any module: review the plan, and "
                               "allow the release (--allow-axis-release)")
        runs = self._runs(line.changes)
        if not runs:
            return None
        known = self._before_writing(runs, line.images)
        if self.keeping.trouble is not None:
            for run in runs:
                run.process(Event.CANCELLED)
                run.problem = "nothing was sent to it"
            return None
        return Sending(tuple(runs), known, line.releasing)  # each in `consent`: refused above else

    def write_and_verify(self, sending: Sending, started: Callable[[], None]) -> None:
        """The runs written and verified (`execute`), their outcomes left in them; a repair may release only
        the axes a change of the plan releases. One stage, not a write and then a verify: on a line every
        module is written before any is verified (a module's verification sees what a damaged frame meant for
        another did to it), and a verification that finds a difference writes again (a repair round) and
        verifies again."""

        def wrote() -> None:
            self.phases.wrote()
            started()

        execute(list(sending.runs), self.links, self._costs, tick=wrote, written=self.phases.line_written,
                verified=self.phases.verified,
                consented=sending.consented, verify=self.verify)

    def _before_writing(self, runs: list[ModuleRun],
                        images: Mapping[Key, ModuleImage]) -> dict[str, dict[int, Known]]:
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
            # the snapshot on disk, if any, holds the modules of the lines written before
            except OSError as error:
                self.keeping.failed(SNAPSHOT, error, self._taken.path if self._taken is not None else None)
                return known
            # under the lock: the last snapshot record is the file's
            self.keeping.note("snapshot", path=self.snapshot.name, sha256=written)
            if self._whole:
                self._tell_snapshot(len(self._taken.images) if self._taken is not None else 0)
        self.keeping.note("apply", plant=self.plant.name, plant_sha256=self.plant.sha256,
                          snapshot=str(self.snapshot),
                          modules=[f"{r.bus}/{r.address}" for r in runs])
        return known

    def _snapshot_with(self, runs: list[ModuleRun], images: Mapping[Key, ModuleImage]) -> tuple[Path, str]:
        """The apply's one snapshot, with the runs' modules as read before writing, saved whole: its path and
        digest. A factory-fresh module's programs planned as the factory's (`ModuleRun.assumed`) hold the
        factory's there: not read, what a restore puts back — the undo of a commissioning."""
        if self._taken is None:
            taken_on = {name: LineTaken(bus.port, bus.framing, self.keys[name])
                        for name, bus in self.buses.items()}
            self._taken = Snapshot.take(self.plant.path, self.plant.sha256, {}, taken_on, self.journal.header)
        factory = what_to_read.from_factory
        self._taken.images.update({(r.bus, r.address): factory(images[(r.bus, r.address)], r.assumed)
                                   for r in runs})
        return self._taken.saved()

    def record(self, sending: Sending) -> None:
        """What the modules that verified hold, back into their lines' records: the read-back with the
        steps' effect, and what the record knew of the rest (`what_to_read.verified`)."""
        when, by = line_record.now(), line_record.who(self.command, self.plant.path)
        for bus, held in sending.known.items():
            done = {r.address: r for r in sending.runs if r.bus == bus and r.verified}
            try:
                self.records[bus].update({a: what_to_read.verified(held.get(a), _holds(run), when, by)
                                          for a, run in done.items()})
            # they stay unknown (forgotten before the writes): the next plan reads them in full
            except UserError as error:
                self.keeping.failed(LINE_RECORD, error)

    def account(self, the_plan: PlantPlan, took: dict[str, float] | None = None,
                unread: tuple[str, ...] = ()) -> Written:
        """What the writes came to, every module's outcome in the plan's order — recorded (E12 kept for the
        next plan, cleared once verified) and journalled, with the travel to the reference point and, when a
        signal stopped the lines, that it did."""
        order = {(c.bus, c.address): index for index, c in enumerate(the_plan.modules)}
        keys, keeping = self.keys, self.keeping
        stopped = None if keeping.trouble is None else "a record could not be kept"
        runs = tuple(run.outcome(stopped)
                     for run in sorted(self.runs, key=lambda run: order[(run.bus, run.address)]))
        for record in self.records.values():  # what a line left as it was read: kept here, where a failure is
            # the account's trouble (`RecordsFailed`, every run said), not an error after it that hides it
            try:
                record.write()
            except UserError as error:
                keeping.failed(LINE_RECORD, error)
        _keep_faults(keeping, keys, runs)
        for run in runs:
            keeping.note(
                "result", bus=run.bus, address=run.address, verified=run.verified, failure=run.failure,
                released_axes=run.released.value, written=[s.message.hex() for s in run.written],
                interrupted=run.interrupted,
            )
        if released := to_travel(runs):
            keeping.note("travel_to_reference_point", modules=[f"{r.bus}/{r.address}" for r in released])
        interrupted = (keeping.trouble is None and self.options.cancel is not None
                       and self.options.cancel.requested)
        if interrupted:
            keeping.note("interrupted")
        return Written(the_plan, runs, self.snapshot, (took or {}) | self.phases.took(), unread,
                       keeping.trouble, interrupted,
                       tuple(keeping.lost))


def _nothing() -> None:
    pass


def _holds(run: ModuleRun) -> ModuleImage:
    """What a verified module holds: its last read-back, and the device model's prediction where that read
    nothing."""
    final = run.final or run.predicted
    return replace(final, programs=tuple(f if f is not None else p
                                         for f, p in zip(final.programs, run.predicted.programs)))
