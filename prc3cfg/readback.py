"""Read-back: what every module holds, in the fewest exchanges.

A module image is one 50h (system parameters, S9) and, for the managed programs only,
52h reads of up to four consecutive programs (51h for a lone one): a greedy cover from
the lowest unread program, which is the fewest exchanges for any set of programs; each
read ends at the last wanted program of its window, so no byte is read for nothing at
the end of a run. A fully managed module takes 1 + 16 exchanges.

S9 must equal the configured address, else the wiring or the plant file is wrong.
Buses are read in parallel (one thread per line), the modules of one line one after
another (the line is half duplex).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

from prc3cfg import codec
from prc3cfg.error_codes import describe, remedy
from prc3cfg.errors import UserError
from prc3cfg.image import PROGRAM_COUNT, ModuleImage, Program
from prc3cfg.link.client import Link


class ReadBackError(UserError):
    """A module answered a read with an error code, or is not the module the plant says."""


def read_messages(programs: Iterable[int]) -> list[codec.Message]:
    """50h, then the fewest 51h/52h that read exactly the programs wanted (and between them)."""
    wanted = sorted(set(programs))
    messages: list[codec.Message] = [codec.ReadSystem()]
    i = 0
    while i < len(wanted):
        first = wanted[i]
        while i < len(wanted) and wanted[i] <= first + codec.MAX_READ_PROGRAMS - 1:
            i += 1
        last = wanted[i - 1]
        messages.append(codec.ReadProgram(first) if first == last else codec.ReadPrograms(first, last))
    return messages


def read_module(link: Link, address: int, programs: Iterable[int], *, name: str = "") -> ModuleImage:
    """The image of the module at `address`: system parameters and the given programs (others None)."""
    where = f"bus {link.bus}, module {address}" + (f" ({name})" if name else "")
    slots: list[Program | None] = [None] * PROGRAM_COUNT
    wanted = set(programs)
    system = None
    for message in read_messages(wanted):
        reply = link.request(address, message)
        if isinstance(reply, int):
            raise ReadBackError(f"{where}: read {message.ID:02X}h refused with {describe(reply)} — {remedy(reply)}")
        if isinstance(reply, codec.SystemReply):
            if reply.address != address:
                raise ReadBackError(
                    f"{where}: the module answering at address {address} reports S9 = {reply.address} — "
                    "check the module's Address Init and the plant file's address"
                )
            system = reply.system
        else:
            for offset, program in enumerate(reply.programs):
                if reply.first + offset in wanted:
                    slots[reply.first + offset - 1] = program
    assert system is not None
    return ModuleImage(address=address, system=system, programs=tuple(slots))


@dataclass(frozen=True, slots=True)
class Target:
    """A module to read: where it is, what it is called, which programs."""

    bus: str
    address: int
    name: str
    programs: tuple[int, ...]


def read_all(
    targets: Iterable[Target],
    links: dict[str, Link],
    *,
    progress: Callable[[], None] | None = None,
) -> dict[tuple[str, int], ModuleImage]:
    """Read every target, buses in parallel, the modules of one bus one after another.

    `progress()` is called after each module. The first error on a bus stops that bus; the
    errors of all buses are raised together (one line each) once every bus has finished.
    """
    per_bus: dict[str, list[Target]] = {}
    for target in targets:
        per_bus.setdefault(target.bus, []).append(target)

    def read_bus(bus_targets: list[Target]) -> dict[tuple[str, int], ModuleImage]:
        images = {}
        for t in bus_targets:
            images[(t.bus, t.address)] = read_module(links[t.bus], t.address, t.programs, name=t.name)
            if progress:
                progress()
        return images

    result: dict[tuple[str, int], ModuleImage] = {}
    errors = []
    with ThreadPoolExecutor(max_workers=max(1, len(per_bus))) as pool:
        for future in [pool.submit(read_bus, bus_targets) for bus_targets in per_bus.values()]:
            try:
                result.update(future.result())
            except UserError as error:
                errors.append(str(error))
    if errors:
        raise UserError("\n".join(errors))
    return result
