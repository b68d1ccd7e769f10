"""The planner on realistic plant changes: plan bus time against the exact optimum and the naive download.

    python bench/plan_bench.py [--profile crc16] [--profile stx] [--seeds 2] [--bound] [--modules 30]

For each scenario family (commissioning, full rewrites, partial rewrites, clamps, chains,
inits; `FAMILIES`) and line profile (9600 baud 8E1, turnaround 10 ms; crc16, open-driver with
a ZVZ of 100 ms and stx, or those named) it prints, per scenario, the plan's estimated bus time
and messages, the exact optimum's (bench/exact_reference.py: an integer programme solved by
HiGHS, its plan replayed on the device model; `pip install -e '.[bench]'` for scipy),
plan/exact, the naive download's bus time (20h if the system differs, one 21h per changed
program) and the planning CPU time; then per family and profile the plans' total over the
optima's and the worst scenario; then the worst scenario of all with both plans' messages.
`--bound` adds a lower bound R on the bus time of *any* plan (below). Last, it plans whole
plants — N modules × 64 programs, fully managed, each with one of the scenarios' changes
("mixed"), or each commissioned or changed a lot ("heavy") — from images saved as JSON, and
prints the total CPU time (acceptance: under 1 s for 30 modules).

The lower bound is the optimum of a relaxation R: a problem every plan maps into at no more than its bus time,
solved exactly, or bounded from below where the search below stops. A message of n bytes costs `exchange +
byte × n` (`Prices`, measured on the line's own `LineCost`; exact but for stx stuffing, which only adds bytes:
R counts the stuffed bytes of the values it writes, never a stuffed checksum). Every plan has the same system
step (a 10h for factory parameters, else a 20h; none if they match). Take any plan and look at each managed
program after its last init (before or after the system step, or none: the bases and difference masks of
`PlanningProblem`, predicted on the device model): every field that still differs from the plant file has a
last writer after that init, and R is what those last writers must cost:

- inits: the programs whose last init comes after the system step form runs, each at least
  one 11h..14h; those initialised before it (they may also be initialised after) form runs
  of their own. A run costs a 12h or 13h (one program, or up to 64) or a 14h.
- a program whose last writer of some field is a 21h costs a 21h;
- P and V written last by 33h/32h: those messages cover runs of at most 15 consecutive
  managed programs (overlapping ones only cost more), each run the price of its 33h (32h);
- every other last write of P, V, Vr, T, F1 or F2 is an item of its 40h..45h, every last
  write of a jump address by 46h an item of a 46h; a field with n items needs
  ceil(n / 15) messages (31 for 46h), each its header;
- jump addresses written last by 30h/31h: a plan's ranges, later ones over earlier ones,
  can be redrawn nested at most two deep (a link range over unlink ranges, an unlink range
  over link ranges) with no more ranges and the same final addresses; each range is a 30h
  or 31h. An initialised program whose last init came after every range over it keeps the
  init's address ("wiped"); one init message and one range are sent in one order, so along
  one range the programs of one init message are all wiped or all show the range. Every
  other program keeps its base address.

R is solved by a dynamic programme over programs 1..64 whose state is the init runs open
on either side of the system step, the length of the open 33h run, the ranges open (none,
a link range, one with an unlink range inside, an unlink range, one with a link range
inside) and whether the range shown is wiped in the current init run; each program takes
the cheapest of its items or a 21h. The headers are outside the programme: for every set
of open 40h..46h channels the programme runs with items priced one by one, which gives a
solution needing ceil(n/15) messages per channel (a value of R) and bounds every smaller
message count vector of that set; those are bounded higher with a share of a header on
each item of the channels over their capacity (a Lagrangian relaxation of n <= 15 k: the
shares are bisected), then with one channel's headers counted exactly in the state (its
item count modulo 15), then two channels' at once (the Lagrangian leaves a gap where three
channels overflow together, as a full rewrite's 43h..45h do: only counting two exactly
closes it). Whatever stays below the best value of R found is the bound; `bound` also says
whether it is R's optimum (nothing stayed below). The table no longer marks that beside the
plan ("=", read as "the plan is optimal"): R misses moves a plan can make (issue 29: four
programs written whole by 21h so that 60 others fit one message fewer of each field), and
where it does, its optimum says nothing of the plan's. The table compares plans with the exact
optimum, and shows R (--bound) as a bound only. The plan's bus time is the first
"best value": it only lets the search stop early — a vector bounded above the plan can hold
no plan cheaper than the plan, so the bound stays below every plan either way.

What R leaves out only makes plans dearer (a stx checksum that is 7Eh, messages that are
last writers of nothing), so its optimum is below every plan's bus time. One step is argued
rather than proved for every case: R asks that along one of its redrawn ranges the
programs of one init message are all wiped or all shown. That holds for a plan's own
ranges, and redrawing keeps it wherever it keeps the ranges apart; where redrawing a plan
merges two ranges that an init message separates, that plan may fall outside R. The tests
(tests/planner/test_plan_bound.py) hold the bound against every plan of up to three
messages on small modules and against the planner's plans.
"""

from __future__ import annotations

import argparse
import itertools
import json
import random
import tempfile
import time
from dataclasses import replace
from math import ceil
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.framing.stx import START
from prc3cfg.core.image import (
    DEFAULT_SYSTEM,
    PROGRAM_COUNT,
    PROGRAM_FIELDS,
    ModuleImage,
    Program,
    default_program,
)
from prc3cfg.core.line import LineSettings
from prc3cfg.core.planner import ModulePlan, plan_module, summarise
from prc3cfg.core.planner.problem import FIELD_BIT, INIT_AFTER, INIT_BEFORE, KEEP, PlanningProblem

if TYPE_CHECKING:  # scipy, which exact_reference needs, is the bench extra: imported where the table runs
    from exact_reference import ReferencePlan

SYSTEM = replace(DEFAULT_SYSTEM, S1=2500, S2=120, S4=500, S5=20)
USED = 40  # programs a recipe uses; the rest are at their defaults (plant files with `reset`)
ID_WORD = 2


def recipe_program(rnd: random.Random, number: int, system=SYSTEM) -> Program:
    """A program as a coating recipe has it: position, speed, a dwell, a function output, chains of four."""
    return Program(
        P=rnd.randrange(300, system.S1, 5), V=rnd.randrange(max(system.S5, 50), system.S4, 10),
        Vr=0, T=rnd.choice([0, 0, 5, 10, 20]), F1=rnd.choice([0, 1010, 1050]), F2=rnd.choice([0, 0, 1050]),
        A=number + 1 if number % 4 else 0,
    )


def plant(rnd: random.Random, address: int = 1) -> ModuleImage:
    programs = [recipe_program(rnd, n) if n <= USED else default_program(SYSTEM)
                for n in range(1, PROGRAM_COUNT + 1)]
    return ModuleImage(address, SYSTEM, tuple(programs))


def changed(image: ModuleImage, changes: dict[int, Program | None], **system: int) -> ModuleImage:
    programs = list(image.programs)
    for number, program in changes.items():
        programs[number - 1] = program
    return replace(image, system=replace(image.system, **system), programs=tuple(programs))


# -- scenarios: (read-back, plant file) ---------------------------------------------------------


def recipe_tweak(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    actual = plant(rnd, address)
    p = actual.programs
    changes = {n: replace(p[n - 1], V=p[n - 1].V + 10) for n in rnd.sample(range(1, USED + 1), 3)}
    changes |= {n: replace(p[n - 1], T=p[n - 1].T + 5) for n in rnd.sample(range(1, USED + 1), 2)}
    return actual, changed(actual, changes)


def teach_in_revert(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    desired = plant(rnd, address)
    p = desired.programs
    taught = {
        n: replace(p[n - 1], P=p[n - 1].P + rnd.choice([-15, -5, 5, 15]))
              for n in rnd.sample(range(1, USED + 1), 12)
    }
    return changed(desired, taught), desired


def commissioning(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    return ModuleImage.factory(address), plant(rnd, address)


def lower_s1(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    actual = plant(rnd, address)
    s1 = 1200
    clamped = {n: replace(p, P=min(p.P, s1)) for n, p in enumerate(actual.programs, start=1)}
    high = [n for n, p in enumerate(actual.programs, start=1) if p.P > s1]
    clamped |= {n: replace(clamped[n], P=rnd.randrange(800, s1, 5)) for n in high[:3]}
    return actual, changed(actual, clamped, S1=s1)


def rechaining(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    actual = plant(rnd, address)
    p = actual.programs
    chains = {n: n + 1 if n < 8 else 1 for n in range(1, 9)}  # a loop 1 → … → 8 → 1
    chains |= {n: n + 1 if n < 16 else 0 for n in range(9, 17)}
    chains |= {n: n + 1 if n < USED else 0 for n in range(17, USED + 1)}
    return actual, changed(actual, {n: replace(p[n - 1], A=a) for n, a in chains.items()})


def cleanup(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    desired = plant(rnd, address)
    old = {n: recipe_program(rnd, n) for n in range(USED + 1, PROGRAM_COUNT + 1)}  # an old recipe's leftovers
    return changed(desired, old), desired


def factory_reset(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    return plant(rnd, address), ModuleImage.factory(address)


def full_rewrite(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    """A new recipe on all 64 programs over an old one."""
    actual, desired = (ModuleImage(address, SYSTEM,
                                   tuple(recipe_program(rnd, n) for n in range(1, PROGRAM_COUNT + 1)))
                       for _ in range(2))
    return actual, desired


def large_mixed(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    """Narrower speeds, a new recipe on 20 programs, dwell and outputs, a rechain, a cleanup, kept
    programs."""
    actual = plant(rnd, address)
    actual = changed(actual, {n: recipe_program(rnd, n) for n in range(50, PROGRAM_COUNT + 1)})
    system = replace(SYSTEM, S4=400, S5=40)
    programs = [replace(p, V=max(min(p.V, system.S4), system.S5)) for p in actual.programs]
    for n in rnd.sample(range(1, USED + 1), 20):
        programs[n - 1] = replace(programs[n - 1], P=rnd.randrange(300, system.S1, 5),
                                  V=rnd.randrange(50, 400, 10))
    for n in rnd.sample(range(1, USED + 1), 10):
        programs[n - 1] = replace(programs[n - 1], T=rnd.choice([0, 15, 30]), F1=rnd.choice([0, 1020]))
    for n in range(21, 31):
        programs[n - 1] = replace(programs[n - 1], A=n + 1 if n < 30 else 0)
    for n in range(50, PROGRAM_COUNT + 1):
        programs[n - 1] = default_program(system)
    for n in (45, 46, 47):  # kept by hand on the floor: unmanaged, not read
        programs[n - 1] = None
    actual = changed(actual, {45: None, 46: None, 47: None})
    return actual, replace(actual, system=system, programs=tuple(programs))


def full_program(rnd: random.Random, number: int, system=SYSTEM) -> Program:
    """A program that differs from the defaults in every field: relative speed, dwell and both outputs set,
    chains of four."""
    return Program(
        P=rnd.randrange(300, system.S1, 5), V=rnd.randrange(max(system.S5, 50), system.S4, 10),
        Vr=rnd.choice([-1, 1]) * rnd.randrange(5, 100, 5), T=rnd.randrange(1, 100),
                   F1=rnd.choice([20, 1010, 1050]),
        F2=rnd.choice([30, 1050]), A=number + 1 if number % 4 else 0,
    )


def full_module(rnd: random.Random, address: int = 1) -> ModuleImage:
    return ModuleImage(address, SYSTEM, tuple(full_program(rnd, n) for n in range(1, PROGRAM_COUNT + 1)))


def commissioning_every_field(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    """Every field of all 64 programs from factory defaults (issue 29: four programs written whole let the
    other 60 fit four messages of each field, not five)."""
    return ModuleImage.factory(address), full_module(rnd, address)


def full_rewrite_every_field(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    """New values in every field of all 64 programs."""
    return full_module(rnd, address), full_module(rnd, address)


def half_rewrite(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    """32 programs, anywhere, rewritten in every field."""
    actual = full_module(rnd, address)
    return actual, changed(actual, {n: full_program(rnd, n)
                                    for n in rnd.sample(range(1, PROGRAM_COUNT + 1), 32)})


def narrower_speeds(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    """S4 and S5 narrowed: the module clamps the speeds outside, and the plant file sets six speeds
    otherwise."""
    actual = plant(rnd, address)
    s4, s5 = 300, 60
    programs: dict[int, Program | None] = {n: replace(p, V=max(min(p.V, s4), s5))
                                           for n, p in enumerate(actual.programs, start=1)}
    programs |= {n: replace(actual.programs[n - 1], V=rnd.randrange(100, s4, 10))
                 for n in rnd.sample(range(1, USED + 1), 6)}
    return actual, changed(actual, programs, S4=s4, S5=s5)


def unlinking_around_a_chain(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    """Programs 1..24 unlinked but for one chain 9 → … → 16: a link range inside an unlink range."""
    actual = plant(rnd, address)
    jumps = {n: n + 1 if 9 <= n < 16 else 0 for n in range(1, 25)}
    return actual, changed(actual, {n: replace(actual.programs[n - 1], A=a) for n, a in jumps.items()})


SCENARIOS = {
    "recipe tweak": recipe_tweak,
    "teach-in revert": teach_in_revert,
    "commissioning": commissioning,
    "lower S1, clamping": lower_s1,
    "rechaining": rechaining,
    "cleanup (reset)": cleanup,
    "factory reset": factory_reset,
    "large mixed change": large_mixed,
    "full rewrite": full_rewrite,
}
#: Scenarios of the exact comparison only: the plant runs keep the nine above, so that their CPU
#: times compare with earlier runs.
MORE_SCENARIOS = {
    "commissioning, every field": commissioning_every_field,
    "full rewrite, every field": full_rewrite_every_field,
    "half rewrite, every field": half_rewrite,
    "narrower speeds": narrower_speeds,
    "unlinking around a chain": unlinking_around_a_chain,
}
#: The families the comparison with the exact optimum is reported by, and their scenarios.
FAMILIES = {
    "commissioning": ("commissioning", "commissioning, every field"),
    "full rewrite": ("full rewrite", "full rewrite, every field"),
    "partial rewrite": ("recipe tweak", "teach-in revert", "half rewrite, every field", "large mixed change"),
    "clamps": ("lower S1, clamping", "narrower speeds"),
    "chains": ("rechaining", "unlinking around a chain"),
    "inits": ("cleanup (reset)", "factory reset"),
}
#: Probes of the header shares that bound one message count vector (`Relaxation._vectors`).
SHARE_PROBES = 6
#: Channels counted exactly at once, after one at a time, where vectors stay below (`Relaxation._vectors`).
EXACT_TOGETHER = 2
#: Line profiles: framing and ZVZ (used by open-driver only).
PROFILES = {
    "crc16": ("crc16", 0.020),
    "stx": ("stx", 0.020),
    "open-driver/20ms": ("open-driver", 0.020),
    "open-driver/100ms": ("open-driver", 0.100),
}
#: The profiles of issue 29's acceptance: the comparison with the exact optimum runs on these unless told.
EXACT_PROFILES = ("crc16", "open-driver/100ms", "stx")


# -- the bound: the relaxation R (see the module docstring) -------------------------------------

INF = float("inf")
ITEM_FIELDS = PROGRAM_FIELDS[:-1]  # P V Vr T F1 F2: their 40h..45h
CHANNELS = (*ITEM_FIELDS, "A")  # A: 46h
CAPACITY = {**dict.fromkeys(ITEM_FIELDS, codec.MAX_FIELD_ITEMS), "A": codec.MAX_ADDRESS_ITEMS}
PV = ("P", "V")
#: An init side (before or after the system step) at a program: not covering it, covering it
#: as the first program of a run, covering it further on in a run.
OUT, ONE, MORE = 0, 1, 2
#: Ranges open after a program: none, a link range, a link range with an unlink range inside,
#: an unlink range, an unlink range with a link range inside.
NO_RANGE, LINK, LINK_UNLINK, UNLINK, UNLINK_LINK = range(5)
#: What a program shows of the ranges: none over it, the link value i+2, 0.
UNCOVERED, NEXT, ZERO = range(3)
#: Whether the programs of one init run under the range shown keep the init's address.
FREE, WIPED, SHOWN = range(3)
#: Ranges open before a program → (ranges open after it, what it shows, a range opens here,
#: the range shown is the one shown at the program before, it is shown at the program after).
RANGE_MOVES = {
    NO_RANGE: ((NO_RANGE, UNCOVERED, 0, False, False), (LINK, NEXT, 1, False, True),
               (NO_RANGE, ZERO, 1, False, False), (UNLINK, ZERO, 1, False, True)),
    LINK: ((LINK, NEXT, 0, True, True), (NO_RANGE, ZERO, 0, True, False),
           (LINK_UNLINK, ZERO, 1, False, True), (LINK, ZERO, 1, False, False)),
    LINK_UNLINK: ((LINK_UNLINK, ZERO, 0, True, True), (LINK, ZERO, 0, True, False),
                  (NO_RANGE, ZERO, 0, True, False)),
    UNLINK: ((UNLINK, ZERO, 0, True, True), (NO_RANGE, ZERO, 0, True, False),
             (UNLINK_LINK, NEXT, 1, False, True)),
    UNLINK_LINK: ((UNLINK_LINK, NEXT, 0, True, True), (UNLINK, ZERO, 0, True, False),
                  (NO_RANGE, ZERO, 0, True, False)),
}


def stuffed(value: int) -> int:
    """Bytes of a value word that stx stuffs."""
    return value.to_bytes(2, "big", signed=True).count(START)


class Relaxation:
    """R for one module: what the last writers of every difference must cost (module docstring)."""

    def __init__(self, actual: ModuleImage, desired: ModuleImage, cost: LineCost) -> None:
        problem = PlanningProblem.build(actual, desired, cost)
        self.prices = prices = problem.prices
        self.fixed = 0.0 if problem.system_step is None else cost.message_time(problem.address,
                                                                               problem.system_step)
        self.kinds = problem.kinds
        self.managed = problem.managed
        stx = cost.framing.name == "stx"
        self.stuffing = [
            {name: stuffed(value) * prices.byte if stx else 0.0
             for name, value in zip(PROGRAM_FIELDS, want.values())}
            if want is not None else None
            for want in desired.programs
        ]
        self.masks = [{kind: problem.masks[kind][i] for kind in self.kinds} for i in range(PROGRAM_COUNT)]
        # per program and init kind: the address is right when uncovered, shown NEXT, shown ZERO, wiped
        self.address_ok = []
        for i, want in enumerate(desired.programs):
            row = {}
            for kind in self.kinds:
                base = problem.bases[kind][i].A
                row[kind] = (True,) * 4 if want is None else (
                    base == want.A, want.A == i + 2, want.A == 0, kind != KEEP and base == want.A)
            self.address_ok.append(row)
        differ = 0
        for masks in self.masks:
            for mask in masks.values():
                differ |= mask
        self.relevant = [name for name in CHANNELS if differ & FIELD_BIT[name]]
        self.runs_matter = bool(differ & (FIELD_BIT["P"] | FIELD_BIT["V"]))
        self.ranges_matter = bool(differ & FIELD_BIT["A"])
        self.header = {**dict.fromkeys(ITEM_FIELDS, prices.field_header), "A": prices.address_header}
        self.item = {**dict.fromkeys(ITEM_FIELDS, prices.field_item), "A": prices.address_item}
        # init states (before side, after side) and their moves: (next state, cost, the same run goes on)
        sides = (OUT, ONE, MORE)
        two = INIT_BEFORE in self.kinds
        side_moves = {OUT: ((OUT, 0.0, False), (ONE, prices.init, False)),
                      ONE: ((OUT, 0.0, False), (MORE, prices.init_range - prices.init, True),
                            (ONE, prices.init, False)),
                      MORE: ((OUT, 0.0, False), (MORE, 0.0, True), (ONE, prices.init, False))}
        self.init_moves = {}
        for state in ((b, a) for b in (sides if two else (OUT,)) for a in sides):
            moves = []
            for before, cost_b, on_b in side_moves[state[0]] if two else ((OUT, 0.0, False),):
                for after, cost_a, on_a in side_moves[state[1]]:
                    kind, new = self.kind(state), self.kind((before, after))
                    same_run = kind == new != KEEP and (on_a if new == INIT_AFTER else on_b)
                    moves.append(((before, after), cost_b + cost_a, same_run))
            self.init_moves[state] = tuple(moves)
        self.run_refund = prices.parts_header + prices.parts_item - prices.parts(1)  # a run of one is a 32h
        self.end_refund = prices.init_range - prices.init  # a run to program 64 is a 13h

    @staticmethod
    def kind(sides: tuple[int, int]) -> int:
        return INIT_AFTER if sides[1] else INIT_BEFORE if sides[0] else KEEP

    def _options(self, i: int, price: dict[str, float], exact: tuple[str, ...]) -> dict:
        """Per init kind, [in a 33h run][address right]: (cost, per channel of `exact` whether it
        uses an item there) per way to write the program's differences (items, or a 21h)."""
        stuffing = self.stuffing[i]
        whole = self.prices.program + sum(stuffing.values())
        pair = stuffing["P"] + stuffing["V"]
        out = {}
        for kind in self.kinds:
            mask = self.masks[i][kind]
            plain = pv = 0.0
            for name in ITEM_FIELDS:
                if mask & FIELD_BIT[name]:
                    if name in PV:
                        pv += price[name] + stuffing[name]
                    else:
                        plain += price[name] + stuffing[name]
            rows = []
            for in_run in (False, True):
                row = []
                for right in (False, True):
                    items = plain + (0.0 if in_run else pv) + (0.0 if right else price["A"])
                    extra = pair if in_run else 0.0
                    if not exact:
                        row.append(((min(items, whole) + extra, ()),))
                    else:
                        uses = tuple((not right) if name == "A" else bool(mask & FIELD_BIT[name])
                                     and not (in_run and name in PV)
                                     for name in exact)
                        row.append(((items + extra, uses), (whole + extra, (False,) * len(exact))))
                rows.append(row)
            out[kind] = rows
        return out

    def solve(self, opened: frozenset, shares: dict[str, float], limit: float = INF,
              exact: tuple[str, ...] = ()) -> tuple[float, dict[str, int] | None]:
        """The cheapest R without the headers of 40h..46h (but those of the `exact` channels, their
        item counts modulo their capacity in the state), items only in the `opened` channels and
        priced with their `shares` of a header; and its item counts. (INF, None) when nothing is
        cheaper than `limit`."""
        prices = self.prices
        head, per, link = prices.parts_header, prices.parts_item, prices.link
        price = {name: self.item[name] + shares.get(name, 0.0) if name in opened else INF
                 for name in CHANNELS}
        for name in exact:
            price[name] = self.item[name]
        capacity, header = [CAPACITY[name] for name in exact], [self.header[name] for name in exact]
        options = [self._options(i, price, exact) if self.managed[i] else None for i in range(PROGRAM_COUNT)]
        # the least programs i.. can add, to drop states that cannot get below `limit`
        rest = [0.0] * (PROGRAM_COUNT + 1)
        for i in range(PROGRAM_COUNT - 1, -1, -1):
            least = 0.0
            if options[i] is not None:
                least = min(min(o[0] for o in rows[0][1] + tuple((c + per, u) for c, u in rows[1][1]))
                            for rows in options[i].values())
            rest[i] = rest[i + 1] + least
        slack = limit + 2 * self.end_refund + self.run_refund  # refunds still to come
        states = {((OUT, OUT), 0, NO_RANGE, FREE, (0,) * len(exact)): 0.0}
        steps = []
        for i in range(PROGRAM_COUNT):
            managed = self.managed[i]
            ranges_on = managed and i + 1 < PROGRAM_COUNT and self.managed[i + 1]
            cut = slack - rest[i + 1]
            inited, back_init = {}, {}
            for state, c in states.items():
                sides, run, rng, shown, count = state
                for new, cost, same_run in self.init_moves[sides] if managed else (((OUT, OUT), 0.0, False),):
                    key = (new, run, rng, shown if same_run else FREE, count)
                    if c + cost < inited.get(key, INF):
                        inited[key], back_init[key] = c + cost, state
            runs, back_run = {}, {}
            for state, c in inited.items():
                sides, run, rng, shown, count = state
                closed = c - self.run_refund if run == 1 else c
                moves = [(0, closed)]
                if managed and self.runs_matter:
                    moves.append((1, closed + head + per))
                    if 0 < run < codec.MAX_FIELD_ITEMS:
                        moves.append((run + 1, c + per))
                for new_run, cost in moves:
                    key = (sides, new_run, rng, shown, count)
                    if cost < runs.get(key, INF):
                        runs[key], back_run[key] = cost, state
            done, back_done = {}, {}
            for state, c in runs.items():
                sides, run, rng, shown, count = state
                if not managed:
                    if c < done.get(state, INF):
                        done[state], back_done[state] = c, (state, True)
                    continue
                kind = self.kind(sides)
                row = options[i][kind][run > 0]
                right = self.address_ok[i][kind]
                for new_rng, seen, opens, same, goes_on in (RANGE_MOVES[rng] if self.ranges_matter
                                                            else RANGE_MOVES[0][:1]):
                    if new_rng != NO_RANGE and not ranges_on:
                        continue
                    if seen == UNCOVERED or kind == KEEP:
                        ways = ((right[seen], FREE),)
                    else:
                        before = shown if same else FREE
                        ways = tuple((ok, how) for ok, how in ((right[3], WIPED), (right[seen], SHOWN))
                                     if before in (FREE, how))
                    for ok, how in ways:
                        for cost, uses in row[ok]:
                            total, new_count = c + opens * link + cost, count
                            if any(uses):
                                total += sum(h for h, n, u in zip(header, count, uses) if u and n == 0)
                                new_count = tuple((n + 1) % m if u else n
                                                  for n, m, u in zip(count, capacity, uses))
                            key = (sides, run, new_rng, how if goes_on else FREE, new_count)
                            if total < cut and total < done.get(key, INF):
                                done[key], back_done[key] = total, (state, ok)
            steps.append((back_init, back_run, back_done))
            states = done
        best, last = INF, None
        for state, c in states.items():
            c -= (self.run_refund if state[1] == 1 else 0.0) + self.end_refund * state[0].count(MORE)
            if c < best:
                best, last = c, state
        if best >= limit:
            return INF, None
        return best, self._counts(steps, last, price)

    def _counts(self, steps: list, state: tuple, price: dict[str, float]) -> dict[str, int]:
        """The items per channel of the solution that ends in `state`."""
        counts = dict.fromkeys(CHANNELS, 0)
        for i in range(PROGRAM_COUNT - 1, -1, -1):
            back_init, back_run, back_done = steps[i]
            before, ok = back_done[state]
            if self.managed[i]:
                sides, run = before[0], before[1]
                mask = self.masks[i][self.kind(sides)]
                items = [name for name in ITEM_FIELDS if mask & FIELD_BIT[name] and not (run and name in PV)]
                items += [] if ok else ["A"]
                stuffing = self.stuffing[i]
                if (sum(price[name] + stuffing.get(name, 0.0) for name in items) <= self.prices.program
                    + sum(stuffing.values())):
                    for name in items:
                        counts[name] += 1
            state = back_init[back_run[before]]
        return counts

    def bound(self, incumbent: float = INF) -> tuple[float, bool]:
        """A lower bound on every plan's bus time, and whether it is R's optimum.

        `incumbent` (a plan's bus time) only lets the search stop early (module docstring).
        """
        best = incumbent - self.fixed
        head, capacity = self.header, CAPACITY
        found = []
        for size in range(len(self.relevant), -1, -1):
            for opened in map(frozenset, itertools.combinations(self.relevant, size)):
                cost, counts = self.solve(opened, {}, best - sum(head[name] for name in opened))
                if counts is not None:
                    top = {name: max(1, ceil(counts[name] / capacity[name])) for name in opened}
                    best = min(best, cost + sum(top[name] * head[name] for name in opened))
                    found.append((opened, cost, top, counts))
        below = []
        for opened, cost, top, counts in found:
            best, lows = self._vectors(opened, cost, top, counts, best)
            below += lows
        return self.fixed + min([best, *below]), not below

    def _vectors(self, opened: frozenset, cost: float, top: dict[str, int], counts: dict[str, int],
                 best: float) -> tuple[float, list[float]]:
        """Every message count vector of `opened` below `top` bounded, first by shares of a header,
        then with one channel counted exactly; the best value found and the bounds left below it."""
        order = sorted(opened)
        head, capacity = self.header, CAPACITY
        vectors = [k for k in itertools.product(*(range(1, top[name] + 1) for name in order))
                   if list(k) != [top[name] for name in order]]
        low = {k: cost + sum(n * head[name] for n, name in zip(k, order)) for k in vectors}
        tried = set()
        while True:
            live = [k for k in vectors if low[k] < best]
            if not live or min(live, key=low.get) in tried:
                break
            target = min(live, key=low.get)
            tried.add(target)
            fits = dict(zip(order, target))
            over = [name for name in order if fits[name] < top[name]]
            floor, ceiling = dict.fromkeys(over, 0.0), dict.fromkeys(over, self.prices.program)
            for _ in range(SHARE_PROBES):
                shares = {name: (floor[name] + ceiling[name]) / 2 for name in over}
                value, n = self.solve(opened, shares)
                for k in vectors:
                    low[k] = max(low[k], value + sum(c * (head[name] - capacity[name] * shares.get(name, 0.0))
                                                     for c, name in zip(k, order)))
                best = min(best, value - sum(shares.get(name, 0.0) * n[name] for name in order)
                           + sum(max(1, ceil(n[name] / capacity[name])) * head[name] for name in order))
                if low[target] >= best:
                    break
                for name in over:
                    if n[name] > capacity[name] * fits[name]:
                        floor[name] = shares[name]
                    else:
                        ceiling[name] = shares[name]
        # then channels counted exactly: one at a time, the one with the most room first; then two at
        # once, the channels that bounded highest alone first (the pair that bounds the rest is most
        # often those: a channel at its `top` counts too, as counting another exactly may push it over)
        alone = {}
        for name in sorted(order, key=lambda name: capacity[name] * top[name] - counts[name]):
            best, alone[name] = self._exact((name,), opened, vectors, low, best)
        for names in itertools.combinations(sorted(order, key=alone.__getitem__, reverse=True),
                                            EXACT_TOGETHER):
            best, _ = self._exact(names, opened, vectors, low, best)
        return best, [low[k] for k in vectors if low[k] < best]

    def _exact(self, names: tuple[str, ...], opened: frozenset, vectors: list, low: dict,
               best: float) -> tuple[float, float]:
        """Raise `low` of the vectors still below `best` by R with the channels `names` counted
        exactly; the best value found and the bound (-INF when nothing was left to bound)."""
        order = sorted(opened)
        head, capacity = self.header, CAPACITY
        live = [k for k in vectors if low[k] < best]
        if not live:
            return best, -INF
        others = [(j, other) for j, other in enumerate(order) if other not in names]
        least = min(sum(k[j] * head[other] for j, other in others) for k in live)
        value, n = self.solve(opened, {}, best - least, exact=names)
        for k in live:
            low[k] = max(low[k], value + sum(k[j] * head[other] for j, other in others))
        if n is not None:
            best = min(best, value
                       + sum(max(1, ceil(n[other] / capacity[other])) * head[other] for _, other in others))
        return best, value


# -- running ------------------------------------------------------------------------------------


def line_cost(profile: str) -> LineCost:
    framing, zvz = PROFILES[profile]
    return LineCost.of(framing, LineSettings(), 0.010, zvz)


class Compared(NamedTuple):
    """One scenario on one line: the plan and the exact optimum."""

    family: str
    scenario: str
    profile: str
    actual: ModuleImage
    plan: ModulePlan
    reference: ReferencePlan

    @property
    def ratio(self) -> float:
        return self.plan.bus_time / self.reference.bus_time if self.reference.bus_time else 1.0


def exact_table(profiles: list[str], seeds: int, with_bound: bool) -> list[Compared]:
    """Every scenario of `FAMILIES` (each with `seeds` seeds) on every profile: the plan against the exact
    optimum. "+" after the optimum: on stx a checksum of 7Eh costs the optimum's plan a byte the
    programme does not count — the true optimum lies between the programme's value and this."""
    from exact_reference import exact_plan  # scipy: the bench extra, needed here only

    scenarios = SCENARIOS | MORE_SCENARIOS
    print(f"{'family':<16} {'scenario':<29} {'profile':<18} {'plan ms':>9} {'msgs':>4} {'exact ms':>10} "
          f"{'msgs':>4} "
          f"{'plan/exact':>10} {'naive ms':>9} {'cpu ms':>7} {'exact s':>7}"
          + (f" {'R bound ms':>10}" if with_bound else ""))
    compared = []
    for profile in profiles:
        cost = line_cost(profile)
        for family, names in FAMILIES.items():
            for name, seed in itertools.product(names, range(seeds)):
                label = name if seed == 0 else f"{name} #{seed + 1}"
                actual, desired = scenarios[name](random.Random(label))
                start = time.process_time()
                plan = plan_module(actual, desired, cost)
                cpu = time.process_time() - start
                start = time.process_time()
                reference = exact_plan(actual, desired, cost)
                exact_cpu = time.process_time() - start
                case = Compared(family, label, profile, actual, plan, reference)
                compared.append(case)
                mark = "+" if reference.bus_time > reference.bound + 1e-9 else " "
                bound = (f" {Relaxation(actual, desired, cost).bound(plan.bus_time)[0] * 1e3:10.1f}"
                         if with_bound else "")
                print(f"{family:<16} {label:<29} {profile:<18} {plan.bus_time * 1e3:9.1f} "
                      f"{len(plan.steps):4d} "
                      f"{reference.bus_time * 1e3:9.1f}{mark} {len(reference.messages):4d} "
                      f"{case.ratio:10.4f} "
                      f"{plan.naive_bus_time * 1e3:9.1f} {cpu * 1e3:7.1f} {exact_cpu:7.1f}{bound}",
                      flush=True)
    return compared


def exact_summary(compared: list[Compared]) -> None:
    """Per family and profile: the plans' total bus time over the optima's, and the worst scenario; then
    the worst scenario of all, with both plans' messages."""
    print(f"\n{'family':<16} {'profile':<18} {'scenarios':>9} {'total plan/exact':>16}  worst")
    groups: dict[tuple[str, str], list[Compared]] = {}
    for case in compared:
        groups.setdefault((case.family, case.profile), []).append(case)
    for (family, profile), cases in groups.items():
        total = sum(c.plan.bus_time for c in cases) / (sum(c.reference.bus_time for c in cases) or 1.0)
        worst = max(cases, key=lambda c: c.ratio)
        above = (f"{worst.ratio:.4f} ({worst.scenario})" if worst.ratio > 1 + 1e-9
                 else "every plan at the optimum")
        print(f"{family:<16} {profile:<18} {len(cases):9d} {total:16.4f}  {above}")
    worst = max(compared, key=lambda c: c.ratio)
    print(f"\nworst: {worst.scenario} on {worst.profile}, plan/exact {worst.ratio:.4f}")
    plans = (("prc3cfg", [s.message for s in worst.plan.steps]), ("exact", list(worst.reference.messages)))
    cost = line_cost(worst.profile)
    for name, messages in plans:
        total = sum(cost.message_time(worst.actual.address, m) for m in messages)
        print(f"  {name}: {len(messages)} messages, {total * 1e3:.1f} ms")
        for message in messages:
            print(f"    {cost.message_time(worst.actual.address, message) * 1e3:7.1f} ms  "
                  f"{summarise(message, worst.actual.system)}")


def plant_run(profile: str, modules: int, scenarios: list[str], label: str) -> None:
    """Plan a whole plant from saved images, as `prc3cfg plan --actual` does."""
    rnd = random.Random(f"plant-{label}-{modules}")
    makers = [SCENARIOS[name] for name in scenarios]
    cases = [makers[m % len(makers)](rnd, address=m % 30 + 1) for m in range(modules)]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "images.json"
        path.write_text(json.dumps([[a.to_json(), d.to_json()] for a, d in cases]))
        saved = [(ModuleImage.from_json(a), ModuleImage.from_json(d))
                 for a, d in json.loads(path.read_text())]
    cost = line_cost(profile)
    start = time.process_time()
    plans = [plan_module(actual, desired, cost) for actual, desired in saved]
    cpu = time.process_time() - start
    print(f"{label} plant, {modules} modules × {PROGRAM_COUNT} programs, {profile}: planning CPU "
          f"{cpu * 1e3:.0f} ms, "
          f"bus time {sum(p.bus_time for p in plans):.2f} s (naive "
          f"{sum(p.naive_bus_time for p in plans):.2f} s), "
          f"{sum(len(p.steps) for p in plans)} messages")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", action="append", choices=list(PROFILES))
    parser.add_argument("--modules", type=int, default=30)
    parser.add_argument("--seeds", type=int, default=1,
                        help="seeds of each scenario compared with the exact optimum")
    parser.add_argument("--bound", action="store_true", help="show the lower bound R too (slow)")
    args = parser.parse_args()
    exact_summary(exact_table(args.profile or list(EXACT_PROFILES), args.seeds, args.bound))
    print()
    for profile in args.profile or list(PROFILES):
        plant_run(profile, args.modules, list(SCENARIOS), "mixed")
        plant_run(profile, args.modules, ["commissioning", "large mixed change"], "heavy")


if __name__ == "__main__":
    main()
