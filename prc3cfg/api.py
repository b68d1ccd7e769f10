"""The Python API: everything the command line does, as functions of plain values.

    from prc3cfg import api

    plant = api.load("plant.yaml")
    plan = api.plan(plant)                          # reads every module back
    for change in plan.changes:
        print(change.bus, change.name, len(change.steps), "steps")
    result = api.apply(plant, gates=api.Gates(allow_axis_release=True))
    assert result.verified and not api.plan(plant).changes
    print("travel to reference point:", [run.name for run in result.released])

(a test runs this example, and the README's, against emulated buses.)

Each function returns values — a `Plant`, module images, a `PlantPlan`, an `ApplyResult` —
and raises a `UserError` subclass whose `str()` is one line saying what is wrong and what to
do: `PlantError`, `LinkError`, `LineBusy`, `StalePlan`, `AxisReleaseRefused`, `NotApproved`,
`ApplyFailed` and `ApplyInterrupted` (both carry the `ApplyResult`, for the account).
Every function that talks on a line takes `LineOptions`: retries, the lock time-out, a frame
trace, a cancel event (Ctrl-C, `prc3cfg.shell.cancel`) and a `Progress` to report to.

Owns the workflows: which modules, what to read, locking the lines, reading back, planning
each line as it is read (and probing it before broadcasts), proving a plan file, gating, the
snapshot and the journal, running and verifying, restoring, drift, adopting Teach In into the
plant file, scanning, importing, a gateway's INIT block, the pictures of a module's motion and
serving an emulated bus. Does not own what they are made of (the pure core, `prc3cfg.core` —
the planner and its cache, `prc3cfg.core.planning`; plant files, `prc3cfg.plant`; the shell:
links, locks, records, apply, files, the emulator, `prc3cfg.shell`), nor arguments, prompts
and output (`prc3cfg.cli`). `__all__` is what the CLI and users' scripts call.
"""

from __future__ import annotations

import contextlib
import hashlib
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from decimal import Decimal
from pathlib import Path
from typing import Any, Protocol, TextIO
from urllib.parse import urlsplit

from prc3cfg.core import bustime, codec, gateway, planfile, plot, render, what_to_read
from prc3cfg.core.axes import Release
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.device import can_clamp
from prc3cfg.core.framing import detects_damage, get_framing
from prc3cfg.core.image import MAX_MODULE_ADDRESS, PROGRAM_NUMBERS, ModuleImage, images_from_json
from prc3cfg.core.line import EMULATOR_SCHEME, LineSettings
from prc3cfg.core.planfile import PlanFile, StalePlan
from prc3cfg.core.planning import PROBE_TIMEOUT, PROOF_PROBES, Line, Planner, Prober, Wanted
from prc3cfg.core.plantplan import ModuleChange, PlantPlan, Reading
from prc3cfg.core.render import Drift, drifted, plural
from prc3cfg.core.what_to_read import Known, Target
from prc3cfg.errors import Interrupted, NotSent, UserError
from prc3cfg.plant import Bus, Module, Plant, PlantError
from prc3cfg.plant.adopt import Adopted
from prc3cfg.plant.adopt import adopt as adopt_text
from prc3cfg.plant.importer import bus_entry, imported_plant
from prc3cfg.plant.messages import port_error
from prc3cfg.shell import audit, bases, releases
from prc3cfg.shell.apply import ModuleRun, Verify, execute
from prc3cfg.shell.audit import Pruned, RecordedRun, Verified
from prc3cfg.shell.cancel import Cancellation, main_thread_only
from prc3cfg.shell.doctor import Diagnosis, LineCandidate, Search, diagnose
from prc3cfg.shell.emulator import Emulator, FaultInjection, modules_to_serve, ptys
from prc3cfg.shell.emulator.server import IDLE_TIMEOUT, MAX_CONNECTIONS
from prc3cfg.shell.files import FileProblem, Why, read_json, replace_unless_changed
from prc3cfg.shell.link import Exchange, Link, LinkError, NoReadMessages, PortFailed, PossibleWrite, Trace, open_plant_links, open_port
from prc3cfg.shell.link.client import Port
from prc3cfg.shell.link.ports import FormatRefused, emulator_state_path, is_pseudo_terminal
from prc3cfg.shell.link.ports import SerialPort as SerialPort
from prc3cfg.shell.link.ports import serial_ports as serial_ports
from prc3cfg.shell.locks import LineBusy, line_keys, line_lock
from prc3cfg.shell.phases import Phases
from prc3cfg.shell.plant_files import load_plant
from prc3cfg.shell.platform import HAS_PTY, python_command, result_of
from prc3cfg.shell.platform import device_number as device_number
from prc3cfg.shell.platform import terminal_path as terminal_path
from prc3cfg.shell.platform import wait_for as wait_for
from prc3cfg.shell.readback import LinesFailed, read_all, read_module
from prc3cfg.shell.records import Journal, LineTaken, Snapshot, applied_copy, check_writable, reason_given, save_applied
from prc3cfg.shell.records import header as run_header

#: What the CLI, the pytest plugin and users' scripts call (a test keeps the CLI to these).
__all__ = [
    "Adoption", "ApplyFailed", "ApplyInterrupted", "ApplyResult", "AxisReleaseRefused", "BareLine", "Diagnosis", "Drift", "FormatRefused", "Gates",
    "LineBusy", "LineOptions", "LinkError", "NotApproved", "PlantError", "Progress", "Pruned", "RecordedRun", "Release", "Search", "SerialPort",
    "StalePlan", "UserError", "Verified", "Verify", "adopt", "apply", "default_parity", "device_number", "doctor", "drift", "emulator",
    "import_modules", "import_plant", "init_data_block", "left_alone", "list_records", "listen", "load", "load_images", "measurable", "open_pty",
    "picture", "plan", "plan_document", "plan_file_plant", "plot_format", "prune_records", "read", "restore", "scan", "select", "serial_ports",
    "served_pty", "setup_machine", "slower_than_priced", "terminal_path", "unshared_records", "verify_records", "wait_for",
    "write_adoption",
]  # fmt: skip

Key = tuple[str, int]  # (bus name, module address)
Pairs = list[tuple[Bus, Module]]
#: Called with each exchange on a line: before its frame leaves (`announce`), or once it is done.
Observer = Callable[[Exchange], None]


class AxisReleaseRefused(UserError):
    """The plan releases axes and `allow_axis_release` was not given: nothing was written."""


class NotApproved(UserError):
    """`approve` said no: nothing was written."""


class ApplyFailed(UserError):
    """Some module did not verify; `result` has the account of every module."""

    def __init__(self, result: ApplyResult) -> None:
        failed = [r for r in result.runs if not r.verified]
        said = [*result.unread]  # lines not written: what stopped their read-back or plan, one line each
        if failed or not said:
            said.append(f"apply failed on {len(failed)} of {plural(len(result.runs), 'module')} (see above) — restore with: "
                        f"prc3cfg restore {result.snapshot}")  # fmt: skip
        else:
            written = len(result.runs)
            said[-1] += (f"; the {plural(written, 'module')} of the other lines {'was' if written == 1 else 'were'} written and "
                         f"verified (see above) — restore {'it' if written == 1 else 'them'} with: prc3cfg restore {result.snapshot}")  # fmt: skip
        super().__init__("\n".join(said))
        self.result = result


class RecordsFailed(ApplyFailed):
    """A record the apply keeps as it writes — its journal, the record of an axis release, its
    snapshot — could not be written midway (a full disk): every line stopped before its next frame;
    `result` says what each module was sent."""

    def __init__(self, result: ApplyResult, trouble: str) -> None:
        super().__init__(result)
        then = "plan and apply again" + (f", or restore: prc3cfg restore {result.snapshot}" if result.snapshot else "")
        self.args = (f"{trouble}: every line stopped before its next frame — the account above says what each module "
                     f"was sent; free the space (or fix the folder), then {then}",)  # fmt: skip


class ApplyInterrupted(Interrupted):
    """Ctrl-C or SIGTERM stopped the apply after the exchange in flight; `result` has the account."""

    def __init__(self, result: ApplyResult) -> None:
        super().__init__()
        self.result = result


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


@dataclass
class LineOptions:
    """How to use the lines: retries per message, seconds to wait for another prc3cfg's lock, a
    frame trace, Ctrl-C handling (`prc3cfg.shell.cancel.Cancellation`) and progress reports."""

    retries: int = 5
    lock_timeout: float = 0.0
    trace: TextIO | None = None
    cancel: Cancellation | None = None
    progress: Progress = field(default_factory=Quiet)
    #: called with the text when a line is busy and a wait for its lock begins
    waiting: Callable[[str], None] | None = None
    #: after a command that succeeded: the links used, with their `repeated` exchanges
    links_used: list[Link] = field(default_factory=list)
    #: called with each warning a command has for the operator (an axis release nobody was told
    #: of, `prc3cfg.shell.releases`); every one is also kept in `notices`
    notice: Callable[[str], None] | None = None
    notices: list[str] = field(default_factory=list)
    #: the command line a run's records name (their header): the program's, `sys.argv`, unless told
    command_line: tuple[str, ...] | None = None

    def tell(self, text: str) -> None:
        self.notices.append(text)
        if self.notice is not None:
            self.notice(text)

    def deferred(self) -> contextlib.AbstractContextManager[None]:
        """A phase a signal must not cut (`Cancellation.deferred`), when there is a cancellation."""
        return self.cancel.deferred() if self.cancel is not None else contextlib.nullcontext()


@dataclass(frozen=True)
class ApplyResult:
    """What an apply did: the plan it ran, every module's run, the snapshot and journal it left."""

    plan: PlantPlan
    runs: tuple[ModuleRun, ...]
    snapshot: Path | None
    journal: Path
    #: axis releases earlier applies on these lines left untold (killed after a 10h/20h): this
    #: apply's account lists them too
    earlier: tuple[releases.Pending, ...] = ()
    records: releases.Releases | None = None
    #: seconds each phase took — reading back (and planning), writing, verifying — beside the plan's estimate
    took: dict[str, float] = field(default_factory=dict)
    #: lines written as soon as their own plan was whole, while another's read-back or plan failed (or
    #: Ctrl-C stopped it): what stopped that one, one line each, saying nothing was written there
    unread: tuple[str, ...] = ()

    def told(self) -> None:
        """The account — `released` and `earlier` — has been shown to the operator: the records of
        those releases, kept on disk since before their frames left, can go (`prc3cfg.shell.releases`).
        Until this is called, every command on these lines warns of them."""
        if self.records is not None:
            self.records.told(self.earlier)

    @property
    def verified(self) -> bool:
        return not self.unread and all(run.verified for run in self.runs)

    @property
    def released(self) -> tuple[ModuleRun, ...]:
        """Every module whose axes were — or may have been — released: it must travel to its reference point."""
        return tuple(run for run in self.runs if run.released is not Release.NO)


# -- the plant and its modules ----------------------------------------------------------


def load(path: str | Path) -> Plant:
    """The plant file at `path`; `PlantError` with every problem, one line each."""
    return load_plant(path)


def select(plant: Plant, names: Iterable[str] | None = None) -> Pairs:
    """(bus, module) pairs of the plant, limited to the named modules; unknown names are an error."""
    pairs = list(plant.modules())
    if not names:
        return pairs
    wanted = set(names)
    unknown = wanted - {module.name for _, module in pairs}
    if unknown:
        raise UserError(
            f"{plant.path}: no module named {', '.join(sorted(unknown))} — the plant's modules are "
            + ", ".join(module.name for _, module in pairs)
        )
    return [(bus, module) for bus, module in pairs if module.name in wanted]


def line_cost(bus: Bus) -> LineCost:
    return LineCost.of(bus.framing, bus.line, bus.turnaround, bus.zvz)


def targets(pairs: Pairs) -> list[Target]:
    """What to read of each module: its managed programs, and every program its plant system
    parameters could clamp."""
    return what_to_read.in_full(_wanted(pairs, None))


#: What a targeted read-back compares with, in words (`prc3cfg.shell.bases`).
RECORD = "the line's record of what prc3cfg last read or verified"


def record(plant: Plant, buses: Iterable[Bus]) -> dict[Key, Known]:
    """What the records of these buses' lines say their modules hold, by (bus, address)."""
    return {(bus.name, address): known for bus in buses for address, known in bases.load(bus_line_keys(plant, bus)).items()}


def setup_machine(group: str | None = None) -> tuple[Path, str | None]:
    """Make (or put right) the machine's folder of axis-release records and line records that every user
    of its lines shares — run once by an administrator; the folder and the serial ports' group it gave it."""
    return releases.setup_machine(group)


def unshared_records() -> str | None:
    """The one-line hint for a user whose records no other user of the machine sees (None: they do)."""
    return releases.unshared()


@dataclass(frozen=True)
class Reads:
    """What a plan reads: the modules (of those chosen) and their targets, and for a targeted
    read-back the record it was compared with, in words (None: every chosen module in full), the
    modules read in full with why ("bus/name (why)": as a plan file says, else worked out from the
    targets and the read-back) and whose verification the programs not read rest on."""

    pairs: Pairs
    targets: list[Target]
    base: str | None = None
    not_as_verified: tuple[str, ...] | None = None
    why: dict[Key, str] = field(default_factory=dict)  # read in full before any evidence: not on record, too old, E12
    taken: dict[str, str] | None = None  # "bus/name" → `Known.said()`: as a plan file says, else from `known`
    known: dict[Key, Known] = field(default_factory=dict)

    def reading(self, chosen: Pairs, images: dict[Key, ModuleImage]) -> Reading | None:
        """What the plan says it read now and took as known, once `images` are read."""
        if self.base is None:
            return None
        unread = tuple(f"{bus.name}/{m.name}" for bus, m in chosen if (bus.name, m.address) not in images)
        skipped = {key: what_to_read.not_read(m.desired_image(), images[key]) for bus, m in chosen if (key := (bus.name, m.address)) in images}
        other = self.not_as_verified
        if other is None:
            other = what_to_read.read_in_full(_wanted(chosen, None), self.targets, images, self.why)
        taken = self.taken
        if taken is None:
            taken = {f"{bus.name}/{m.name}": self.known[key].said() for bus, m in chosen if skipped.get(key := (bus.name, m.address))}
        return Reading(self.base, unread, skipped, other, taken)


def reads(plant: Plant, pairs: Pairs, full_read: bool = False) -> Reads:
    """What to read of the chosen modules: everything (`targets`) with `full_read` or when the lines'
    records know none of them; else of each module its system block and the managed programs the
    record does not show holding the plant file's values (`what_to_read.for_plan`) — every managed
    program of one the record does not know, knows from too long ago, or that reported E12 since."""
    buses = {bus.name: bus for bus, _ in pairs}
    known: dict[Key, Known] = {}
    overruled: dict[Key, str] = {}
    for bus in [] if full_read else buses.values():
        on_record, newer = bases.read(bus_line_keys(plant, bus))
        known |= {(bus.name, address): k for address, k in on_record.items()}
        overruled |= {(bus.name, address): said for address, said in newer.items()}
    unset = unset_systems(plant, buses.values()) if known or overruled else frozenset()  # of no use without a record
    max_age = {name: bus.record_max_age for name, bus in buses.items()}
    targeted = what_to_read.for_plan(_wanted(pairs, None), known, overruled, unset, max_age, datetime.now(UTC))
    if targeted is None:
        return Reads(pairs, targets(pairs))
    to_read, why = targeted
    return Reads(pairs, to_read, RECORD, why=why, known=known)


# -- the lines --------------------------------------------------------------------------


def slower_than_priced(links: Iterable[Link]) -> list[Link]:
    """The links whose answered exchanges took clearly longer than their line settings price them
    (`prc3cfg.core.bustime.slower_than_priced`): the plant file's line settings are off."""
    return [link for link in links if link.cost is not None and link.answered and bustime.slower_than_priced(link.answered_time, link.priced_time)]


def measurable(port: str) -> bool:
    """Whether `prc3cfg doctor` can measure the line at `port` (an `emulator://` port it cannot: its URL says how it answers)."""
    return not port.startswith(EMULATOR_SCHEME)


def bus_line_keys(plant: Plant, bus: Bus) -> tuple[str, ...]:
    """The identities of a bus's line: its port, or for `emulator://` the emulator's state file."""
    state = emulator_state_path(plant.path, bus.port) if bus.port.startswith(EMULATOR_SCHEME) else None
    return line_keys(bus.port, emulator_state=state)


class _Records(Protocol):
    """Where an axis release is recorded: `releases.Releases`, or an apply's `_Keeping` of it."""

    def record(self, keys: tuple[str, ...], bus: str, address: int, name: str, kind: str = ...) -> None: ...


@contextlib.contextmanager
def lines(plant: Plant, buses: Iterable[str], options: LineOptions, *, purpose: str = "read", observer: Observer | None = None,
          announce: Observer | None = None, records: _Records | None = None) -> Iterator[dict[str, Link]]:  # fmt: skip
    """A `Link` per named bus, each line locked first: only one prc3cfg talks on a line at a time.
    Every axis release on these lines that no account has named yet is told (`LineOptions.tell`),
    and a read a module answers as a write is recorded as one in `records` (`PossibleWrite`).

    Two buses that are one line (two spellings of one address) are refused: they would wait
    for each other's lock."""
    names = set(buses)
    keys = {bus.name: bus_line_keys(plant, bus) for bus in plant.buses if bus.name in names}
    owner: dict[str, str] = {}
    for name, identities in keys.items():
        for key in identities:
            if key in owner:
                raise UserError(f"{plant.path}: buses {owner[key]} and {name} are one line ({key}) — "
                                "describe each line once, as one bus")  # fmt: skip
            owner[key] = name
    with contextlib.ExitStack() as stack:
        for bus in plant.buses:
            if bus.name in names:
                stack.enter_context(line_lock(keys[bus.name], f"bus {bus.name} ({bus.port})", port=bus.port, timeout=options.lock_timeout,
                                              purpose=purpose, waiting=options.waiting))  # fmt: skip
        if _sha256_of(plant.path) != plant.sha256:  # edited (or adopted into) while this waited for the line
            raise UserError(f"{plant.path}: the plant file changed while this command waited for the line — nothing was "
                            "read or written: run it again, with the file as it is now")  # fmt: skip
        for record in releases.pending(owner):
            options.tell(record.said())
        trace = Trace(options.trace) if options.trace is not None else None
        cancel = options.cancel.event if options.cancel is not None else None
        module_names = {(bus.name, m.address): m.name for bus, m in plant.modules()}
        watch = _written_reads(module_names, keys, records or releases.Releases(purpose), observer)
        links = stack.enter_context(open_plant_links(plant, names, trace=trace, retries=options.retries, observer=watch,
                                                     announce=announce, cancel=cancel))  # fmt: skip
        yield links
        options.links_used.extend(links.values())


def _sha256_of(path: Path) -> str | None:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def _written_reads(names: dict[Key, str], keys: dict[str, tuple[str, ...]], records: _Records,
                   observer: Callable[[Exchange], None] | None = None) -> Callable[[Exchange], None]:  # fmt: skip
    """`observer`, and a read answered with an acknowledgement recorded as an axis release: the
    module executed a damaged frame as a write, a 10h as likely as any (`PossibleWrite`)."""

    def watch(exchange: Exchange) -> None:
        if observer is not None:
            observer(exchange)
        if exchange.reply == codec.encode_code(0) and codec.MESSAGE_TYPES[exchange.request[0]].IS_READ:
            name = names.get((exchange.bus, exchange.address), f"address {exchange.address}")
            records.record(keys[exchange.bus], exchange.bus, exchange.address, name)

    return watch


#: Called with a bus and its modules' images as soon as the bus is read.
LineRead = Callable[[str, dict[Key, ModuleImage]], None]


def seen(plant: Plant, command: str, then: LineRead | None = None) -> LineRead:
    """Each line's read-back, as soon as it is read, into the line's record (`prc3cfg.shell.bases`):
    what `command` saw — drift included, so the next plan writes it back — then `then`."""
    by, buses = bases.who(command, plant.path), {bus.name: bus for bus in plant.buses}

    def record_and_then(bus: str, images: dict[Key, ModuleImage]) -> None:
        keys = bus_line_keys(plant, buses[bus])
        known, when = bases.load(keys), bases.now()
        bases.update(keys, {a: what_to_read.merged(known.get(a), image, when, by) for (b, a), image in images.items() if b == bus})
        if then is not None:
            then(bus, images)

    return record_and_then


def _read(targets_: list[Target], links: dict[str, Link], options: LineOptions, each: Callable[[Target, ModuleImage], None] | None = None,
          then: LineRead | None = None) -> dict[Key, ModuleImage]:  # fmt: skip
    """Every target read back; a Ctrl-C stops after the exchange in flight (`Interrupted`) — also
    one that came during the last exchanges, when the read ended anyway: it is not forgotten. Each
    line's read goes into its record by `then` (`seen`)."""
    options.progress.start("reading modules", len(targets_))
    with options.deferred():
        images = read_all(targets_, links, progress=options.progress.advance, each=each, then=then)
    if options.cancel is not None:
        options.cancel.check()
    return images


def _read_and_plan(plant: Plant, pairs: Pairs, to_read: list[Target], links: dict[str, Link], options: LineOptions,
                   desired: dict[Key, ModuleImage] | None = None, *, command: str,
                   only_read: bool = False) -> tuple[dict[Key, ModuleImage], PlantPlan]:  # fmt: skip
    """Read back and plan, each module planned as soon as it is read and each line as soon as its
    last module is — while the other lines are still being read: the lines never wait for all of
    the planning. `only_read`: see `Planner`."""
    buses = {bus.name: bus for bus, _ in pairs}
    planner = _planner(plant, pairs, unset_systems(plant, buses.values()), only_read=only_read)
    wanted = _wanted(pairs, desired)
    images = _read(to_read, links, options, each=_planning_each(planner, wanted),
                   then=seen(plant, command, lambda bus, read: planner.plan_line(bus, wanted, read, prober(links[bus], buses[bus]))))  # fmt: skip
    return images, planner.plan(wanted, images)


def _planning_each(planner: Planner, wanted: list[Wanted]) -> Callable[[Target, ModuleImage], None]:
    """Each module planned as soon as it is read (`Planner.plan_module`)."""
    by_key = {w.key: w for w in wanted}
    return lambda target, image: planner.plan_module(by_key[(target.bus, target.address)], image)


def read(plant: Plant, modules: Iterable[str] | None = None, options: LineOptions | None = None, *,
         command: str = "read") -> dict[Key, ModuleImage]:  # fmt: skip
    """Read back the chosen modules: system parameters, managed programs, and every program the
    plant's system parameters could clamp — by (bus, address); what was read goes into the lines'
    records as `command`'s."""
    options = options or LineOptions()
    pairs = select(plant, modules)
    with lines(plant, {bus.name for bus, _ in pairs}, options) as links:
        return _read(targets(pairs), links, options, then=seen(plant, command))


def load_images(path: Path, plant: Plant, modules: Iterable[str] | None = None) -> dict[Key, ModuleImage]:
    """Module images saved by `prc3cfg read --json`, matched to the plant's modules by bus and address."""
    remedy = "save the images again with prc3cfg read --json"
    entries = read_input(path, "the file prc3cfg read --json wrote", remedy)
    try:
        saved = [(entry.get("bus"), image) for entry, image in zip(entries, images_from_json(entries))]
    except ValueError as error:
        raise UserError(f"{path}: not a list of module images as `prc3cfg read --json` writes ({error}) — {remedy}") from None
    images: dict[Key, ModuleImage] = {}
    for bus, module in select(plant, modules):
        found = [img for b, img in saved if img.address == module.address and b in (None, bus.name)]
        if len(found) != 1:
            raise UserError(
                f"{path}: {'no' if not found else 'more than one'} image for bus {bus.name}, module "
                f"{module.address} ({module.name}) — {remedy}"
            )
        missing = [n for n in module.managed_programs() if found[0].programs[n - 1] is None]
        if missing:
            raise UserError(f"{path}: the image of bus {bus.name}, module {module.address} lacks program {missing[0]}, "
                            f"which the plant manages — {remedy}")  # fmt: skip
        unread = [n for n, p in enumerate(found[0].programs, start=1) if p is None]
        if unread and can_clamp(found[0].system, module.desired_system()):
            raise UserError(f"{path}: the image of bus {bus.name}, module {module.address} lacks program {unread[0]}, "
                            f"which the plant's system parameters would clamp — {remedy}")  # fmt: skip
        images[(bus.name, module.address)] = found[0]
    return images


def read_input(path: Path, what: str, remedy: str) -> Any:
    """A JSON file prc3cfg wrote (`what`: "the plan file …"), within `files.JSON_LIMIT`; one line otherwise."""
    try:
        return read_json(path)
    except FileProblem as problem:
        raise UserError(f"{problem.where(path)}: {problem} — {remedy if problem.why is Why.NOT_JSON else f'name {what}'}") from None


# -- planning ---------------------------------------------------------------------------


def plan(plant: Plant, modules: Iterable[str] | None = None, *, images: dict[Key, ModuleImage] | None = None,
         options: LineOptions | None = None, previous: Path | None = None, full_read: bool = False) -> PlantPlan:  # fmt: skip
    """The cheapest plan from what the modules hold (read back now, or `images` as `read` or
    `load_images` gave them) to the plant file. Read back now: only what the change from a base
    touches (`previous`, else the plant file last applied in full here: `base`, `reads`) — every
    chosen module in full without a base, or with `full_read`."""
    options = options or LineOptions()
    pairs = select(plant, modules)
    if images is not None:
        return make_plan(plant, pairs, images)
    wanted = reads(plant, pairs, full_read)
    with lines(plant, {bus.name for bus, _ in wanted.pairs}, options, purpose="plan") as links:
        read_, planned = _read_and_plan(plant, wanted.pairs, wanted.targets, links, options, command="plan",
                                        only_read=wanted.base is not None)  # fmt: skip
    return replace(planned, reading=wanted.reading(pairs, read_))


def make_plan(plant: Plant, pairs: Pairs, actual: dict[Key, ModuleImage], desired: dict[Key, ModuleImage] | None = None,
              probers: dict[str, Prober] | None = None, unset: frozenset[Key] = frozenset(), *, only_read: bool = False) -> PlantPlan:  # fmt: skip
    """Plan every chosen module from its read-back to its desired image (the plant file's by default),
    then broadcast what the modules of a line share, where every receiver is known — proven by the
    line's `probers` (`Planner.plan_line`). `only_read`: see `Planner`."""
    return _planner(plant, pairs, unset, only_read=only_read).plan(_wanted(pairs, desired), actual, probers)


def _planner(plant: Plant, pairs: Pairs, unset: frozenset[Key], *, only_read: bool = False) -> Planner:
    """A `Planner` of the lines of these modules' buses."""
    buses = {bus.name: bus for bus, _ in pairs}
    return Planner(plant.name, str(plant.path.resolve()), plant.sha256, {name: _line(bus) for name, bus in buses.items()}, unset,
                   only_read=only_read)  # fmt: skip


def _line(bus: Bus) -> Line:
    """A bus as the planning sees its line: complete when the plant lists all 30 addresses, or says
    it lists every module there (`only_these_modules: true`)."""
    listed = frozenset(m.address for m in bus.modules)
    complete = len(listed) == MAX_MODULE_ADDRESS or bus.only_these_modules
    return Line(bus.name, line_cost(bus), listed, complete, probe_timeout(bus))


def _wanted(pairs: Pairs, desired: dict[Key, ModuleImage] | None) -> list[Wanted]:
    """The modules to plan, each with its desired image: of `desired`, else the plant file's."""
    return [Wanted(bus.name, m.address, m.name, desired[(bus.name, m.address)] if desired is not None else m.desired_image())
            for bus, m in pairs]  # fmt: skip


def unset_systems(plant: Plant, buses: Iterable[Bus]) -> frozenset[Key]:
    """The modules of these buses that reported E12 to an earlier apply and were not cleared since."""
    return frozenset((r.bus, r.address) for bus in buses for r in releases.pending(bus_line_keys(plant, bus), releases.E12))




def probe_timeout(bus: Bus) -> float:
    """How long a probe waits at an address: the line's time-out, at most `PROBE_TIMEOUT`."""
    return min(bus.timeout, PROBE_TIMEOUT)


def prober(link: Link, bus: Bus) -> Prober:
    """The addresses among those given where something answers a 50h (`PROOF_PROBES` tries each)."""

    def probe(addresses: list[int]) -> list[int]:
        found = []
        for address in addresses:
            for _ in range(PROOF_PROBES):
                try:
                    heard = link.probe(address, codec.ReadSystem(), probe_timeout(bus)) is not None
                except (PortFailed, PossibleWrite, NoReadMessages):
                    raise
                except LinkError:
                    heard = True  # something answered, if garbled: not an empty address
                if heard:
                    found.append(address)
                    break
        return found

    return probe


def read_plan(path: Path, plant: Plant) -> PlanFile:
    """A plan file, refused (one line) when damaged, made by another prc3cfg or for another plant file."""
    try:
        alike = planfile.same_text(plant.path.read_bytes())
    except OSError:  # gone since it was loaded: the plant file's own digest alone, which the lines' check then finds changed
        alike = frozenset()
    return planfile.to_apply(read_input(path, "the plan file prc3cfg plan --out wrote", "make the plan again"), path, plant.path, plant.sha256, alike)


def plan_document(path: Path) -> dict[str, Any]:
    """A plan file to show (`prc3cfg show PLAN.json`), checked, its summaries worked out again from its bytes."""
    return planfile.to_show(read_input(path, "a plan file prc3cfg plan --out wrote", "make the plan again"), path)


def plan_file_plant(path: Path) -> Path:
    """The plant file a plan file was made from, where it says it is."""
    document = read_input(path, "the plan file prc3cfg plan --out wrote", "make the plan again")
    recorded = document.get("plant_path") if isinstance(document, dict) else None
    if not isinstance(recorded, str) or not Path(recorded).is_file():
        raise UserError(f"{path}: the plant file it was made from is not at {recorded!r} — name it: "
                        f"prc3cfg apply PLANT --plan {path}")  # fmt: skip
    return Path(recorded)


def prove(path: Path, planned: PlanFile, plant: Plant, pairs: Pairs, images: dict[Key, ModuleImage],
          probers: dict[str, Prober] | None = None) -> PlantPlan:  # fmt: skip
    """The plan file's plan, proved before anything is written (`prc3cfg.core.planfile`): what is
    applied is then the plan prc3cfg makes from this read-back."""
    modules = {(bus.name, m.address): (bus, m) for bus, m in pairs}
    planfile.check_modules(path, planned, {key: m.name for key, (_, m) in modules.items()}, images)
    chosen = [modules[(entry.bus, entry.address)] for entry in planned.modules]
    said = planned.document.get("read")  # a targeted read-back's base, in words: it sends nothing
    targeted = Reads(chosen, [], said["base"], tuple(said["not_as_verified"]), taken=dict(said.get("taken", {}))) if isinstance(said, dict) else None
    ours = make_plan(plant, chosen, images, probers=probers, unset=unset_systems(plant, {bus.name: bus for bus, _ in chosen}.values()),
                     only_read=targeted is not None)  # fmt: skip
    if targeted is not None:
        ours = replace(ours, reading=targeted.reading(pairs, images))
    planfile.check_plan(path, planned, ours, {bus.name: line_cost(bus) for bus, _ in chosen}, lambda: left_alone(plant), render)
    return ours


# -- applying ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Gates:
    """What an apply asks before it writes, in this order, each seeing the plan:

    - `show(plan)`: the plan is ready (to print it);
    - `allow_axis_release`: True, False, or a question — called with the modules whose axes
      the plan releases, True to allow — else `AxisReleaseRefused`; the answer also decides
      whether a repair may release axes;
    - `approve(plan)`: False stops with `NotApproved`.

    Without a question (`asks`) each line is written as soon as its own plan is whole, while the
    other lines are still read — `show_line` sees that line's plan before its first write — and
    `show` sees the plant's plan once it is whole, writes going on.
    """

    show: Callable[[PlantPlan], None] | None = None
    allow_axis_release: bool | Callable[[list[str]], bool] = False
    approve: Callable[[PlantPlan], bool] | None = None
    #: without a question: each line's own plan, before that line's first write (from its thread)
    show_line: Callable[[PlantPlan], None] | None = None

    @property
    def asks(self) -> bool:
        """Whether a question may stand between the plan and the writes — a confirmation, or an axis
        release not allowed up front — so that a person reviews the plan of the whole plant first."""
        return self.approve is not None or self.allow_axis_release is not True


def apply(
    plant: Plant,
    modules: Iterable[str] | None = None,
    *,
    plan_file: Path | None = None,
    gates: Gates = Gates(),
    verify: Verify = Verify.FLOOR,
    options: LineOptions | None = None,
    previous: Path | None = None,
    full_read: bool = False,
    reason: str | None = None,
) -> ApplyResult:
    """Lock, read back, plan (or prove `plan_file`), pass the `gates`, snapshot, write, verify.

    What is read back is what `plan` reads (`previous`, `full_read`); for `plan_file`, exactly
    what its plan read. `reason` (else `PRC3CFG_REASON`) goes into the records' header — a bus
    with `require_reason` refuses to start without one. Returns the result when every module
    verified; raises `ApplyFailed` or `ApplyInterrupted`, each with the result, otherwise; before
    anything is written, any other `UserError`.
    """
    planned = None if plan_file is None else (plan_file, read_plan(plan_file, plant))  # before any time on the line
    pairs = select(plant, modules)
    wanted = _plan_file_reads(plant, *planned, pairs) if planned is not None else reads(plant, pairs, full_read)
    return _apply(plant, pairs, wanted, None, planned, gates, verify, options or LineOptions(), reason=reason)


def _plan_file_reads(plant: Plant, path: Path, planned: PlanFile, pairs: Pairs) -> Reads:
    """What to read for a plan file: every chosen module in full, or — for a plan made from a
    targeted read-back — exactly the modules and programs its plan read, with the line's record as
    evidence; refused as stale when the record no longer shows a module holding what the plan took
    as known without reading it (another apply or read since, or the record outgrew its age)."""
    said = planned.document.get("read")
    if not isinstance(said, dict):
        return Reads(pairs, targets(pairs))
    names = {(bus.name, m.address): (bus, m) for bus, m in pairs}
    entries = [e for e in planned.modules if (e.bus, e.address) in names]  # the rest is refused by `prove`
    buses = {bus.name: bus for bus, _ in (names[(e.bus, e.address)] for e in entries)}
    desired, max_age = {key: m.desired_image() for key, (_, m) in names.items()}, {name: bus.record_max_age for name, bus in buses.items()}
    to_read, stale = what_to_read.for_plan_file(entries, desired, record(plant, buses.values()), max_age, datetime.now(UTC))
    if stale is not None:
        raise StalePlan(f"{path}: stale plan — bus {stale.bus}, module {stale.address} ({stale.name}): the line's record no longer shows it "
                        "holding what the plan took as known without reading it (written or read by another run since, or "
                        "older than record_max_age); nothing was written — plan again")  # fmt: skip
    return Reads([names[(e.bus, e.address)] for e in entries], to_read, said["base"], tuple(said["not_as_verified"]),
                 taken=dict(said.get("taken", {})))  # fmt: skip


def restore(snapshot: Path, *, gates: Gates = Gates(), verify: Verify = Verify.FLOOR, options: LineOptions | None = None,
            onto_current_lines: bool = False, reason: str | None = None) -> ApplyResult:  # fmt: skip
    """Plan and apply the modules back to what a snapshot holds, with the same gates as `apply` —
    onto the lines it was taken on: a bus of the plant file that now names another line (port or
    framing) is refused, unless `onto_current_lines`; and a snapshot that its journal does not
    show as written (`prc3cfg.shell.audit.snapshot_checked`) is refused."""
    options = options or LineOptions()
    taken = Snapshot.load(snapshot)
    if (note := audit.snapshot_checked(snapshot, taken)) is not None:
        options.tell(note)
    plant = load_plant(taken.plant_path)
    pairs = [(bus, m) for bus, m in plant.modules() if (bus.name, m.address) in taken.images]
    if len(pairs) != len(taken.images):
        raise UserError(f"{snapshot}: the plant file {taken.plant_path} no longer has every module of the snapshot — nothing was written")
    for bus in {bus.name: bus for bus, _ in pairs}.values():
        line = taken.lines.get(bus.name)
        if line is not None and not onto_current_lines and not line.same_line(bus.port, bus.framing, bus_line_keys(plant, bus)):
            raise UserError(f"{snapshot}: taken on bus {bus.name} at {line.port} ({line.framing}), which the plant file now puts at "
                            f"{bus.port} ({bus.framing}) — restoring there would write one line's modules onto another; nothing "
                            "was written: give --onto-current-lines if that is what you mean")  # fmt: skip
    to_read = what_to_read.in_full(_wanted(pairs, taken.images))  # every program the snapshot holds
    return _apply(plant, pairs, Reads(pairs, to_read), taken.images, None, gates, verify, options, reason=reason)


def _apply(plant: Plant, chosen: Pairs, wanted: Reads, desired: dict[Key, ModuleImage] | None,
           plan_file: tuple[Path, PlanFile] | None, gates: Gates, verify: Verify, options: LineOptions, *,
           reason: str | None = None) -> ApplyResult:  # fmt: skip
    buses = {bus.name: bus for bus, _ in wanted.pairs}
    command = "restore" if desired is not None else "apply"
    reason = _reason(plant, buses.values(), reason, command)
    for bus in buses.values():
        if not detects_damage(bus.framing, bus.line.parity) and not bus.accept_undetected_damage:
            raise UserError(f"{plant.path}: bus {bus.name}: {bus.framing} with parity none detects no damage — a damaged frame can "
                            "become another write, a read a write, a module's address the broadcast 0; nothing was written: set "
                            "parity: even (or odd) on the bus and its devices, or accept the risk with accept_undetected_damage: true")  # fmt: skip
    check_writable(plant.path)  # before the line: an apply that cannot keep its records writes nothing
    releases.folder()  # nor one that could not record an axis release before its frame, or drop a module from its line's record
    releases.folder(bases.KIND, bases.WHAT)
    said = run_header(command, plant.path, plant.name, plant.sha256, reason=reason, plan_file=plan_file[0] if plan_file else None,
                      argv=options.command_line)  # fmt: skip
    journal = Journal(plant.path, said, audit.follow(plant.path))  # its file is made at the first record: not for a busy line
    records = releases.Releases(command, journal.path)
    keys = {name: bus_line_keys(plant, bus) for name, bus in buses.items()}  # each line's identities, resolved once
    if options.cancel is None:  # the event that stops the lines when a record cannot be kept
        options = replace(options, cancel=Cancellation())
    assert options.cancel is not None
    keeping = _Keeping(plant, buses, keys, journal, records, options.cancel.event)
    try:
        with lines(plant, buses, options, purpose="apply", observer=keeping.observe, announce=keeping.announce, records=keeping) as links:
            earlier = tuple(releases.pending(key for identities in keys.values() for key in identities))
            writing = _Writing(plant, keys, buses, links, keeping, verify, options, records.command)
            if plan_file is None and not gates.asks:
                result = _apply_by_line(plant, chosen, wanted, desired, gates, writing, options, earlier, records)
            else:
                result = _apply_whole(plant, chosen, wanted, desired, plan_file, gates, writing, options, earlier, records)
            if result.runs and desired is None and len(chosen) == len(plant.modules()):
                _keep_applied(plant)
            return result
    finally:
        keeping.close()


def _apply_whole(plant: Plant, chosen: Pairs, wanted: Reads, desired: dict[Key, ModuleImage] | None,
                 plan_file: tuple[Path, PlanFile] | None, gates: Gates, writing: _Writing, options: LineOptions,
                 earlier: tuple[releases.Pending, ...], records: releases.Releases) -> ApplyResult:  # fmt: skip
    """Read back and plan the whole plant (or prove the plan file), show it and pass the gates, then write every line."""
    pairs, to_read, links = wanted.pairs, wanted.targets, writing.links
    started = time.monotonic()
    if plan_file is None:
        images, the_plan = _read_and_plan(plant, pairs, to_read, links, options, desired, command=writing.command,
                                          only_read=wanted.base is not None)  # fmt: skip
        the_plan = replace(the_plan, reading=wanted.reading(chosen, images))
    else:
        images = _read(to_read, links, options, then=seen(plant, writing.command))
        the_plan = prove(*plan_file, plant, chosen, images, {name: prober(links[name], bus) for name, bus in writing.buses.items()})
    reading = time.monotonic() - started
    if gates.show is not None:
        gates.show(the_plan)
    if not the_plan.changes:
        return ApplyResult(the_plan, (), None, writing.journal.path, earlier, records)
    releasing = [f"{m.bus}/{m.name}" for m in the_plan.axis_releases]
    allow = gates.allow_axis_release
    allow_axis_release = allow(releasing) if callable(allow) and releasing else allow is True
    if releasing and not allow_axis_release:
        raise AxisReleaseRefused(
            f"the plan releases the axes of {', '.join(releasing)} (10h/20h: they must travel to their "
            "reference point before production) — nothing was written; apply again with --allow-axis-release"
        )
    if gates.approve is not None and not gates.approve(the_plan):
        raise NotApproved("not applied — nothing was written")
    with options.deferred():  # from the snapshot to the end of the records, a signal waits its turn
        writing.whole(the_plan)
        writing.write(the_plan.modules, images, allow_axis_release)
        return writing.account(the_plan, earlier, records, {"reading": reading})


def _apply_by_line(plant: Plant, chosen: Pairs, wanted: Reads, desired: dict[Key, ModuleImage] | None, gates: Gates,
                   writing: _Writing, options: LineOptions, earlier: tuple[releases.Pending, ...],
                   records: releases.Releases) -> ApplyResult:  # fmt: skip
    """No question stands between the plan and the writes (`Gates.asks`): each module is planned as
    soon as it is read, and each line — its broadcasts decided once its last module is read — written
    as soon as its own plan is whole, while the other lines are still read and planned: no line
    waits for another. The plant's plan is shown once whole, the writes going on. A line whose
    read-back or plan fails is not written; the others are, and the result says both (`ApplyFailed`)."""
    pairs, links, buses = wanted.pairs, writing.links, writing.buses
    planner = _planner(plant, pairs, unset_systems(plant, buses.values()), only_read=wanted.base is not None)
    want = _wanted(pairs, desired)
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
            read_all(wanted.targets, links, progress=writing.phases.read, each=_planning_each(planner, want), then=seen(plant, writing.command, line))
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


class _Keeping:
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


class _Writing:
    """An apply's writes, a line or the whole plan at a time, from any line's thread: the runs of
    the modules a plan changes, the snapshot of those modules saved before the first write on
    their line — added to the apply's one snapshot file, written whole and atomically each time —
    and journalled, then written and verified (`execute`); then the account of every run."""

    def __init__(self, plant: Plant, keys: dict[str, tuple[str, ...]], buses: dict[str, Bus], links: dict[str, Link], keeping: _Keeping,
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
        steps' effect, and what the record knew of the rest (`what_to_read.verified`)."""
        when, by = bases.now(), bases.who(self.command, self.plant.path)
        for bus, held in known.items():
            done = {r.address: r for r in runs if r.bus == bus and r.verified}
            try:
                bases.update(self.keys[bus], {a: what_to_read.verified(held.get(a), _holds(run), when, by) for a, run in done.items()})
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


def _keep_applied(plant: Plant) -> None:
    """The plant file just applied in full and verified on every module, kept for `left_alone` — if
    it is still the one applied."""
    text = plant.path.read_bytes()
    if hashlib.sha256(text).hexdigest() == plant.sha256:
        save_applied(plant.path, text)


def left_alone(plant: Plant, previous: Path | None = None) -> list[str]:
    """What the plant file no longer describes — modules, and programs under `unmanaged_programs:
    keep` — which stays on the hardware as it is: against `previous` (the plant file as it was, e.g.
    on the main branch), else against the copy last applied in full from here (`.prc3cfg/applied/`)."""
    if previous is not None:
        before = load_plant(previous)  # named by the caller: its problems are said
    else:
        try:
            before = load_plant(applied_copy(plant.path))
        except UserError:
            return []  # never applied in full here, or a copy this prc3cfg cannot read: nothing to compare
    now = {(bus.name, m.address): m for bus, m in plant.modules()}
    notes = []
    for bus, old in before.modules():
        new = now.get((bus.name, old.address))
        if new is None:
            notes.append(f"{bus.name}/{old.name} (address {old.address}) is no longer in the plant file: "
                         "it stays on the hardware as it is, no longer managed")  # fmt: skip
        elif new.unmanaged_programs == "keep":
            gone = sorted(set(old.managed_programs()) - set(new.managed_programs()))
            if gone:
                which = f"program {gone[0]}" if len(gone) == 1 else f"programs {', '.join(map(str, gone))}"
                notes.append(f"{bus.name}/{new.name}: {which} no longer in the plant file (unmanaged_programs: keep): "
                             "it stays on the module as it is")  # fmt: skip
    return notes


# -- a bus without a plant file ------------------------------------------------------------


@dataclass(frozen=True)
class BareLine:
    """A line named by its port alone (`scan`, `import`): framing, character format, times."""

    port: str
    framing: str = "crc16"
    line: LineSettings = LineSettings()
    timeout: float = 0.5
    zvz: float = 0.020


def default_parity(port: str) -> str:
    """The parity of a bare line whose parity is not given: none on a pseudo-terminal, which carries
    none, else even (a PRC 3 line's)."""
    return "none" if is_pseudo_terminal(port) else "even"


@contextlib.contextmanager
def _bare_lock(port: str, options: LineOptions, purpose: str) -> Iterator[tuple[str, ...]]:
    """The line of a port without a plant file, locked; its identities."""
    problem = port_error("port", port)
    if problem is None and port.startswith(EMULATOR_SCHEME):
        problem = (f"port {port} is a plant file's emulator (its state is kept beside the plant file) — for a "
                   "bus without a plant file run prc3cfg emulator serve and give its socket://HOST:PORT")  # fmt: skip
    if problem is not None:
        raise UserError(problem)
    keys = line_keys(port)
    with line_lock(keys, port, port=port, timeout=options.lock_timeout, purpose=purpose, waiting=options.waiting):
        for record in releases.pending(keys):
            options.tell(record.said())
        yield keys


@contextlib.contextmanager
def _bare_link(bare: BareLine, options: LineOptions, purpose: str) -> Iterator[Link]:
    with contextlib.ExitStack() as stack:
        keys = stack.enter_context(_bare_lock(bare.port, options, purpose))
        port = open_port(bare.port, bare.line, bus=bare.port)
        stack.callback(port.close)
        yield Link(port, get_framing(bare.framing), bus=bare.port, line=bare.line, timeout=bare.timeout, zvz=bare.zvz,
                   retries=options.retries, trace=Trace(options.trace) if options.trace is not None else None,
                   observer=_written_reads({}, {bare.port: keys}, releases.Releases(purpose)),
                   cancel=options.cancel.event if options.cancel is not None else None)  # fmt: skip


def scan(bare: BareLine, options: LineOptions | None = None) -> dict[int, codec.SystemReply]:
    """Which addresses 1..30 answer a 50h, with what they answer (S9 and the system parameters)."""
    options = options or LineOptions()
    with _bare_link(bare, options, "scan") as link:
        return _scan(link, options)


def _scan(link: Link, options: LineOptions) -> dict[int, codec.SystemReply]:
    """One short try of a 50h at every address 1..30 (`Link.probe`); the replies of those that answer."""
    found = {}
    options.progress.start("scanning addresses", MAX_MODULE_ADDRESS)
    for address in range(1, MAX_MODULE_ADDRESS + 1):
        try:
            reply = link.probe(address, codec.ReadSystem(), min(link.timeout, PROBE_TIMEOUT))
        except (PortFailed, PossibleWrite, NoReadMessages):
            raise  # the port, not an absent module; a read a module executed as a write
        except LinkError:
            reply = None  # heard, but never usable: not a module this scan can report
        if isinstance(reply, codec.SystemReply):
            found[address] = reply
        options.progress.advance()
    return found


def doctor(bare: BareLine, search: Search, options: LineOptions | None = None, *, addresses: Iterable[int] | None = None,
           exchanges: int = 10, allow_unchecked: Callable[[], bool] = lambda: False) -> Diagnosis:  # fmt: skip
    """Which of `search`'s framings, bauds and parities the line of `bare.port` speaks, and each
    answering module's turnaround over `exchanges` timed 50h (`prc3cfg.shell.doctor`). Over
    `socket://` the gateway fixes baud and character format: only framings are tried, at `bare.line`.
    A probe in a framing without a checksum waits for `allow_unchecked()` (asked once)."""
    options = options or LineOptions()
    settable = urlsplit(bare.port).scheme.lower() != "socket"
    if not settable:
        search = replace(search, bauds=(bare.line.baud,), parities=(bare.line.parity,))

    @contextlib.contextmanager
    def open_line(line: LineSettings) -> Iterator[Port]:
        port = open_port(bare.port, line, bus=bare.port)
        try:
            yield port
        finally:
            port.close()

    def probing(candidate: LineCandidate) -> None:
        options.progress.note(f"probing {candidate.said()}")

    with _bare_lock(bare.port, options, "doctor"):
        return diagnose(bare.port, search, open_line, addresses=range(1, MAX_MODULE_ADDRESS + 1) if addresses is None else addresses,
                        zvz=bare.zvz, settings_found=settable, exchanges=exchanges, allow_unchecked=allow_unchecked,
                        progress=probing)  # fmt: skip


def import_modules(bare: BareLine, addresses: Iterable[int] | None = None, options: LineOptions | None = None) -> list[ModuleImage]:
    """The complete images of the modules at `addresses` (default: those a scan finds)."""
    options = options or LineOptions()
    with _bare_link(bare, options, "import") as link:
        wanted = sorted(addresses) if addresses is not None else sorted(_scan(link, options))
        if not wanted:
            raise UserError(f"{bare.port}: no module answered — nothing to import")
        options.progress.start("reading modules", len(wanted))
        images = []
        for address in wanted:
            images.append(read_module(link, address, PROGRAM_NUMBERS))
            options.progress.advance()
        return images


# -- drift and Teach In ----------------------------------------------------------------------


def drift(plant: Plant, modules: Iterable[str] | None = None, *, images: dict[Key, ModuleImage] | None = None,
          options: LineOptions | None = None) -> list[Drift]:  # fmt: skip
    """The chosen modules that drifted from the plant file — read back now, or as `images` —
    reported as drift, not as a plan (`prc3cfg plan --refresh-only`)."""
    if images is None:
        images = read(plant, modules, options, command="plan --refresh-only")
    found = []
    for bus, module in select(plant, modules):
        said = drifted(module.desired_image(), images[(bus.name, module.address)])
        if said:
            found.append(Drift(bus.name, module.address, module.name, tuple(said)))
    return found


@dataclass(frozen=True)
class Adoption:
    """The plant file rewritten to describe what the modules hold (`adopt`), not written yet:
    `before` is the file as read, `after` the new text, `adopted` each value with its one-line `text`."""

    path: Path
    before: str
    after: str
    adopted: tuple[Adopted, ...]
    #: why it is adopted (`--reason`, `PRC3CFG_REASON`), and the plant's name: for the journal's header
    reason: str | None = None
    plant: str = ""
    command_line: tuple[str, ...] | None = None


def adopt(plant: Plant, modules: Iterable[str] | None = None, programs: Iterable[int] | None = None,
          options: LineOptions | None = None, *, reason: str | None = None, check: bool = False) -> Adoption:  # fmt: skip
    """Read the chosen modules and work out the plant file that describes what they hold: only the
    values that drifted, in the layer they came from (`prc3cfg.plant.adopt`); `write_adoption`
    writes it. Unless it is only a `check`, a bus with `require_reason` refuses before its line is
    opened when neither `reason` nor `PRC3CFG_REASON` gives one."""
    options = options or LineOptions()
    given = None if check else _reason(plant, {bus.name: bus for bus, _ in select(plant, modules)}.values(), reason, "adopt")
    before = _plant_text(plant.path)
    images = read(plant, modules, options, command="adopt")
    found = adopt_text(plant, images, before, programs)
    return Adoption(plant.path, before, found.text, found.adopted, given, plant.name, options.command_line)


def write_adoption(adoption: Adoption) -> None:
    """Write the adopted plant file in place of the one read, atomically and with its permissions
    (through a link, to the file linked to) — refused if the file changed since it was read, which is
    checked once the new text is on disk, around the rename (`replace_unless_changed`). A journal
    says who adopted what and why, before and after (`prc3cfg.shell.records`)."""
    target = adoption.path.resolve()
    before = adoption.before.encode("utf-8")
    said = run_header("adopt", adoption.path, adoption.plant, hashlib.sha256(before).hexdigest(), reason=adoption.reason,
                      argv=adoption.command_line)  # fmt: skip
    journal = Journal(adoption.path, said, audit.follow(adoption.path))
    try:
        journal.record("adopt", buses=sorted({name.partition("/")[0] for value in adoption.adopted for name in value.modules}),
                       values=[value.text for value in adoption.adopted])  # fmt: skip
    except OSError as error:
        raise UserError(f"{journal.path}: cannot write the journal ({error.strerror}) — the plant file was not changed") from None
    try:
        try:
            written = replace_unless_changed(target, adoption.after, before)
        except OSError as error:
            raise UserError(f"{adoption.path}: cannot write it ({error.strerror}) — it was not changed") from None
        journal.record("adopted", written=written, sha256=hashlib.sha256(adoption.after.encode("utf-8")).hexdigest() if written else None)
    finally:
        journal.close()
    if not written:
        raise UserError(f"{adoption.path}: the plant file changed while adopting — it was not written: adopt again")


def _reason(plant: Plant, buses: Iterable[Bus], reason: str | None, command: str) -> str | None:
    """Why `command` writes (`reason`, else `PRC3CFG_REASON`) — refused in one line, before any line
    is opened, where a bus says `require_reason: true` and nothing says why."""
    given = reason_given(reason)
    requiring = [bus.name for bus in buses if bus.require_reason]
    if given is None and requiring:
        raise UserError(f"{plant.path}: {'bus' if len(requiring) == 1 else 'buses'} {', '.join(requiring)} "
                        f"{'requires' if len(requiring) == 1 else 'require'} a reason for every {command} (require_reason: true) "
                        "— nothing was written: give --reason TEXT or set PRC3CFG_REASON")  # fmt: skip
    return given


# -- the records beside a plant file ---------------------------------------------------------


def verify_records(paths: Iterable[Path]) -> Verified:
    """Check the records under `paths` — plant files (their records), records folders, journals,
    snapshots (`prc3cfg.shell.audit.check`): the first record of each file that does not match."""
    return audit.check(list(paths))


def list_records(plant_path: Path) -> list[RecordedRun]:
    """Every apply, restore and adopt beside the plant file, oldest first, as its records tell it."""
    return audit.runs(Path(plant_path))


def prune_records(plant: Plant, *, keep: int | None = None, older_than_days: float | None = None, dry_run: bool = False) -> Pruned:
    """Remove the plant's runs (journal and snapshot together) beyond the newest `keep` and older
    than `older_than_days` — never the newest snapshot of a line, never a run an axis release (or
    an E12) nobody was told of names."""
    if keep is None and older_than_days is None:
        raise UserError("say what to prune: --keep N (the newest N runs stay) or --older-than DAYS, or both")
    keys = {bus.name: bus_line_keys(plant, bus) for bus in plant.buses}
    with contextlib.ExitStack() as held:  # no apply of these lines writes its records meanwhile
        for bus in plant.buses:
            held.enter_context(line_lock(keys[bus.name], f"bus {bus.name} ({bus.port})", purpose="records prune"))
        every = [key for identities in keys.values() for key in identities]
        protected = [Path(r.journal) for kind in (releases.RELEASE, releases.E12) for r in releases.pending(every, kind) if r.journal]
        return audit.prune(plant.path, keep=keep, older_than_days=older_than_days, protected=protected, dry_run=dry_run)


def _plant_text(path: Path) -> str:
    try:
        return path.read_bytes().decode("utf-8", "replace")
    except OSError as error:
        raise UserError(f"{path}: cannot read it ({error.strerror}) — nothing was adopted") from None


# -- what a plant file says of its gateways and pictures -------------------------------------


def init_data_block(plant: Plant, bus_name: str) -> list[tuple[str, str, str]]:
    """The CP 524/525 Open Driver INIT data block of a bus's gateway: (label, notation, hex) per
    data word — refused in one line where the bus has no gateway or the driver would refuse it."""
    found = [b for b in plant.buses if b.name == bus_name]
    if not found:
        raise UserError(f"{plant.path}: no bus named {bus_name} — the plant's buses are {', '.join(b.name for b in plant.buses)}")
    bus = found[0]
    if bus.gateway is None:
        raise UserError(f"{plant.path}: bus {bus_name} has no gateway block — add gateway: {{receive_db, receive_dw, cpu, identifier}}")
    zvz_ms = Decimal(str(bus.zvz)) * 1000
    if zvz_ms != zvz_ms.to_integral_value():
        raise UserError(f"{plant.path}: bus {bus_name}: zvz {bus.zvz} s is not a whole number of milliseconds — ZVZTIM is set in ms")
    settings = gateway.GatewaySettings(
        receive_db=bus.gateway.receive_db, receive_dw=bus.gateway.receive_dw, cpu=bus.gateway.cpu,
        identifier=bus.gateway.identifier, line=bus.line, zvz_ms=int(zvz_ms),
    )  # fmt: skip
    problems = gateway.refusals(settings)
    if problems:
        raise UserError(f"bus {bus_name}: the CP 524/525 Open Driver would refuse these settings: " + "; ".join(map(str, problems)))
    return gateway.format_data_block(gateway.init_data_block(settings))


def picture(plant: Plant, module_name: str, *, fmt: str, images: dict[Key, ModuleImage] | None = None,
            planned: PlantPlan | None = None) -> bytes:  # fmt: skip
    """The chains of a module drawn (`prc3cfg.core.plot`, the plot extra): the plant file's, or what
    the module holds as before and what the plan leaves it holding as after — of `planned`, or of a
    plan from `images` (as `read` or `load_images` gave them)."""
    (bus, module), = select(plant, [module_name])
    title = f"module {module.name} — bus {bus.name}, address {module.address}"
    if images is None and planned is None:
        return plot.picture(module.desired_image(), fmt=fmt, title=f"{title}: the plant file", python=python_command())
    planned = planned or plan(plant, [module.name], images=images)
    change = next(c for c in planned.modules if (c.bus, c.address) == (bus.name, module.address))
    return plot.picture(change.as_known(change.plan.predicted), change.as_known(change.actual), fmt=fmt,
                        title=f"{title}: before (dashed) and after the plan", python=python_command())  # fmt: skip


def plot_format(path: Path) -> str:
    """"svg" or "png", the format of a picture to write to `path` (by its suffix) — a PlotError for any
    other, and when matplotlib is missing, naming the command that installs it into this Python."""
    return plot.plot_format(path, python=python_command())


# -- a plant file from a bus -----------------------------------------------------------------


def import_plant(buses: Mapping[str, BareLine], addresses: Iterable[int] | None = None, options: LineOptions | None = None, *,
                 plant_name: str = "imported") -> tuple[str, int]:  # fmt: skip
    """A plant file (its text) describing the live modules of these buses, by name (`import_modules`,
    one line after another), and how many modules it describes: what they all hold alike once, in one
    profile; `unmanaged_programs: reset`, so planning it against those lines is empty. Two names for
    one line are refused before any is read."""
    owner: dict[str, str] = {}
    for name, bare in buses.items():
        try:
            keys = line_keys(bare.port) if len(buses) > 1 else ()
        except ValueError:  # a port that names no line: opening it says so, in its turn
            keys = ()
        for key in keys:
            if key in owner:
                raise UserError(f"--port {buses[owner[key]].port} and --port {bare.port} are one line ({key}) — give each line once")
            owner[key] = name
    wanted = None if addresses is None else list(addresses)
    read = [(bus_entry(name, bare.port, bare.framing, bare.line, bare.timeout, bare.zvz), import_modules(bare, wanted, options))
            for name, bare in buses.items()]  # fmt: skip
    return imported_plant(plant_name, read), sum(len(images) for _, images in read)


# -- an emulated bus -------------------------------------------------------------------------


def emulator(modules: Iterable[int] | None = None, *, state: Path | None = None, framing: str = "crc16",
             line: LineSettings = LineSettings(), line_speed: bool = False, zvz: float = 0.020, turnaround: float = 0.010,
             turnarounds: Mapping[int, float] | None = None, jitter: float = 0.0, drop_rate: float = 0.0, corrupt_rate: float = 0.0,
             seed: int | None = None, max_connections: int | None = None,
             idle_timeout: float | None = None) -> Emulator:  # fmt: skip
    """A bus emulator (`prc3cfg emulator serve`), serving nothing yet (`listen`, `open_pty`): the
    modules at `modules` — else those of the `state` file, else 1-30 — as `state` holds them, every
    write it accepts saved there; closed on leaving its `with`. `turnarounds`: some modules' own
    turnaround instead of `turnaround`; `jitter`: each turnaround shifted by up to ± this (seeded by
    `seed`). Settings it refuses: `UserError`."""
    served, unserved = modules_to_serve(state, sorted(modules) if modules is not None else None)
    try:
        return Emulator(
            served, framing=framing, zvz=zvz, turnaround=turnaround, turnarounds=turnarounds, jitter=jitter, line_speed=line_speed, line=line,
            faults=FaultInjection(drop_rate, corrupt_rate, seed), state_path=state, unserved=unserved,
            max_connections=MAX_CONNECTIONS if max_connections is None else max_connections,
            idle_timeout=IDLE_TIMEOUT if idle_timeout is None else idle_timeout,
        )  # fmt: skip
    except ValueError as error:
        raise UserError(f"emulator: {error}") from None


def listen(running: Emulator, host: str, port: int, *, rfc2217: bool = False) -> tuple[str, int]:
    """Serve `running` to TCP clients at HOST:PORT (0: any free port) — speaking RFC 2217 if asked (a
    client at other line settings then gets what a UART would make of its bytes); the address it listens at."""
    try:
        return running.listen(host, port, rfc2217=rfc2217)
    except OSError as error:  # the reason, without the "(while attempting to bind …)" Python adds
        reason = str(error.strerror or error).partition(" (while attempting")[0]
        raise UserError(f"--listen {host}:{port}: cannot listen ({reason}) — choose a free port on an address of this host") from None


def served_pty(path: str, modules: Iterable[int]) -> contextlib.AbstractContextManager[None]:
    """While it runs, `prc3cfg ports` lists the pseudo-terminal at `path` as this process's emulator of `modules`."""
    return ptys.served(path, modules)


def open_pty(running: Emulator) -> str:
    """Serve `running` on a new pseudo-terminal too; its path."""
    if not HAS_PTY:
        raise UserError("--pty: Windows has no pseudo-terminals — serve over TCP (--listen HOST:PORT) and use socket://HOST:PORT")
    try:
        return running.open_pty()
    except OSError as error:
        raise UserError(f"--pty: cannot open a pseudo-terminal ({error.strerror or error})") from None
