"""A candidate plan as decisions, and the messages those decisions make, in the order they are sent.

A `Layout` says, per program, how it is initialised (`problem` init kinds) and, in
`Writes`, how the remaining differences are written: a whole program (21h), P and V of
consecutive programs (33h, or 32h for one), one field of many programs (40h..45h), link
and unlink ranges (30h/31h) and jump addresses (46h). The values written are always the
desired ones. Program sets are bit masks over indices 0..63.

Order of the messages: inits before the system step (over programs initialised again after
it, where that saves: `init_runs`), the system step, inits after it, link/unlink ranges,
21h, 33h/32h, 40h..45h, 46h; within a kind by program number. Each later kind may overwrite
what an earlier one left (a 21h after a link range, a 46h after it), never the other way round.

Owns turning decisions into messages. Does not own choosing them (`prc3cfg.core.planner.init_search`).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from prc3cfg.core import codec
from prc3cfg.core.image import PROGRAM_COUNT, PROGRAM_FIELDS
from prc3cfg.core.planner.problem import INIT_AFTER, INIT_BEFORE, PlanningProblem

#: The fields 40h..45h write, in message order.
ITEM_FIELDS = PROGRAM_FIELDS[:-1]


def members(mask: int) -> Iterator[int]:
    """The indices in a bit mask, ascending."""
    while mask:
        low = mask & -mask
        yield low.bit_length() - 1
        mask ^= low


def runs_of(kinds: tuple[int, ...], kind: int) -> list[tuple[int, int]]:
    """Maximal runs (first, last index) of consecutive programs of init kind `kind`."""
    runs: list[tuple[int, int]] = []
    for i, k in enumerate(kinds):
        if k != kind:
            continue
        if runs and runs[-1][1] == i - 1:
            runs[-1] = (runs[-1][0], i)
        else:
            runs.append((i, i))
    return runs


def init_runs(kinds: tuple[int, ...], kind: int) -> list[tuple[int, int]]:
    """The runs (first, last index) the init messages of `kind` cover. An INIT_BEFORE run also
    covers the INIT_AFTER programs between it and the next one, or up to program 64: they are
    initialised again after the system step, and one message instead of two, or a 13h instead of a
    14h, is cheaper (whatever the framing stuffs: one byte less or a whole message less)."""
    runs = runs_of(kinds, kind)
    if kind != INIT_BEFORE or not runs:
        return runs
    joined = [runs[0]]
    for first, last in runs[1:]:
        if all(k == INIT_AFTER for k in kinds[joined[-1][1] + 1 : first]):
            joined[-1] = (joined[-1][0], last)
        else:
            joined.append((first, last))
    if all(k == INIT_AFTER for k in kinds[joined[-1][1] + 1 :]):
        joined[-1] = (joined[-1][0], PROGRAM_COUNT - 1)
    return joined


def init_message(first: int, last: int) -> codec.Message:
    """The cheapest init of programs first..last (indices): 11h, 12h, 13h or 14h."""
    if first == last:
        return codec.InitProgram(first + 1)
    if last == PROGRAM_COUNT - 1:
        return codec.InitAllPrograms() if first == 0 else codec.InitProgramsFrom(first + 1)
    return codec.InitPrograms(first + 1, last + 1)


@dataclass(frozen=True, slots=True)
class Writes:
    """The write phase of a plan (everything after the inits)."""

    whole: int  # 21h
    part_runs: tuple[tuple[int, int], ...]  # 33h/32h, first and last index
    items: tuple[int, ...]  # per field of ITEM_FIELDS, the programs written by 40h..45h
    ranges: tuple[tuple[bool, int, int], ...]  # (link?, first, last index): 30h / 31h
    addresses: int  # 46h
    estimate: float  # the write phase's price by `Prices`


@dataclass(frozen=True, slots=True)
class Layout:
    kinds: tuple[int, ...]  # init kind per program
    writes: Writes
    estimate: float  # the whole plan's price by `Prices`

    def messages(self, problem: PlanningProblem) -> list[codec.Message]:
        desired = problem.desired.known  # the programs written are managed: known
        w = self.writes
        out = [init_message(a, b) for a, b in init_runs(self.kinds, INIT_BEFORE)]
        if problem.system_step is not None:
            out.append(problem.system_step)
        out += [init_message(a, b) for a, b in init_runs(self.kinds, INIT_AFTER)]
        out += [
            (codec.LinkPrograms if link else codec.UnlinkPrograms)(first + 1, last + 1)
            for link, first, last in w.ranges
        ]
        out += [codec.WriteProgram(i + 1, desired(i + 1)) for i in members(w.whole)]
        for first, last in w.part_runs:
            if first == last:
                out.append(codec.WritePartProgram(first + 1, desired(first + 1).P, desired(first + 1).V))
            else:
                pairs = tuple((desired(i + 1).P, desired(i + 1).V) for i in range(first, last + 1))
                out.append(codec.WritePartPrograms(first + 1, pairs))
        for name, mask in zip(ITEM_FIELDS, w.items):
            items = [(i + 1, getattr(desired(i + 1), name)) for i in members(mask)]
            out += _chunked(codec.FIELD_MESSAGES[name], items, codec.FIELD_KINDS[name].capacity)
        items = [(i + 1, desired(i + 1).A) for i in members(w.addresses)]
        out += _chunked(codec.WriteAddresses, items, codec.FIELD_KINDS["A"].capacity)
        return out


def _chunked(cls: type, items: list[tuple[int, int]], size: int) -> list[codec.Message]:
    return [cls(tuple(items[k : k + size])) for k in range(0, len(items), size)]
