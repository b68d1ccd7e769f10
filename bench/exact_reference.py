"""The exact reference: the cheapest plan of one module in the canonical message order, by an integer
programme (scipy's HiGHS), rebuilt as messages and replayed on the device model.

    reference = exact_plan(actual, desired, cost)   # raises when its plan does not replay to `desired`

The planner is judged against this, not against a relaxation: a bound (`plan_bench.Relaxation`) sits
below the plans it models, so a plan above it may be anywhere in between, and it is only as good as the
moves it models. The bench showed full rewrites "at R's optimum" while the planner missed a move R
misses too (issue 29: four programs written whole so that 60 others fit four messages of each field, not
five).

The plans it chooses from: the canonical order of a module's plan —

    inits before the system step · the system step · inits · link/unlink ranges · 21h · 32h/33h · 40h..45h ·
    46h

- the system step: none when the system parameters match, else a 20h of the desired ones, or a 10h where
  those are the factory defaults (each option is tried; the cheapest wins);
- inits (11h..14h): any runs of managed programs, on either side of the system step (a run before it
  initialises a program to the defaults of the old parameters, then clamped by the new ones; one after,
  to the new ones' defaults). A program initialised on both sides holds the later init's defaults. A run
  costs its cheapest message (11h, 12h, 13h or 14h, each priced by the line);
- link (30h) and unlink (31h) ranges of managed programs, in two layers: outer ranges, and inner ranges
  sent after them, each inside an outer range of the other kind (a link range inside an unlink range,
  or an unlink range inside a link range). Plan_bench's relaxation argues that any sequence of ranges
  can be redrawn so, with no more ranges and the same addresses;
- writes of desired values: 21h (a whole program), 32h/33h (P and V of 1..15 consecutive managed
  programs), 40h..45h (one field of up to 15 programs), 46h (addresses of up to 31 programs). They write
  desired values only, so their order among themselves does not matter.

What each message does is the device model's (`prc3cfg.core.device`): the bases — a program after the
system step, with no init, with an init after it or an init before it — come from running 10h/20h and
11h on the model, never from a copy of its rules; link ranges set A(i) = i + 1 but on the last program
of the range (0), unlink ranges 0 (docs/protocol.md "Messages"), which the replay checks.

The programme: init runs and link/unlink ranges as columns per program (covered, a run starts, a run
ends: `_Programme._segments`); a binary column per 21h and per 32h/33h run; binary items and integer
message counts for 40h..46h (`n items ≤ 15 m`, 31 for 46h). Every field of a managed program that its
base (by its init) or, for A, its ranges leave different from the desired value must be written by a
message that carries it. The objective is the bus time. Every message whose content the programme fixes
(inits, ranges, 21h, 32h/33h, the system step) is priced by `LineCost.message_time` of that message:
framing overhead, stx stuffing of every byte (its checksum too), reply, turnaround, open-driver gaps. A
40h..46h message costs its header — priced by the line on a one-item message — and its items, each the
line's character time per byte it adds (on stx, with the stuffed bytes of its own values). That is exact
but for one byte the line adds where a stx message's checksum is 7Eh: the programme's optimum is a lower
bound (`bound`), the rebuilt plan's bus time an upper one (`bus_time`), equal on crc16 and open-driver
(asserted); on stx the items are regrouped to avoid a stuffed checksum where another grouping can.
HiGHS proves the optimum to a gap of 0: no tolerance.

The plan is then rebuilt as messages and replayed on the device model from the read-back: every
message accepted, the desired system and managed programs reached, no unmanaged program touched
(`replay`). A reference whose plan did not replay would be no reference.

What it takes: a fraction of a second for most changes, a few seconds for every field of 64 programs,
some 20 to 35 seconds (CPU) for the bench's full rewrite, where the relaxation of the 33h runs is weakest.

scipy is a bench-only dependency (`pip install -e '.[bench]'`): the planner itself never solves an
integer programme.
"""

from __future__ import annotations

import math
import random
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
from scipy.optimize import Bounds, LinearConstraint, milp
from scipy.sparse import coo_array

from prc3cfg.core import codec, device
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.framing.stx import START
from prc3cfg.core.image import DEFAULT_SYSTEM, PROGRAM_COUNT, PROGRAM_FIELDS, ModuleImage, default_program

#: The fields 40h..45h write, in message order; A is written by 46h.
ITEM_FIELDS = PROGRAM_FIELDS[:-1]
PV = ("P", "V")
ITEM_MESSAGES: dict[str, type[codec.Message]] = {**codec.FIELD_MESSAGES, "A": codec.WriteAddresses}
CAPACITY = {**dict.fromkeys(ITEM_FIELDS, codec.MAX_FIELD_ITEMS), "A": codec.MAX_ADDRESS_ITEMS}
#: Init kinds: not initialised, initialised before the system step, after it (or with no system step).
KEEP, BEFORE, AFTER = "keep", "before", "after"
#: Groupings of a field's items tried to avoid a stx checksum of 7Eh (`_grouped`).
REGROUPINGS = 64
#: Seconds below which two bus times are the same (sums of floats).
EPSILON = 1e-9


@dataclass(frozen=True, slots=True)
class ReferencePlan:
    """The exact reference of one module: its messages in the order sent, their bus time by the line,
    and the integer programme's optimum (a lower bound on every plan in the canonical order)."""

    messages: tuple[codec.Message, ...]
    bus_time: float
    bound: float


def exact_plan(actual: ModuleImage, desired: ModuleImage, cost: LineCost, *,
               time_limit: float = 600.0) -> ReferencePlan:
    """The cheapest plan in the canonical order from `actual` (the read-back; `None`: not read) to
    `desired` (`None`: unmanaged), replayed on the device model (AssertionError if it does not reach
    `desired`). `time_limit`: seconds HiGHS may take per system step option (RuntimeError beyond)."""
    start = _start(actual)
    plans = []
    for step in _system_steps(actual, desired, start, cost):
        plans.append(_Programme(start, desired, step, cost).solve(time_limit))
        replay(actual, desired, plans[-1].messages)
    best = min(plans, key=lambda plan: plan.bus_time)
    return replace(best, bound=min(plan.bound for plan in plans))


def replay(actual: ModuleImage, desired: ModuleImage,
           messages: Iterable[codec.Message]) -> device.ModuleState:
    """Run `messages` on the device model from the read-back; assert each is accepted, none touches an
    unmanaged program, and the desired system and managed programs result. The final state."""
    state = _start(actual)
    managed = {n for n, p in enumerate(desired.programs, start=1) if p is not None}
    for message in messages:
        assert set(message.touched_programs()) <= managed, f"{message.hex()} touches an unmanaged program"
        assert codec.decode_message(message.encode()) == message, message
        state = device.execute(state, message)  # codec.Rejected: the module would refuse it
    assert state.image.system == desired.system, "the replay ends with other system parameters"
    for number, (got, want) in enumerate(zip(state.image.programs, desired.programs), start=1):
        assert want is None or got == want, f"program {number}: the replay gives {got}, not {want}"
    return state


def _start(actual: ModuleImage) -> device.ModuleState:
    """The read-back as a module: programs not read hold their defaults (they are never written)."""
    filler = default_program(actual.system)
    return device.ModuleState(replace(actual, programs=tuple(filler if p is None else p
                                                             for p in actual.programs)))


def _system_steps(actual: ModuleImage, desired: ModuleImage, start: device.ModuleState,
                  cost: LineCost) -> list[codec.Message | None]:
    """Every system step that gives the desired system parameters: none when they match; else 20h of
    them, and 10h where they are the factory defaults — of steps that leave the same module (on its
    programs as read, and as an init leaves them), the cheapest only."""
    if actual.system == desired.system:
        return [None]
    steps: list[codec.Message] = [codec.WriteSystem(desired.system)]
    if desired.system == DEFAULT_SYSTEM:
        steps.append(codec.InitSystem())
    initialised = device.execute(start, codec.InitAllPrograms())
    effects = {}
    for step in sorted(steps, key=lambda step: cost.message_time(desired.address, step)):
        effects.setdefault((device.execute(start, step), device.execute(initialised, step)), step)
    return list(effects.values())


def _runs(managed: list[bool], longest: int = PROGRAM_COUNT) -> list[tuple[int, int]]:
    """Every run first..last (program numbers) of consecutive managed programs, at most `longest` long."""
    out = []
    for first in range(1, PROGRAM_COUNT + 1):
        last = first
        while last <= PROGRAM_COUNT and managed[last - 1] and last - first < longest:
            out.append((first, last))
            last += 1
    return out


def _init_messages(first: int, last: int) -> list[codec.Message]:
    """Every init message that initialises exactly programs first..last."""
    out: list[codec.Message] = [codec.InitPrograms(first, last)]
    if first == last:
        out.append(codec.InitProgram(first))
    if last == PROGRAM_COUNT:
        out.append(codec.InitProgramsFrom(first))
        if first == 1:
            out.append(codec.InitAllPrograms())
    return out


def _parts_message(first: int, last: int, desired: ModuleImage) -> codec.Message:
    """P and V of programs first..last: a 32h for one program, a 33h for more."""
    if first == last:
        program = desired.known(first)
        return codec.WritePartProgram(first, program.P, program.V)
    return codec.WritePartPrograms(first, tuple((desired.known(n).P, desired.known(n).V)
                                                for n in range(first, last + 1)))


class _Segments(NamedTuple):
    """Runs of consecutive managed programs, each sent as one message: the programme's columns per
    program — covered by a run, a run starts here, a run ends here — and the message of each run."""

    on: dict[int, int]
    start: dict[int, int]
    end: dict[int, int]
    message: Callable[[int, int], codec.Message]

    def chosen(self, x: np.ndarray) -> list[codec.Message]:
        """The messages of the runs a solution `x` draws, by their first program."""
        out, first = [], 0
        for n in sorted(self.on):
            if x[self.start[n]] > 0.5:
                first = n
            if x[self.end[n]] > 0.5:
                out.append(self.message(first, n))
        return out


class _Programme:
    """The integer programme of one module and one system step (module docstring).

    Init runs and link/unlink ranges are runs of consecutive programs: each is written as columns per
    program (covered, starts, ends), not as a column per run — a column per run (2,080 of them per
    kind of run) made the programme ten times larger and HiGHS twenty times slower. A run costs the
    price most runs of its kind have (a 14h, a 30h, a 31h), put on its start; the runs whose message
    costs otherwise (a 12h of one program, a 13h or 11h to program 64, a stx checksum of 7Eh) get a
    column of the difference that the constraints tie to that run being drawn (`_segments`).
    """

    def __init__(self, start: device.ModuleState, desired: ModuleImage, step: codec.Message | None,
                 cost: LineCost) -> None:
        self.desired, self.step, self.cost = desired, step, cost
        self.address = desired.address
        self.managed = [p is not None for p in desired.programs]
        self.numbers = [n for n in range(1, PROGRAM_COUNT + 1) if self.managed[n - 1]]
        self.wanted = {n: desired.known(n) for n in self.numbers}
        after_step = start if step is None else device.execute(start, step)
        init_all = codec.InitAllPrograms()
        self.bases = {KEEP: after_step.image.complete(),
                      AFTER: device.execute(after_step, init_all).image.complete()}
        before = device.execute(start, init_all)
        before = (before if step is None else device.execute(before, step)).image.complete()
        if before != self.bases[AFTER]:
            self.bases[BEFORE] = before
        self.fixed = 0.0 if step is None else self.price(step)
        # the columns: cost, integrality, upper bound; the rows: (terms, lower, upper)
        self.costs: list[float] = []
        self.integral: list[int] = []
        self.upper: list[float] = []
        self.rows: list[tuple[dict[int, float], float, float]] = []
        self._build()

    # -- prices -------------------------------------------------------------------------------

    def price(self, message: codec.Message) -> float:
        return self.cost.message_time(self.address, message)

    def _item_prices(self, name: str) -> tuple[float, float]:
        """A 40h..46h message of field `name`: the header's price (priced by the line on one-item
        messages: the least of two whose checksums differ, so that no stuffed checksum is counted) and
        the line's character time per byte of an item."""
        cls = ITEM_MESSAGES[name]
        item_bytes = cls(((1, 0), (1, 0))).size() - cls(((1, 0),)).size()
        byte = self.cost.line.char_time
        header = min(self.price(cls(((1, value),))) for value in (0, 1)) - byte * item_bytes
        return header, byte

    def _item_bytes(self, name: str, number: int, value: int) -> int:
        """Bytes one item adds to a message on the line: its own, and those the framing stuffs
        into them (stx: a 00h after each 7Eh)."""
        cls = ITEM_MESSAGES[name]
        data = cls(((number, value),)).encode()[2 * cls.HEADER_WORDS :]
        return len(data) + (data.count(START) if self.cost.framing.stuffs else 0)

    # -- building the programme ---------------------------------------------------------------

    def column(self, cost: float, *, integral: bool = True, upper: float = 1.0) -> int:
        self.costs.append(cost)
        self.integral.append(int(integral))
        self.upper.append(upper)
        return len(self.costs) - 1

    def row(self, terms: dict[int, float], lower: float, upper: float) -> None:
        self.rows.append((terms, lower, upper))

    def _segments(self, message: Callable[[int, int], codec.Message], *, separate: bool) -> _Segments:
        """Runs of managed programs, one `message(first, last)` each. `separate` (link ranges): runs may
        touch, each ends where its column says; otherwise (inits, unlink ranges) touching runs are one
        run — one message always costs less than two."""
        on, start, end = {}, {}, {}
        for n in self.numbers:
            on[n] = self.column(0.0)
            start[n] = self.column(0.0, integral=separate)
            end[n] = self.column(0.0, integral=separate)
            self.row({start[n]: 1.0, on[n]: -1.0}, -np.inf, 0.0)
            self.row({end[n]: 1.0, on[n]: -1.0}, -np.inf, 0.0)
        for n in self.numbers:
            before, after = on.get(n - 1), on.get(n + 1)
            if separate:
                if before is None:
                    self.row({on[n]: 1.0, start[n]: -1.0}, 0.0, 0.0)
                if after is None:
                    self.row({on[n]: 1.0, end[n]: -1.0}, 0.0, 0.0)
                else:  # what goes on past n is what is on at n+1 and did not start there
                    self.row({on[n]: 1.0, end[n]: -1.0, after: -1.0, start[n + 1]: 1.0}, 0.0, 0.0)
            else:  # starts and ends exactly where `on` changes
                self.row({on[n]: 1.0, start[n]: -1.0, **({before: -1.0} if before is not None else {})},
                         -np.inf, 0.0)
                self.row({on[n]: 1.0, end[n]: -1.0, **({after: -1.0} if after is not None else {})}, -np.inf,
                         0.0)
                if before is not None:
                    self.row({start[n]: 1.0, before: 1.0}, -np.inf, 1.0)
                if after is not None:
                    self.row({end[n]: 1.0, after: 1.0}, -np.inf, 1.0)
        prices = {run: self.price(message(*run)) for run in _runs(self.managed)}
        if not prices:  # no program is managed: no run to initialise, link or unlink
            return _Segments(on, start, end, message)
        common = Counter(round(p, 12) for p in prices.values()).most_common(1)[0][0]
        for n in self.numbers:
            self.costs[start[n]] = common
        for (first, last), price in prices.items():
            extra = price - common
            if abs(extra) < EPSILON:
                continue
            between = {end[j]: 1.0 for j in range(first, last)}
            drawn = self.column(extra, integral=False)
            if extra > 0:  # forced up where the run first..last is drawn
                self.row({start[first]: 1.0, end[last]: 1.0, **_minus(between), drawn: -1.0}, -np.inf, 1.0)
            else:  # held down where it is not: no start at first, no end at last, or an end between
                self.row({drawn: 1.0, start[first]: -1.0}, -np.inf, 0.0)
                self.row({drawn: 1.0, end[last]: -1.0}, -np.inf, 0.0)
                for column in between:
                    self.row({drawn: 1.0, column: 1.0}, -np.inf, 1.0)
        return _Segments(on, start, end, message)

    def _cover(self, columns: dict[tuple[int, int], int]) -> dict[int, int]:
        """A continuous column per program equal to the number of `columns` (runs first..last) over it."""
        out = {}
        for n in self.numbers:
            terms = {j: 1.0 for (first, last), j in columns.items() if first <= n <= last}
            if terms:
                aux = out[n] = self.column(0.0, integral=False, upper=np.inf)
                self.row({**terms, aux: -1.0}, 0.0, 0.0)
        return out

    def _build(self) -> None:
        bases, numbers, wanted = self.bases, self.numbers, self.wanted
        differs = {kind: {n: {name: getattr(base[n - 1], name) != getattr(wanted[n], name)
                              for name in PROGRAM_FIELDS}
                          for n in numbers} for kind, base in bases.items()}
        # inits, per side of the system step; the kind of each program: AFTER where a run after covers
        # it, else BEFORE where one before does, else KEEP
        self.inits = {kind: self._segments(lambda a, b: min(_init_messages(a, b), key=self.price),
                                           separate=False)
                      for kind in (BEFORE, AFTER) if kind in bases}
        kind_of: dict[str, dict[int, int]] = {KEEP: {}, AFTER: self.inits[AFTER].on}
        for n in numbers:
            keep = kind_of[KEEP][n] = self.column(0.0, integral=False)
            initialised = self.inits[AFTER].on[n]
            if BEFORE not in bases:
                self.row({keep: 1.0, initialised: 1.0}, 1.0, 1.0)
                continue
            before, covered = self.column(0.0, integral=False), self.inits[BEFORE].on[n]
            kind_of.setdefault(BEFORE, {})[n] = before
            self.row({keep: 1.0, before: 1.0, initialised: 1.0}, 1.0, 1.0)
            self.row({before: 1.0, covered: -1.0}, -np.inf, 0.0)
            self.row({keep: 1.0, covered: 1.0}, -np.inf, 1.0)
        self.kind_of = kind_of

        def left(n: int, name: str) -> dict[int, float]:
            """The kinds of program n whose base differs from the desired program in field `name`."""
            return {kind_of[kind][n]: 1.0 for kind in bases if differs[kind][n][name]}

        self.whole = {n: self.column(self.price(codec.WriteProgram(n, wanted[n]))) for n in numbers}
        self.parts: dict[tuple[int, int], int] = {}
        if any(left(n, name) for n in numbers for name in PV):
            for first, last in _runs(self.managed, codec.MAX_FIELD_ITEMS):
                self.parts[(first, last)] = self.column(self.price(_parts_message(first, last, self.desired)))
        parts_over = self._cover(self.parts)
        for columns in (self.whole.values(), self.parts.values()):  # message counts: for HiGHS to branch on
            if columns:
                count = self.column(0.0, upper=PROGRAM_COUNT)
                self.row({**dict.fromkeys(columns, 1.0), count: -1.0}, 0.0, 0.0)
        self.items: dict[str, dict[int, int]] = {}
        self.counts: dict[str, int] = {}
        for name in PROGRAM_FIELDS:
            header, byte = self._item_prices(name)
            self.items[name] = {n: self.column(byte * self._item_bytes(name, n, getattr(wanted[n], name)))
                                for n in numbers}
            count = self.counts[name] = self.column(header, upper=math.ceil(PROGRAM_COUNT / CAPACITY[name]))
            self.row({**dict.fromkeys(self.items[name].values(), 1.0), count: -CAPACITY[name]}, -np.inf, 0.0)
            for item in self.items[name].values():  # an item needs a message (implied, but not by the LP)
                self.row({item: 1.0, count: -1.0}, -np.inf, 0.0)
        for n in numbers:  # every difference in P..F2 is written
            for name in ITEM_FIELDS:
                writers = {self.whole[n]: -1.0, self.items[name][n]: -1.0}
                if name in PV and n in parts_over:
                    writers[parts_over[n]] = -1.0
                if left(n, name):
                    self.row({**left(n, name), **writers}, -np.inf, 0.0)
        self.ranges: dict[tuple[bool, int], _Segments] = {}
        # else every address is right, whatever the inits: no range helps
        if any(left(n, "A") for n in numbers):
            self._addresses(left)

    def _addresses(self, left: Callable[[int, str], dict[int, float]]) -> None:
        """The jump addresses: link/unlink ranges in two layers, then a 46h item or a 21h where wrong."""
        for layer in (1, 2):
            self.ranges[(True, layer)] = self._segments(codec.LinkPrograms, separate=True)
            self.ranges[(False, layer)] = self._segments(codec.UnlinkPrograms, separate=False)
        links, unlinks = ({layer: self.ranges[(link, layer)] for layer in (1, 2)} for link in (True, False))
        for n in self.numbers:
            l1, u1, l2, u2 = links[1], unlinks[1], links[2], unlinks[2]
            # an inner link range lies inside an outer unlink range, an inner unlink inside an outer
            # link range and short of its end (which shows 0 either way)
            self.row({l1.on[n]: 1.0, u1.on[n]: 1.0}, -np.inf, 1.0)
            self.row({l2.on[n]: 1.0, u1.on[n]: -1.0}, -np.inf, 0.0)
            self.row({u2.on[n]: 1.0, l1.on[n]: -1.0}, -np.inf, 0.0)
            self.row({u2.on[n]: 1.0, l1.end[n]: 1.0}, -np.inf, 1.0)
            # what n shows, one of three: the next program (a link range goes on past n), 0 (a link
            # range ends at n, or an unlink range covers it), or, under no range, its base's address
            shows = {
                n + 1: _add(
                    {l1.on[n]: 1.0, l1.end[n]: -1.0, u2.on[n]: -1.0}, {l2.on[n]: 1.0, l2.end[n]: -1.0}
                ),
                0: _add({l1.end[n]: 1.0, u2.on[n]: 1.0, u1.on[n]: 1.0, l2.on[n]: -1.0}, {l2.end[n]: 1.0}),
            }
            target = self.wanted[n].A
            wrong = self.column(0.0, integral=False)
            shown_wrong = _add(*(terms for value, terms in shows.items() if value != target), {wrong: -1.0})
            self.row(shown_wrong, -np.inf, 0.0)
            wrong_bases = {table[n]: 1.0 for kind, table in self.kind_of.items()
                           if self.bases[kind][n - 1].A != target}
            if wrong_bases:
                self.row(_add(shown_wrong, wrong_bases, {l1.on[n]: -1.0, u1.on[n]: -1.0}), -np.inf, 0.0)
            self.row({wrong: 1.0, self.whole[n]: -1.0, self.items["A"][n]: -1.0}, -np.inf, 0.0)

    # -- solving and rebuilding ---------------------------------------------------------------

    def solve(self, time_limit: float) -> ReferencePlan:
        size = len(self.costs)
        data, rows, cols = [], [], []
        for r, (terms, _, _) in enumerate(self.rows):
            for j, value in terms.items():
                rows.append(r)
                cols.append(j)
                data.append(value)
        matrix = coo_array((data, (rows, cols)), shape=(len(self.rows), size)).tocsr()
        result = milp(
            np.array(self.costs), integrality=np.array(self.integral),
                      bounds=Bounds(np.zeros(size), np.array(self.upper)),
            constraints=LinearConstraint(matrix, [r[1] for r in self.rows], [r[2] for r in self.rows]),
            options={"time_limit": time_limit, "mip_rel_gap": 0.0},
        )
        if result.status != 0:
            raise RuntimeError(f"module {self.address}: HiGHS did not prove an optimum: {result.message}")
        messages = self._messages(result.x)
        plan = ReferencePlan(tuple(messages), math.fsum(map(self.price, messages)), self.fixed
                             + float(result.fun))
        # the programme prices every message exactly but for a stx checksum of 7Eh in 40h..46h
        slack = (0.0 if not self.cost.framing.stuffs
                 else self.cost.line.char_time * sum(m.ID >= codec.WritePositions.ID for m in messages))
        assert plan.bound - EPSILON <= plan.bus_time <= plan.bound + slack + EPSILON, (plan.bound,
                                                                                       plan.bus_time)
        return plan

    def _messages(self, x: np.ndarray) -> list[codec.Message]:
        """The messages of a solution `x`, in the canonical order."""
        out = self.inits[BEFORE].chosen(x) if BEFORE in self.inits else []
        out += [] if self.step is None else [self.step]
        out += self.inits[AFTER].chosen(x)
        for layer in (1, 2):
            for link in (True, False):
                out += self.ranges[(link, layer)].chosen(x) if self.ranges else []
        out += [codec.WriteProgram(n, self.wanted[n]) for n, j in self.whole.items() if x[j] > 0.5]
        out += [_parts_message(first, last, self.desired)
                for (first, last), j in sorted(self.parts.items()) if x[j] > 0.5]
        for name in PROGRAM_FIELDS:
            out += self._grouped(name, [(n, getattr(self.wanted[n], name))
                                        for n, j in self.items[name].items() if x[j] > 0.5])
        return out

    def _grouped(self, name: str, items: list[tuple[int, int]]) -> list[codec.Message]:
        """`items` of one field in as few messages as the limit allows; on a framing that stuffs, the
        cheapest of a few groupings (a checksum of 7Eh costs a byte)."""
        if not items:
            return []
        cls, capacity = ITEM_MESSAGES[name], CAPACITY[name]
        count = math.ceil(len(items) / capacity)

        def grouped(order: list[tuple[int, int]], share: int) -> list[codec.Message]:
            return [cls(tuple(sorted(order[k : k + share]))) for k in range(0, len(order), share)]

        best = grouped(items, capacity)  # full messages in program order, as the planner groups them
        if self.cost.framing.stuffs and count > 1:
            shuffler, order = random.Random(0), list(items)  # the same groupings every run
            for _ in range(REGROUPINGS):
                candidate = grouped(order, math.ceil(len(items) / count))
                shuffler.shuffle(order)
                if math.fsum(map(self.price, candidate)) < math.fsum(map(self.price, best)) - EPSILON:
                    best = candidate
        return best


def _minus(terms: dict[int, float]) -> dict[int, float]:
    return {j: -value for j, value in terms.items()}


def _add(*parts: dict[int, float]) -> dict[int, float]:
    out: dict[int, float] = {}
    for part in parts:
        for j, value in part.items():
            out[j] = out.get(j, 0.0) + value
    return out
