"""A bus as the modules on it answer: `scan`, `import_modules`, `import_plant`, `doctor`.

Also how a line's own speed compares with what its settings price (`slower_than_priced`) and
whether `doctor` can measure a port (`measurable`). Does not own the search of framings and
settings (`prc3cfg.shell.doctor`) nor writing a plant file (`prc3cfg.plant.importer`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import replace
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

from prc3cfg.core import bustime, codec
from prc3cfg.core.image import MAX_MODULE_ADDRESS, PROGRAM_NUMBERS, ModuleImage
from prc3cfg.core.line import EMULATOR_SCHEME, LineSettings
from prc3cfg.errors import UserError
from prc3cfg.plant.messages import port_error
from prc3cfg.shell.link.client import Link, Port
from prc3cfg.shell.link.ports import open_port
from prc3cfg.shell.locks import line_keys
from prc3cfg.shell.probe import probe, probe_timeout
from prc3cfg.shell.readback import read_module
from prc3cfg.shell.sessions import BareLine, LineOptions, bare_link, bare_lock

# doctor's search and the importer load where `doctor` and `import_plant` run: `plan` asks `measurable`
if TYPE_CHECKING:
    from prc3cfg.shell.doctor import Diagnosis, LineCandidate, Search


def slower_than_priced(links: Iterable[Link]) -> list[Link]:
    """The links whose answered exchanges took clearly longer than their line settings price them
    (`prc3cfg.core.bustime.slower_than_priced`): the plant file's line settings are off."""
    return [link for link in links if link.cost is not None and link.answered
            and bustime.slower_than_priced(link.answered_time, link.priced_time)]


def measurable(port: str) -> bool:
    """Whether `prc3cfg doctor` can measure the line at `port` (an `emulator://` port it cannot: its URL says
    how it answers)."""
    return not port.startswith(EMULATOR_SCHEME)


def scan(bare: BareLine, options: LineOptions | None = None, *,
         link: Link | None = None) -> dict[int, codec.SystemReply]:
    """Which addresses 1..30 answer a 50h, with what they answer (S9 and the system parameters) —
    over `bare.port`, or the `link` given, already open (`import_modules` takes one too)."""
    options = options or LineOptions()
    with bare_link(bare, options, "scan", link) as open_link:
        return _scan(open_link, options)


def _scan(link: Link, options: LineOptions) -> dict[int, codec.SystemReply]:
    """One short try of a 50h at every address 1..30 (`probe`); the replies of those that answer."""
    found = {}
    options.progress.start("scanning addresses", MAX_MODULE_ADDRESS)
    for address in range(1, MAX_MODULE_ADDRESS + 1):
        heard = probe(link, address, probe_timeout(link.timeout))
        # heard but never usable: not a module to report
        if heard is not None and isinstance(heard.reply, codec.SystemReply):
            found[address] = heard.reply
        options.progress.advance()
    return found


def doctor(bare: BareLine, search: Search, options: LineOptions | None = None, *,
           addresses: Iterable[int] | None = None,
           exchanges: int = 10, allow_unchecked: Callable[[], bool] = lambda: False) -> Diagnosis:
    """Which of `search`'s framings, bauds and parities the line of `bare.port` speaks, and each
    answering module's turnaround over `exchanges` timed 50h (`prc3cfg.shell.doctor`). Over
    `socket://` the gateway fixes baud and character format: only framings are tried, at `bare.line`.
    A probe in a framing without a checksum waits for `allow_unchecked()` (asked once)."""
    from prc3cfg.shell.doctor import diagnose

    options = options or LineOptions()
    settable = urlsplit(bare.port).scheme.lower() != "socket"
    if not settable:
        search = replace(search, bauds=(bare.line.baud,), parities=(bare.line.parity,))

    @contextlib.contextmanager
    def open_line(line: LineSettings) -> Iterator[Port]:
        port = open_port(bare.port, line, bus=bare.port, operators=True)
        try:
            yield port
        finally:
            port.close()

    def probing(candidate: LineCandidate) -> None:
        options.progress.note(f"probing {candidate.said()}")

    with bare_lock(bare.port, options, "doctor"):
        return diagnose(bare.port, search, open_line,
                        addresses=range(1, MAX_MODULE_ADDRESS + 1) if addresses is None else addresses,
                        zvz=bare.zvz, settings_found=settable, exchanges=exchanges,
                        allow_unchecked=allow_unchecked,
                        progress=probing)


def import_modules(bare: BareLine, addresses: Iterable[int] | None = None, options: LineOptions | None = None,
                   *,
                   link: Link | None = None) -> list[ModuleImage]:
    """The complete images of the modules at `addresses` (default: those a scan finds)."""
    options = options or LineOptions()
    with bare_link(bare, options, "import", link) as open_link:
        wanted = sorted(addresses) if addresses is not None else sorted(_scan(open_link, options))
        if not wanted:
            raise UserError(f"{bare.port}: no module answered — nothing to import")
        options.progress.start("reading modules", len(wanted))
        images = []
        for address in wanted:
            images.append(read_module(open_link, address, PROGRAM_NUMBERS))
            options.progress.advance()
        return images


def import_plant(buses: Mapping[str, BareLine], addresses: Iterable[int] | None = None,
                 options: LineOptions | None = None, *,
                 plant_name: str = "imported", links: Mapping[str, Link] | None = None) -> tuple[str, int]:
    """A plant file (its text) describing the live modules of these buses, by name (`import_modules`,
    one line after another — over their ports, or the `links` given by name), and how many modules it
    describes: what they all hold alike once, in one profile; `unmanaged_programs: reset`, so planning
    it against those lines is empty. Two names for one line, and a port no plant file may name (a
    pyserial handler's URL: `core.line.port_refusal`), are refused before any is read."""
    from prc3cfg.plant.importer import bus_entry, imported_plant

    owner: dict[str, str] = {}
    for name, bare in buses.items():
        readable = port_error("port", bare.port, operators=True) is None
        if readable and (problem := port_error("--port", bare.port)) is not None:
            # fine to read, but no plant file may name it
            raise UserError(f"{problem}: import writes it into the plant file")
        try:
            keys = line_keys(bare.port) if len(buses) > 1 else ()
        except ValueError:  # a port that names no line: opening it says so, in its turn
            keys = ()
        for key in keys:
            if key in owner:
                raise UserError(f"--port {buses[owner[key]].port} and --port {bare.port} are one line "
                                f"({key}) — give each line once")
            owner[key] = name
        if links is not None and name not in links:
            raise UserError(f"no link given for {name} ({bare.port}) — give an open link for every "
                            "line, or none")
    wanted = None if addresses is None else list(addresses)
    read = [(bus_entry(name, bare.port, bare.framing, bare.line, bare.timeout, bare.zvz),
             import_modules(bare, wanted, options, link=None if links is None else links[name]))
            for name, bare in buses.items()]
    return imported_plant(plant_name, read), sum(len(images) for _, images in read)
