"""Read-back: what every module holds, in the fewest exchanges.

A module image is one 50h (system parameters, S9) and, for the programs a `Target` names, the
fewest 52h/51h reads (`prc3cfg.core.what_to_read.read_messages`): a fully managed module
takes 1 + 16 exchanges.

What to read is decided in `prc3cfg.core.what_to_read`, also where a read widens on what it finds:
when the system parameters a plan will write can clamp programs (a lower S1 or S4, a higher S5:
docs/protocol.md "What a module does"), every program is read, not only the managed ones — the module's own
clamping reaches programs the plant does not manage, and what it does to them must be shown in
the plan and kept in the snapshot (`after_system`); and what contradicts the line's record is
read in full (`after_programs`) — with every other module of its line, those read before it again
for the rest (`opens_line`). This module only reads.

On a line where nothing protects a data reply (`what_to_read.protects_replies`: open-driver, and no
parity the port checks) a reply is believed once it agrees with another observation (`_confirmed`): what
an independent source said the module holds — the line's record, or what a verified write put there — or
else the next reply to the same read. A flipped bit is never believed once: to pass, it would have to turn
what the module holds into exactly what the other observation says, which is as likely as two damaged
replies that agree. A read whose reply is as expected costs one exchange; any other, one more at least.

S9 must equal the configured address, else the wiring or the plant file is wrong.
Buses are read in parallel (one thread per line), the modules of one line one after
another (the line is half duplex).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING, TypeVar

from prc3cfg.core import codec, what_to_read
from prc3cfg.core.error_codes import describe, remedy
from prc3cfg.core.image import PROGRAM_COUNT, ModuleImage, Program, SystemParameters
from prc3cfg.core.what_to_read import CONFIRMATIONS, Target, protects_replies, read_messages
from prc3cfg.errors import Interrupted, UserError
from prc3cfg.shell import platform
from prc3cfg.shell.cancel import main_thread_only

if TYPE_CHECKING:
    from prc3cfg.shell.link.client import Link

#: Called with a bus and its modules' images as soon as the bus is read (`read_all`'s `then`).
LineRead = Callable[[str, dict[tuple[str, int], ModuleImage]], None]


class ReadBackError(UserError):
    """A module answered a read with an error code, or is not the module the plant says."""


class LinesFailed(UserError):
    """The read-back (or what `read_all` ran after it) failed on some lines: one line each, by bus."""

    def __init__(self, failed: dict[str, str]) -> None:
        super().__init__("\n".join(failed.values()))
        self.failed = failed


def read_module(
    link: Link, address: int, programs: Iterable[int], *, name: str = "",
                clamped_by: SystemParameters | None = None,
    known: ModuleImage | None = None, managed: Iterable[int] = (), fresh: bool = False,
) -> ModuleImage:
    """The image of the module at `address`: system parameters and the given programs (others None).

    With `clamped_by` (the system parameters a plan will write), every program is read when writing them can
    clamp programs on this module. With `known` (what the line's record says the module holds), what is read
    is evidence: a system block or a program other than the record's means the module was changed by another
    hand, and every `managed` program is read too — nothing of the record is taken then
    (`prc3cfg.core.what_to_read.after_system`, `after_programs`). With `fresh` (an apply's), the `managed`
    programs of a factory-fresh module are not read (`what_to_read.factory_fresh`).
    """
    expected = None if known is None else {n: p for n, p in enumerate(known.programs, start=1)
                                           if p is not None}
    system = read_system(link, address, name=name, expected=None if known is None else known.system)
    image = ModuleImage(address=address, system=system, programs=(None,) * PROGRAM_COUNT)
    first = what_to_read.after_system(system, programs, clamped_by, known, managed, fresh=fresh)
    image = image.with_programs(read_programs(link, address, first, name=name, expected=expected))
    return image.with_programs(read_programs(link, address,
                                             what_to_read.after_programs(image, known, managed), name=name,
                                             expected=expected))


Reply = TypeVar("Reply", codec.SystemReply, codec.ProgramsReply)


def _request(link: Link, address: int, message: codec.Message, name: str, kind: type[Reply],
             expected: Callable[[Reply], bool] | None = None) -> Reply:
    """The data block of a read, of `kind` (the reply `codec.decode_reply` gives to `message`) — confirmed
    where nothing protects it (`_confirmed`; `expected`: whether a reply is what another observation says)."""
    if protects_replies(link.framing.checked, link.line.parity, link.parity_checked):
        return _one(link, address, message, name, kind)
    return _confirmed(link, address, message, name, kind, expected)


def _confirmed(link: Link, address: int, message: codec.Message, name: str, kind: type[Reply],
               expected: Callable[[Reply], bool] | None) -> Reply:
    """The data block of a read as soon as it is what `expected` says (another observation: the record, or
    a verified write), else heard twice in a row, asking again up to `CONFIRMATIONS` times in all; a
    `LinkError` when no two replies in a row agree (the line damages more than it carries)."""
    # here: a command that opens no line (`plan --actual`) loads no link
    from prc3cfg.shell.link.client import LinkError

    heard = _one(link, address, message, name, kind)
    if expected is not None and expected(heard):
        return heard
    for _ in range(CONFIRMATIONS - 1):
        again = _one(link, address, message, name, kind)
        if again == heard:
            return again
        heard = again
    raise LinkError(f"bus {link.bus}, module {address}{f' ({name})' if name else ''}: no two replies in a "
                    f"row to {message.ID:02X}h "
                    f"agree in {CONFIRMATIONS} reads — the line damages what it carries (open-driver "
                    "without parity detects "
                    "nothing): check the cabling, or use parity on the line")


def _one(link: Link, address: int, message: codec.Message, name: str, kind: type[Reply]) -> Reply:
    """One data block of a read, as the link gives it."""
    reply = link.request(address, message)
    if isinstance(reply, int):
        where = f"bus {link.bus}, module {address}" + (f" ({name})" if name else "")
        raise ReadBackError(f"{where}: read {message.ID:02X}h refused with {describe(reply)} — "
                            f"{remedy(reply)}")
    if not isinstance(reply, kind):
        raise TypeError(f"a {type(reply).__name__} in reply to {message.ID:02X}h")
    return reply


def read_system(link: Link, address: int, *, name: str = "",
                expected: SystemParameters | None = None) -> SystemParameters:
    """One 50h: the system parameters; S9 must be `address`. `expected`: what another observation says they
    are."""

    def as_expected(reply: codec.SystemReply) -> bool:
        return reply.address == address and reply.system == expected

    reply = _request(link, address, codec.ReadSystem(), name, codec.SystemReply,
                     None if expected is None else as_expected)
    if reply.address != address:
        raise ReadBackError(
            f"bus {link.bus}, module {address}{f' ({name})' if name else ''}: the module answering "
            "at address "
            f"{address} reports S9 = {reply.address} — check the module's Address Init and the plant "
            "file's address"
        )
    return reply.system


def read_programs(link: Link, address: int, programs: Iterable[int], *, name: str = "",
                  expected: Mapping[int, Program] | None = None) -> dict[int, Program]:
    """The given programs, in the fewest 51h/52h exchanges (`read_messages`). `expected`: what another
    observation says some of them are."""
    wanted = set(programs)
    found: dict[int, Program] = {}

    def as_expected(reply: codec.ProgramsReply) -> bool:
        told = expected or {}
        return all(reply.first + offset not in wanted or told.get(reply.first + offset) == program
                   for offset, program in enumerate(reply.programs))

    for message in read_messages(wanted)[1:]:
        reply = _request(link, address, message, name, codec.ProgramsReply,
                         None if expected is None else as_expected)
        for offset, program in enumerate(reply.programs):
            if reply.first + offset in wanted:
                found[reply.first + offset] = program
    return found


def read_all(
    targets: Iterable[Target],
    links: dict[str, Link],
    *,
    progress: Callable[[], None] | None = None,
    each: Callable[[Target, ModuleImage], None] | None = None,
    then: LineRead | None = None,
) -> dict[tuple[str, int], ModuleImage]:
    """Read every target, buses in parallel, the modules of one bus one after another.

    `progress()` is called after each module; `each(target, image)` in the bus's thread as soon as
    a module is read (to plan it while the rest of its line is read); `then(bus, images)` as soon as
    the bus's modules are read (to plan the line, and write it, while other lines are still being
    read: it may take as long as it needs — the other buses go on). The first error
    on a bus stops that bus; the errors of all buses are raised together (one line each) once
    every bus has finished (`LinesFailed`); an interruption (Ctrl-C) wins over them.
    """
    per_bus: dict[str, list[Target]] = {}
    for target in targets:
        per_bus.setdefault(target.bus, []).append(target)

    def read_bus(bus_targets: list[Target]) -> dict[tuple[str, int], ModuleImage]:
        images = {}
        # a module contradicted the record: every module of the line is read
        # in full (`what_to_read.opens_line`)
        opened = False
        for index, t in enumerate(bus_targets):
            t = what_to_read.opened(t) if opened else t
            image = images[(t.bus, t.address)] = read_module(links[t.bus], t.address, t.programs, name=t.name,
                                                             clamped_by=t.clamped_by,
                                                             known=t.known, managed=t.managed, fresh=t.fresh)
            if not opened and what_to_read.opens_line(t, image) is not None:
                opened = True
                for earlier in bus_targets[:index]:  # read before the line opened: the rest of them now
                    key = (earlier.bus, earlier.address)
                    if more := what_to_read.still_to_read(earlier, images[key]):
                        programs = read_programs(links[t.bus], earlier.address, more, name=earlier.name)
                        images[key] = images[key].with_programs(programs)
                        if each is not None:
                            each(earlier, images[key])
            if progress:
                progress()
            if each is not None:
                each(t, image)
        if then is not None and bus_targets:
            then(bus_targets[0].bus, images)
        return images

    result: dict[tuple[str, int], ModuleImage] = {}
    errors: dict[str, str] = {}
    interrupted = False
    with ThreadPoolExecutor(max_workers=max(1, len(per_bus)), initializer=main_thread_only) as pool:
        futures = [(bus, pool.submit(read_bus, bus_targets)) for bus, bus_targets in per_bus.items()]
        for bus, future in futures:
            try:
                images = platform.result_of(future)
                result.update(images)
            except Interrupted:
                interrupted = True
            except UserError as error:
                errors[bus] = str(error)
    if interrupted:
        raise Interrupted()
    if errors:
        raise LinesFailed(errors)
    return result
