"""Line sessions: the lines of a plant, or a bare port, locked and opened for one command.

`lines` locks every named bus's line (refusing two buses that are one line), tells the axis
releases no account has named yet, and opens a `Link` per bus; `bare_lock` and `bare_link` do the
same for a port without a plant file (`BareLine`). A read a module answers as a write is recorded
as an axis release (`written_reads`). `LineOptions` says how a command uses its lines;
`bus_line_keys` are the identities of a bus's line (its lock, its records); where the machine lists
its lines (`PORTS_VARIABLE`), a plant's bus opens only one of them (`refuse_other_lines`).

The link (pyserial, the emulator behind `emulator://`) is imported where a line is opened: a
command that opens none (`plan --actual`) loads none of it, and `LineOptions` costs nothing.
Does not own what is read or written on the lines (`prc3cfg.api`, `prc3cfg.shell.engine`), nor
the locks and the links themselves (`prc3cfg.shell.locks`, `prc3cfg.shell.link`).
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import threading
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, TextIO, TypeAlias

from prc3cfg.core import what_to_read
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.exchange import answered_as_write
from prc3cfg.core.framing import get_framing
from prc3cfg.core.image import Key, ModuleImage
from prc3cfg.core.line import EMULATOR_SCHEME, LineSettings
from prc3cfg.errors import UserError
from prc3cfg.plant import Bus, Plant
from prc3cfg.plant.messages import port_error
from prc3cfg.shell import line_record, pending_records, platform
from prc3cfg.shell.cancel import Cancellation
from prc3cfg.shell.locks import line_keys, line_lock
from prc3cfg.shell.phases import Progress, Quiet

if TYPE_CHECKING:
    from prc3cfg.shell.link.client import Exchange, Link
    from prc3cfg.shell.link.trace import Trace

#: Called with each exchange on a line: before its frame leaves (`announce`), or once it is done.
Observer: TypeAlias = "Callable[[Exchange], None]"


@dataclass(frozen=True)
class LineOptions:
    """How to use the lines: retries per message and a frame trace (of the links a session opens: a
    link handed to it keeps its own), seconds to wait for another prc3cfg's lock, Ctrl-C handling
    (`prc3cfg.shell.cancel.Cancellation`) and progress reports — and where a command reports what
    its caller may want to say after it: the links it used, the warnings it has for the operator.
    A value: no call fills it in."""

    retries: int = 5
    lock_timeout: float = 0.0
    trace: TextIO | None = None
    cancel: Cancellation | None = None
    progress: Progress = field(default_factory=Quiet)
    #: called with the text when a line is busy and a wait for its lock begins
    waiting: Callable[[str], None] | None = None
    #: called after a command that succeeded with the links it used: their `repeated` exchanges, their times
    used: Callable[[list[Link]], None] | None = None
    #: called with each warning a command has for the operator (an axis release nobody was told
    #: of, `prc3cfg.shell.pending_records`)
    notice: Callable[[str], None] | None = None
    #: the command line a run's records name (their header): the program's, `sys.argv`, unless told
    command_line: tuple[str, ...] | None = None

    def tell(self, text: str) -> None:
        if self.notice is not None:
            self.notice(text)

    def deferred(self) -> contextlib.AbstractContextManager[None]:
        """A phase a signal must not cut (`Cancellation.deferred`), when there is a cancellation."""
        return self.cancel.deferred() if self.cancel is not None else contextlib.nullcontext()


def bus_line_keys(plant: Plant, bus: Bus) -> tuple[str, ...]:
    """The identities of a bus's line: its port, or for `emulator://` the emulator's state file — and
    where `PORTS_VARIABLE` gives the line other spellings (`machine_lines`), theirs too: one lock and
    one record of what its modules hold, whichever spelling a plant file names."""
    from prc3cfg.shell.link.ports import emulator_state_path

    if bus.port.startswith(EMULATOR_SCHEME):
        return line_keys(bus.port, emulator_state=emulator_state_path(plant.path, bus.port))
    keys = line_keys(bus.port)
    for spellings in machine_lines():
        if not spellings.isdisjoint(keys):
            keys += tuple(sorted(spellings.difference(keys)))
    return keys


#: The ports of this machine's lines, `;` between lines and `|` between spellings of one line: where it is set
#: (the runner wired to a line, in its own configuration), a plant file's bus opens only a line it names — a
#: pull request's plant file, planned there, cannot make it open another device or connect to another host. A
#: line reached two ways (a ser2net serving one device on a raw and an RFC 2217 port:
#: `socket://gw:4001|rfc2217://gw:4002`) is one line by either: one lock, one record. `emulator://` opens
#: none, and is not listed.
PORTS_VARIABLE = "PRC3CFG_PORTS"


def _listed() -> list[list[str]]:
    """The lines `PORTS_VARIABLE` lists, each as its spellings; `UserError` for a port no plant file could
    name."""
    listed = os.environ.get(PORTS_VARIABLE, "")
    lines = [[port.strip() for port in line.split("|") if port.strip()] for line in listed.split(";")]
    for port in (port for line in lines for port in line):
        if (problem := port_error("port", port, operators=True)) is not None:
            raise UserError(f"{PORTS_VARIABLE}: {problem}")
    return [line for line in lines if line]


def machine_lines() -> list[frozenset[str]]:
    """Each line `PORTS_VARIABLE` lists, as the identities of all its spellings (`line_keys`) — worked out
    once a process for each value of the variable: a command asks for a bus's identities several times, and a
    host name among the spellings would be resolved on every one."""
    return list(_identities(tuple(tuple(line) for line in _listed())))


@functools.lru_cache(maxsize=4)
def _identities(lines: tuple[tuple[str, ...], ...]) -> tuple[frozenset[str], ...]:
    return tuple(frozenset(key for port in line if not port.startswith(EMULATOR_SCHEME)
                           for key in line_keys(port)) for line in lines)


def refuse_other_lines(plant: Plant, keys: Mapping[str, tuple[str, ...]]) -> None:
    """Refuse, before any line is opened, a bus (by its line's identities, `keys`) that `PORTS_VARIABLE` does
    not name where it is set: one of its ports must be that line, as any spelling of it (`line_keys`)."""
    if os.environ.get(PORTS_VARIABLE) is None:
        return
    ports = [port for line in _listed() for port in line]
    machine = frozenset().union(*machine_lines())
    for bus in plant.buses:
        if (bus.name in keys and not bus.port.startswith(EMULATOR_SCHEME)
            and not machine.intersection(keys[bus.name])):
            raise UserError(f"{plant.path}: bus {bus.name}: port {bus.port} is not a line of this machine — "
                            f"{PORTS_VARIABLE}, the "
                            f"machine's own list, names {', '.join(ports) or 'none'}: name one of those in "
                            "the plant file, or add "
                            f"the port to {PORTS_VARIABLE} in the machine's configuration")


def line_cost(bus: Bus) -> LineCost:
    """What an exchange costs on a bus's line, by its settings (`prc3cfg.core.bustime`)."""
    return LineCost.of(bus.framing, bus.line, bus.turnaround, bus.zvz)


class Records(Protocol):
    """Where an axis release is recorded: `pending_records.Releases`, or an apply's `Keeping` of it."""

    def record(self, keys: tuple[str, ...], bus: str, address: int, name: str, kind: str = ...,
               code: int | None = ...) -> None: ...


@dataclass(frozen=True)
class OnRecord:
    """What is on record of the lines a command uses, read once — under the lines' locks where the command
    holds them (`lines`), else as it stands (`on_record`): each line's record of what its modules hold, by
    bus, and every record of an axis release, an E12 or a fault state on them not cleared yet
    (`pending_records.of_line`)."""

    records: dict[str, line_record.LineRecord]
    pending: tuple[pending_records.Pending, ...]

    def of(self, kind: str, bus: str) -> list[pending_records.Pending]:
        """The records of `kind` not cleared yet on the line of `bus` (by that line's identities: any
        spelling)."""
        wanted = set(self.records[bus].keys)
        return [r for r in self.pending if r.kind == kind and wanted & set(r.keys)]

    def saw(self, bus: str, images: Mapping[Key, ModuleImage], by: str) -> None:
        """A line's read-back, as soon as it is in, into the line's record: what `by` saw — drift included, so
        the next plan writes it back. Written with the line's next write of the record (an apply's before its
        first frame), else when the command ends."""
        record, when = self.records[bus], line_record.now()
        known = record.known()
        record.saw({a: what_to_read.merged(known.get(a), image, when, by)
                    for (b, a), image in images.items() if b == bus})


def on_record(keys: Mapping[str, tuple[str, ...]]) -> OnRecord:
    """What is on record of the lines with these identities (by bus), read now."""
    return OnRecord({bus: line_record.LineRecord(line) for bus, line in keys.items()},
                    tuple(pending_records.of_line((key for line in keys.values() for key in line), None)))


@dataclass(frozen=True)
class Lines:
    """The lines a command holds: a `Link` per bus, and what is on record of them, read under their locks."""

    links: dict[str, Link]
    on_record: OnRecord


@contextlib.contextmanager
def lines(plant: Plant, buses: Iterable[str], options: LineOptions, *, purpose: str = "read",
          observer: Observer | None = None,
          announce: Observer | None = None, records: Records | None = None,
          given: Mapping[str, Link] | None = None,
          identities: Mapping[str, tuple[str, ...]] | None = None) -> Iterator[Lines]:
    """A `Link` per named bus, each line locked first: only one prc3cfg talks on a line at a time —
    opened from the plant file's ports, or those `given`, already open (`lent`) — and each line's
    record, read once under its lock and written at the end with what the command saw. Every axis release
    on these lines that no account has named yet is told (`LineOptions.tell`), and a read a module
    answers as a write is recorded as one in `records` (`PossibleWrite`).

    Two buses that are one line (two spellings of one address) are refused: they would wait
    for each other's lock. Each line's identities (`bus_line_keys`) are resolved here, unless the
    caller resolved them already (`identities`: once a command, a name resolved twice may differ)."""
    names = set(buses)
    keys = {bus.name: identities[bus.name] if identities is not None else bus_line_keys(plant, bus)
            for bus in plant.buses if bus.name in names}
    if given is None:
        refuse_other_lines(plant, keys)
    _one_bus_a_line(plant, keys)
    with contextlib.ExitStack() as stack:
        for bus in plant.buses:
            if bus.name in names:
                stack.enter_context(line_lock(keys[bus.name], f"bus {bus.name} ({bus.port})", port=bus.port,
                                              timeout=options.lock_timeout,
                                              purpose=purpose, waiting=options.waiting))
        if _sha256_of(plant.path) != plant.sha256:  # edited (or adopted into) while this waited for the line
            raise UserError(f"{plant.path}: the plant file changed while this command waited for the line — "
                            "nothing was "
                            "read or written: run it again, with the file as it is now")
        held = _line_records(keys, options)
        cancel = options.cancel.event if options.cancel is not None else None
        module_names = {(bus.name, m.address): m.name for bus, m in plant.modules()}
        watch = written_reads(module_names, keys, records or pending_records.Releases(purpose), observer)
        if given is None:
            from prc3cfg.shell.link.ports import open_plant_links

            links = stack.enter_context(open_plant_links(plant, names, trace=_trace(options),
                                                         retries=options.retries, observer=watch,
                                                         announce=announce, cancel=cancel))
        else:
            # in the plant's order
            lending = {bus.name: _given(given, bus.name) for bus in plant.buses if bus.name in names}
            links = stack.enter_context(lent(lending, watch, announce, cancel))
        try:
            yield Lines(links, held)
        # what was read is kept all the same (drift included: the next plan writes it back)
        except BaseException:
            for record in held.records.values():
                with contextlib.suppress(UserError):
                    record.write()
            raise
        for record in held.records.values():
            record.write()
        if options.used is not None:
            options.used(list(links.values()))


def _one_bus_a_line(plant: Plant, keys: Mapping[str, tuple[str, ...]]) -> None:
    """Two buses that are one line (an identity in `keys` of both) are refused."""
    owner: dict[str, str] = {}  # the bus of each identity seen
    for name, identities in keys.items():
        for key in identities:
            if key in owner:
                raise UserError(f"{plant.path}: buses {owner[key]} and {name} are one line ({key}) — "
                                "describe each line once, as one bus")
            owner[key] = name


def _line_records(keys: Mapping[str, tuple[str, ...]], options: LineOptions) -> OnRecord:
    """Under the lines' locks: what is on record of them, read once (this user's names made theirs first:
    `line_record.settle`), with the records' files passed over or moved aside told, every axis release on
    these lines that no account has named yet, and every module a write found in a fault state not seen
    cleared since."""
    said = [*pending_records.passed_over(),
            *(said for line in keys.values() for said in line_record.settle(line))]
    held = on_record(keys)
    for line in [*said, *(said for record in held.records.values() for said in record.passed_over())]:
        options.tell(line)
    for record in held.pending:
        if record.kind in (pending_records.RELEASE, pending_records.FAULT):
            options.tell(record.said())
    return held


def _given(given: Mapping[str, Link], bus: str) -> Link:
    """The link given for `bus`: one for every bus the command uses, speaking for that bus."""
    link = given.get(bus)
    if link is None:
        raise UserError(f"no link given for bus {bus} — give an open link for every bus the command "
                        "uses, or none")
    if link.bus != bus:
        raise UserError(f"the link given for bus {bus} speaks for bus {link.bus} — open it with "
                        f"bus={bus!r}: the journal and "
                        "the records name each exchange by its link's bus")
    return link


@contextlib.contextmanager
def lent(links: dict[str, Link], observer: Observer | None, announce: Observer | None,
         cancel: threading.Event | None) -> Iterator[dict[str, Link]]:
    """Links a caller opened (over any `Port`: a serial port, a socket, an in-memory pair) used for
    one session as the links a session opens are: its `observer` and `announce` (the journal, the
    records of releases) before each link's own, its `cancel` event in place of the link's — each
    as it was again afterwards. Their retries, time-out and trace stay the caller's."""
    kept = {name: (link.observer, link.announce, link.cancel) for name, link in links.items()}
    try:
        for link in links.values():
            link.observer, link.announce = _then(observer, link.observer), _then(announce, link.announce)
            link.cancel = cancel if cancel is not None else link.cancel
        yield links
    finally:
        for name, (own_observer, own_announce, own_cancel) in kept.items():
            link = links[name]
            link.observer, link.announce, link.cancel = own_observer, own_announce, own_cancel


def _then(first: Observer | None, then: Observer | None) -> Observer | None:
    """`first`, then `then`, with each exchange."""
    if first is None or then is None:
        return first or then

    def both(exchange: Exchange) -> None:
        first(exchange)
        then(exchange)

    return both


def _trace(options: LineOptions) -> Trace | None:
    """The frame trace of links a session opens, when there is one."""
    from prc3cfg.shell.link.trace import Trace

    return Trace(options.trace) if options.trace is not None else None


def _sha256_of(path: Path) -> str | None:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def written_reads(names: dict[Key, str], keys: dict[str, tuple[str, ...]], records: Records,
                   observer: Callable[[Exchange], None] | None = None) -> Callable[[Exchange], None]:
    """`observer`, and a read answered with an acknowledgement recorded as an axis release: the
    module executed a damaged frame as a write, a 10h as likely as any (`PossibleWrite`)."""

    def watch(exchange: Exchange) -> None:
        if observer is not None:
            observer(exchange)
        if answered_as_write(exchange.request, exchange.reply):
            name = names.get((exchange.bus, exchange.address), f"address {exchange.address}")
            records.record(keys[exchange.bus], exchange.bus, exchange.address, name)

    return watch


@dataclass(frozen=True)
class BareLine:
    """A line named by its port alone (`scan`, `import`): framing, character format, times. Its port is
    the operator's own choice, not a reviewed file's: any port pyserial opens, its URL handlers too."""

    port: str
    framing: str = "crc16"
    line: LineSettings = LineSettings()
    timeout: float = 0.5
    zvz: float = 0.020


def default_parity(port: str) -> str:
    """The parity of a bare line whose parity is not given: none on a pseudo-terminal, which carries
    none, else even (a PRC 3 line's)."""
    return "none" if platform.is_pseudo_terminal(port) else "even"


@contextlib.contextmanager
def bare_lock(port: str, options: LineOptions, purpose: str) -> Iterator[tuple[str, ...]]:
    """The line of a port without a plant file, locked; its identities."""
    problem = port_error("port", port, operators=True)
    if problem is None and port.startswith(EMULATOR_SCHEME):
        problem = (f"port {port} is a plant file's emulator (its state is kept beside the plant "
                   "file) — for a "
                   "bus without a plant file run prc3cfg emulator serve and give its socket://HOST:PORT")
    if problem is not None:
        raise UserError(problem)
    keys = line_keys(port)
    with line_lock(keys, port, port=port, timeout=options.lock_timeout, purpose=purpose,
                   waiting=options.waiting):
        for record in [*pending_records.of_line(keys), *pending_records.of_line(keys, pending_records.FAULT)]:
            options.tell(record.said())
        yield keys


@contextlib.contextmanager
def bare_link(bare: BareLine, options: LineOptions, purpose: str,
              given: Link | None = None) -> Iterator[Link]:
    """The link of a port without a plant file, its line locked: opened from `bare`, or `given`,
    already open (`lent`; it speaks for the port: its `bus` is `bare.port`)."""
    cancel = options.cancel.event if options.cancel is not None else None
    with contextlib.ExitStack() as stack:
        keys = stack.enter_context(bare_lock(bare.port, options, purpose))
        watch = written_reads({}, {bare.port: keys}, pending_records.Releases(purpose))
        if given is not None:
            yield stack.enter_context(lent({bare.port: _given({bare.port: given}, bare.port)}, watch, None,
                                           cancel))[bare.port]
            return
        from prc3cfg.shell.link.client import Link
        from prc3cfg.shell.link.ports import open_port

        port = open_port(bare.port, bare.line, bus=bare.port, operators=True)
        stack.callback(port.close)
        yield Link(port, get_framing(bare.framing), bus=bare.port, line=bare.line, timeout=bare.timeout,
                   zvz=bare.zvz,
                   retries=options.retries, trace=_trace(options), observer=watch,
                   cancel=cancel)
