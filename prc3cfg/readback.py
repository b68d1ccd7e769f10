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


def read_plant(
    plant,
    links: dict[str, Link],
    *,
    modules: Iterable[tuple[str, int]] | None = None,
    progress: Callable[[str, int], None] | None = None,
) -> dict[tuple[str, int], ModuleImage]:
    """Read every module (or the given (bus, address) pairs) of `plant`; buses in parallel.

    `progress(bus, address)` is called after each module. The first error on a bus stops that
    bus and is raised once every bus has finished.
    """
    chosen = None if modules is None else set(modules)

    def read_bus(bus) -> dict[tuple[str, int], ModuleImage]:
        images = {}
        for module in bus.modules:
            if chosen is not None and (bus.name, module.address) not in chosen:
                continue
            image = read_module(links[bus.name], module.address, module.managed_programs(), name=module.name)
            images[(bus.name, module.address)] = image
            if progress:
                progress(bus.name, module.address)
        return images

    result: dict[tuple[str, int], ModuleImage] = {}
    with ThreadPoolExecutor(max_workers=max(1, len(plant.buses))) as pool:
        futures = [pool.submit(read_bus, bus) for bus in plant.buses]
        errors = []
        for future in futures:
            try:
                result.update(future.result())
            except UserError as error:
                errors.append(str(error))
    if errors:
        raise UserError("\n".join(errors) if len(errors) > 1 else errors[0])
    return result
