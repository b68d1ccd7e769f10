"""The apply engine: the writes of an apply, from the lines' threads, and what it keeps of them.

`apply_by_line` reads, plans and writes each line as soon as its own plan is whole; `Keeping` is the
journal and the records of axis releases (and E12), and stops every line when one cannot be kept;
`Writing` is the snapshot, the runs and the account. Does not own what is planned, nor the gates.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

from prc3cfg.api._bus import prober
from prc3cfg.api._plan import Reads, line_cost, planner_for, planning_each, seen, to_plan, unset_systems
from prc3cfg.api._types import ApplyFailed, ApplyInterrupted, ApplyResult, Gates, Key, LineOptions, Pairs, RecordsFailed
from prc3cfg.core import codec, targeting
from prc3cfg.core.framing import detects_damage
from prc3cfg.core.image import ModuleImage
from prc3cfg.core.plantplan import ModuleChange, PlantPlan
from prc3cfg.core.targeting import Known
from prc3cfg.errors import Interrupted, NotSent, UserError
from prc3cfg.plant import Bus, Plant
from prc3cfg.shell import bases, releases
from prc3cfg.shell.apply import ModuleRun, Verify, execute
from prc3cfg.shell.cancel import main_thread_only
from prc3cfg.shell.link import Exchange, Link
from prc3cfg.shell.phases import Phases
from prc3cfg.shell.platform import result_of
from prc3cfg.shell.readback import LinesFailed, read_all
from prc3cfg.shell.records import Journal, LineTaken, Snapshot


def apply_by_line(plant: Plant, chosen: Pairs, wanted: Reads, desired: dict[Key, ModuleImage] | None, gates: Gates,
                   writing: Writing, options: LineOptions, earlier: tuple[releases.Pending, ...],
                   records: releases.Releases) -> ApplyResult:  # fmt: skip
    """No question stands between the plan and the writes (`Gates.asks`): each module is planned as
    soon as it is read, and each line — its broadcasts decided once its last module is read — written
    as soon as its own plan is whole, while the other lines are still read and planned: no line
    waits for another. The plant's plan is shown once whole, the writes going on. A line whose
    read-back or plan fails is not written; the others are, and the result says both (`ApplyFailed`)."""
    pairs, links, buses = wanted.pairs, writing.links, writing.buses
    planner = planner_for(plant, pairs, unset_systems(plant, buses.values()), only_read=wanted.base is not None)
    want = to_plan(pairs, desired)
    lock = threading.Lock()
    images: dict[Key, ModuleImage] = {}
    planned: list[str] = []
    reading = {target.bus for target in wanted.targets}
    whole_at: float | None = None  # when the last line's plan was whole

    def the_plan() -> PlantPlan:
        with lock:
            read, done = dict(images), set(planned)
        return replace(planner.plan([w for w in want if w.bus in done], read), reading=wanted.reading(chosen, read))

    def show() -> None:
        """The plant's plan shown (once), beside the writes; the writing phase began when it became whole."""
        with lock:
            if not shown:
                shown.append(showing.submit(lambda: writing.whole(the_plan(), gates.show, whole_at)))

    def line(bus: str, read: dict[Key, ModuleImage]) -> None:
        nonlocal whole_at
        planner.plan_line(bus, want, read, prober(links[bus], buses[bus]))
        with lock:
            images.update(read)
            planned.append(bus)
            whole = len(planned) == len(reading)
            if whole:
                whole_at = time.monotonic()
        changes = planner.line_changes(bus)
        if gates.show_line is not None and any(c.steps for c in changes):  # what a line's writes follow is shown before them
            gates.show_line(planner.plan([w for w in want if w.bus == bus], read))
        # the plant's plan shown once the last line's first write is acknowledged: its rendering never holds that frame back
        writing.write(changes, read, True, started=show if whole else None)

    unread: tuple[str, ...] = ()
    shown: list[Future[None]] = []
    # from the first read to the end of the records, a signal waits its turn
    with options.deferred(), ThreadPoolExecutor(max_workers=1, initializer=main_thread_only) as showing:
        writing.phases.reading(len(wanted.targets))
        try:
            read_all(wanted.targets, links, progress=writing.phases.read, each=planning_each(planner, want), then=seen(plant, writing.command, line))
        except Interrupted:
            if not writing.runs:
                raise
            unread = tuple(f"bus {bus}: interrupted before its read-back and plan were whole — nothing was written on it"
                           for bus in sorted(reading - set(planned)))  # fmt: skip
        except LinesFailed as error:
            if not writing.runs:
                raise
            unread = tuple(f"{said} — nothing was written on bus {bus}" for bus, said in error.failed.items())
        if len(planned) == len(reading):
            show()  # not yet, when no write of the last line was acknowledged
        for future in shown:
            result_of(future)
        if options.cancel is not None and not writing.runs:
            options.cancel.check()
        planned_plan = the_plan()
        if not writing.runs:
            return ApplyResult(planned_plan, (), None, writing.journal.path, earlier, records)
        return writing.account(planned_plan, earlier, records, unread=unread)


class Keeping:
    """What an apply keeps as it writes — its journal and its records of axis releases (and E12) —
    and what becomes of it when the disk refuses one of them midway (full, read-only, over a
    quota, gone): the first failure is kept (`trouble`), every line stops before its next frame
    (`stop`, the links' cancel event), and the account that follows says what each module was
    sent. A record that belongs before a frame keeps that frame back (`announce` raises `NotSent`)."""

    def __init__(self, plant: Plant, buses: dict[str, Bus], keys: dict[str, tuple[str, ...]], journal: Journal,
                 records: releases.Releases, stop: threading.Event) -> None:  # fmt: skip
        self.journal, self.records, self._keys, self._stop = journal, records, keys, stop
        self._names = {(bus.name, m.address): m.name for bus, m in plant.modules()}
        self._buses = buses
        self._lock = threading.Lock()
        self.trouble: str | None = None

    def failed(self, what: str, error: OSError | UserError) -> None:
        """`what` could not be kept: the lines stop before their next frame."""
        said = f"{error.filename}: {error.strerror}" if isinstance(error, OSError) and error.filename else \
            (error.strerror if isinstance(error, OSError) and error.strerror else str(error))  # fmt: skip
        with self._lock:
            if self.trouble is None:
                self.trouble = f"could not keep {what} ({said})"
        self._stop.set()

    def announce(self, exchange: Exchange) -> None:
        """Before a frame leaves: the attempt journalled, and a 10h/20h recorded durably as an axis
        release not yet told (a broadcast's for every module on the line) — else it stays back."""
        try:
            self.journal.request(exchange)
        except OSError as error:
            self.failed(f"the journal {self.journal.path}", error)
            raise NotSent() from None
        if codec.MESSAGE_TYPES[exchange.request[0]].RELEASES_AXES:
            name = self._names.get((exchange.bus, exchange.address)) if exchange.address else \
                ", ".join(m.name for m in self._buses[exchange.bus].modules)  # fmt: skip
            self.record(self._keys[exchange.bus], exchange.bus, exchange.address, name or f"address {exchange.address}")
            if self.trouble is not None:
                raise NotSent()

    def observe(self, exchange: Exchange) -> None:
        """An exchange that happened, journalled (a failure stops the lines before their next frame)."""
        try:
            self.journal.exchange(exchange)
        except OSError as error:
            self.failed(f"the journal {self.journal.path}", error)

    def note(self, event: str, **fields: Any) -> None:
        """A record of the apply (not of an exchange) in the journal, once it can still be written."""
        if self.trouble is None:
            try:
                self.journal.record(event, **fields)
            except OSError as error:
                self.failed(f"the journal {self.journal.path}", error)

    def record(self, keys: tuple[str, ...], bus: str, address: int, name: str, kind: str = releases.RELEASE) -> None:
        """`releases.Releases.record`, a failure kept as the apply's trouble."""
        try:
            self.records.record(keys, bus, address, name, kind)
        except (OSError, UserError) as error:
            self.failed("the record of an axis release" if kind == releases.RELEASE else "the record of a module in E12", error)

    def close(self) -> None:
        with contextlib.suppress(OSError):  # already kept as the trouble, or the journal was whole
            self.journal.close()


class Writing:
    """An apply's writes, a line or the whole plan at a time, from any line's thread: the runs of
    the modules a plan changes, the snapshot of those modules saved before the first write on
    their line — added to the apply's one snapshot file, written whole and atomically each time —
    and journalled, then written and verified (`execute`); then the account of every run."""

    def __init__(self, plant: Plant, keys: dict[str, tuple[str, ...]], buses: dict[str, Bus], links: dict[str, Link], keeping: Keeping,
                 verify: Verify, options: LineOptions, command: str) -> None:  # fmt: skip
        self.plant, self.keys, self.buses, self.links, self.keeping = plant, keys, buses, links, keeping
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
        self._exposed = {name for name, bus in buses.items() if not detects_damage(bus.framing, bus.line.parity)}

    def _runs(self, changes: Iterable[ModuleChange]) -> list[ModuleRun]:
        return [ModuleRun(c.bus, c.address, c.name, c.actual, c.desired, c.steps, c.plan.predicted, c.broadcasts, c.bus in self._exposed)
                for c in changes if c.steps or c.bus in self._exposed]  # fmt: skip

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
        runs = self._runs(changes)
        if not runs:
            if started is not None:
                started()
            return
        # not known until verified: dropped from the lines' records before the first frame (what was known kept for then)
        known = {bus: bases.load(self.keys[bus]) for bus in {r.bus for r in runs}}
        with self._lock:
            self.runs.extend(runs)
            try:
                for bus in known:
                    bases.forget(self.keys[bus], [r.address for r in runs if r.bus == bus])
                if self._taken is None:
                    taken_on = {name: LineTaken(bus.port, bus.framing, self.keys[name]) for name, bus in self.buses.items()}
                    self._taken = Snapshot.take(self.plant.path, self.plant.sha256, {}, taken_on, self.journal.header)
                self._taken.images.update({(r.bus, r.address): images[(r.bus, r.address)] for r in runs})
                self.snapshot, written = self._taken.saved()
            except (OSError, UserError) as error:  # another line's writes began: this one's stay back
                self.keeping.failed("the snapshot and the line's record before writing", error)
            else:  # under the lock: the last snapshot record is the file's
                self.keeping.note("snapshot", path=self.snapshot.name, sha256=written)
            if self._whole:
                self._tell_snapshot(len(self._taken.images) if self._taken is not None else 0)
        self.keeping.note("apply", plant=self.plant.name, plant_sha256=self.plant.sha256, snapshot=str(self.snapshot),
                          modules=[f"{r.bus}/{r.address}" for r in runs])  # fmt: skip
        if self.keeping.trouble is not None:
            for run in runs:
                run.interrupted, run.failure = True, "nothing was sent to it"
            if started is not None:
                started()
            return
        consented = frozenset((c.bus, c.address) for c in changes if c.releases_axes) if allow_axis_release else frozenset()
        def wrote() -> None:
            self.phases.wrote()
            if started is not None:
                started()

        try:
            execute(runs, self.links, {name: line_cost(bus) for name, bus in self.buses.items()}, tick=wrote,
                    written=self.phases.line_written, verified=self.phases.verified, consented=consented, verify=self.verify)  # fmt: skip
        finally:
            self._verified(runs, known)

    def _verified(self, runs: list[ModuleRun], known: dict[str, dict[int, Known]]) -> None:
        """What the modules that verified hold, back into their lines' records: the read-back with the
        steps' effect, and what the record knew of the rest (`targeting.verified`)."""
        when, by = bases.now(), bases.who(self.command, self.plant.path)
        for bus, held in known.items():
            done = {r.address: r for r in runs if r.bus == bus and r.verified}
            try:
                bases.update(self.keys[bus], {a: targeting.verified(held.get(a), _holds(run), when, by) for a, run in done.items()})
            except UserError as error:  # they stay unknown: the next plan reads them in full
                self.options.tell(f"bus {bus}: {error} — the next plan reads its modules in full")

    def account(self, the_plan: PlantPlan, earlier: tuple[releases.Pending, ...], records: releases.Releases,
                took: dict[str, float] | None = None, unread: tuple[str, ...] = ()) -> ApplyResult:  # fmt: skip
        """The result, every run in the plan's order: recorded, journalled; `ApplyInterrupted` or
        `ApplyFailed` unless every module verified."""
        order = {(c.bus, c.address): index for index, c in enumerate(the_plan.modules)}
        runs = tuple(sorted(self.runs, key=lambda run: order[(run.bus, run.address)]))
        result = ApplyResult(the_plan, runs, self.snapshot, self.journal.path, earlier, records, (took or {}) | self.phases.took(), unread)
        keys, keeping = self.keys, self.keeping
        for run in runs:  # E12: kept for the next plan, which writes the system parameters first; cleared once verified
            if run.system_unset:
                keeping.record(keys[run.bus], run.bus, run.address, run.name, releases.E12)
        releases.cleared(r for r in releases.pending((k for ks in keys.values() for k in ks), releases.E12)
                         if any(run.verified and (run.bus, run.address) == (r.bus, r.address) for run in runs))
        for run in runs:
            keeping.note(
                "result", bus=run.bus, address=run.address, verified=run.verified, failure=run.failure,
                released_axes=run.released.value, written=[s.message.hex() for s in run.written],
                interrupted=run.interrupted,
            )  # fmt: skip
        if result.released:
            keeping.note("travel_to_reference_point", modules=[f"{r.bus}/{r.address}" for r in result.released])
        if keeping.trouble is not None:
            raise RecordsFailed(result, keeping.trouble)
        if self.options.cancel is not None and self.options.cancel.requested:
            keeping.note("interrupted")
            raise ApplyInterrupted(result)
        if not result.verified:
            raise ApplyFailed(result)
        return result


def _holds(run: ModuleRun) -> ModuleImage:
    """What a verified module holds: its last read-back, and the device model's prediction where that read nothing."""
    final = run.final or run.predicted
    return replace(final, programs=tuple(f if f is not None else p for f, p in zip(final.programs, run.predicted.programs)))
