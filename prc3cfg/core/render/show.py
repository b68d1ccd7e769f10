"""What `show` says of a plant file's modules: the table of its modules (`modules_table`) and one module's
effective configuration, each value in human and device units and where it came from (`shown_module`) — words
and rows; the terminal draws them. Pure.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

from prc3cfg.core.image import Program, SystemParameters
from prc3cfg.core.units import FUNCTION_OUTPUTS, PROGRAM_QUANTITIES, SYSTEM_QUANTITIES, human_text


@dataclass(frozen=True, slots=True)
class Table:
    """A table as `show` lays it out: its title, its columns, and its rows in sections (a line
    between two sections); the terminal draws it."""

    title: str
    columns: tuple[str, ...]
    sections: tuple[tuple[tuple[str, ...], ...], ...]


@dataclass(frozen=True, slots=True)
class ModuleRow:
    """A module as `show PLANT` lists it: where it is, the profiles it takes, the programs it lists."""

    bus: str
    address: int
    name: str
    profiles: tuple[str, ...]
    programs: tuple[int, ...]
    unmanaged_programs: str


def modules_table(plant: str, modules: Iterable[ModuleRow]) -> Table:
    """The modules of a plant, one row each ("-" for no profile, no program listed)."""
    rows = tuple((m.bus, str(m.address), m.name, ", ".join(m.profiles) or "-",
                  ", ".join(map(str, m.programs)) or "-",
                  m.unmanaged_programs) for m in modules)
    return Table(f"plant {plant}", ("bus", "address", "module", "profiles", "programs", "unmanaged"), (rows,))


@dataclass(frozen=True, slots=True)
class Settings:
    """What `show PLANT --module NAME` is given of a module: who and where it is, what it should hold
    in device units (`programs`: the listed ones), and where each value came from ("default",
    "profile NAME", "module") — `sources` by plant-file key (system parameters, `unmanaged_programs`,
    `chains`), `program_sources` by program and key (`jump` for A). `chains`: each chain's programs
    and whether it loops."""

    name: str
    bus: str
    address: int
    profiles: tuple[str, ...]
    unmanaged_programs: str
    system: SystemParameters
    programs: Mapping[int, Program]
    sources: Mapping[str, str]
    program_sources: Mapping[int, Mapping[str, str]]
    chains: tuple[tuple[tuple[int, ...], bool], ...]


class Shown(NamedTuple):
    """A module as `show PLANT --module NAME` shows it: its heading — before the name, the name (the
    terminal sets it off), after it — then lines and tables, in order."""

    heading: tuple[str, str, str]
    blocks: list[str | Table]


def _setting(key: str, symbol: str, device: int, source: str) -> tuple[str, str, str, str]:
    """A value's row: its key and symbol, in human units, as the device holds it, where it came from."""
    return f"{key} ({symbol})", human_text(symbol, device), str(device), source


def shown_module(settings: Settings) -> Shown:
    """A module's effective configuration: each value in human units and device units, and where it came
    from."""
    where = (f" — bus {settings.bus}, address {settings.address}, profiles: "
             f"{', '.join(settings.profiles) or 'none'}")
    unmanaged = (f"unmanaged_programs: {settings.unmanaged_programs} "
                 f"({settings.sources['unmanaged_programs']})")
    system = tuple(_setting(q.key, q.symbol, getattr(settings.system, q.symbol), settings.sources[q.key])
                   for q in SYSTEM_QUANTITIES)
    sections = []
    for number, program in settings.programs.items():
        sources = settings.program_sources[number]
        rows = [_setting(q.key, q.symbol, getattr(program, q.symbol), sources[q.key])
                for q in PROGRAM_QUANTITIES]
        rows += [_setting(symbol.lower(), symbol, getattr(program, symbol), sources[symbol.lower()])
                 for symbol in FUNCTION_OUTPUTS]
        rows.append(("jump (A)", f"program {program.A}" if program.A else "stop", str(program.A),
                     sources["jump"]))
        sections.append(tuple((str(number) if i == 0 else "", *row) for i, row in enumerate(rows)))
    blocks: list[str | Table] = [
        unmanaged,
        Table("system", ("key", "value", "device", "from"), (system,)),
        Table("programs", ("#", "key", "value", "device", "from"), tuple(sections)),
    ]
    if settings.chains:
        blocks.append(f"chains ({settings.sources['chains']}): "
                      f"{'; '.join(chain_text(*chain) for chain in settings.chains)}")
    return Shown(("module ", settings.name, where), blocks)


def chain_text(programs: Sequence[int], loop: bool) -> str:
    """A chain as a plant file's reader follows it: "1 → 2 → 1 (loop)", "10 → 11 → stop"."""
    steps = [*map(str, programs), str(programs[0]) if loop else "stop"]
    return " → ".join(steps) + (" (loop)" if loop else "")
