"""The search for the cheapest plan of one module: the write phase without inits, then init choices.

Bus time is dominated by the fixed cost of an exchange (turnaround, frame overhead, the
reply, open-driver gaps), so the question is which *messages* to open, not which bytes
to send. The search is built around that:

1. **The write phase** (`write_phase.WritePhase`) for one choice of init kinds: the parts DP
   (`parts_dp`) and the jump-address DP (`address_dp`).
2. **Inits.** Which programs to initialise first (11h..14h, before or after the system
   step) is a second DP over program numbers (`choose_inits`): runs of initialised programs
   cost one message each and never cover an unmanaged program; each program is charged what
   its remaining differences would cost. That charge is estimated three ways — what they add
   to the best plan without inits (headers included), item by item with every channel open
   and a share of a header per item, and at the least they could cost (`floor_of`) — and
   again from each better plan
   found (and with each of its init runs moved across the system step); each init choice
   gets its own write phase. When that finds nothing better, two more sources:
   - neighbours of the best plan (`_neighbours`): each of its init runs left out; the
     shortest runs left out whose programs then differ in one set of fields only (as many
     as one message of items takes); each program it writes whole (21h) initialised; the
     programs with an item in one 40h..46h message, or in one 33h run, initialised where
     that takes the items out (together they save the message, one by one they never pay
     for an init);
   - inits that pay only by saving whole messages (`_header_targets`): the charges price
     items one by one, so when a field's items overflow into one more 40h..46h message and
     inits could take the overflow out, header shares per field are bisected until the init
     DP just takes it out (all such fields together, and each alone); each init choice met
     on the way that leaves at most an item or two (a 21h may take those) is searched, and
     so are, per field, init runs that take its items out and add no difference, most items
     first, until the overflow is out (`_harmless_inits`: where runs alike tie, the DP takes
     all or none). This starts from the two plans closest to the best within an exchange
     (one that overflows may be one init away from the best); 40h and 41h count the programs
     outside 33h runs. Each field's shares are bisected alone only once some init choice was
     worth searching (its lower bound below the best plan): before, only all fields' together.
     Where none of the init DP's own choices was worth it, no choice that one field's shares
     drew was ever better — on every change mix of `bench/plan_time_bench.py` and every
     scenario of `bench/plan_bench.py` — and bisecting them was most of planning's CPU (the
     F1/F2 mix's: a third).
   The init choices waiting are searched cheapest lower bound first (`floor_of`: each
   program's differences at their cheapest, every item with its share of a header), those
   whose bound — or `WritePhase.at_least`, the same with headers counted in whole messages —
   cannot beat the best plan not at all, and only so many (SEARCHED), so that planning
   costs about the same for every kind of change; no init choice is searched where no plan
   with an init could beat the best without (`inits_floor`).
3. The candidate layouts go back to the caller, cheapest estimate first, which prices the
   close ones exactly and keeps the cheapest.

Owns the search over init choices. Does not own building messages (`layout`) or checking the result
(the caller runs it on `prc3cfg.core.device`).
"""

from __future__ import annotations

import heapq
from collections.abc import Iterator
from typing import NamedTuple

from prc3cfg.core import codec
from prc3cfg.core.image import PROGRAM_COUNT
from prc3cfg.core.planner.bounds import floor_of, inits_floor, over_every_kind
from prc3cfg.core.planner.charges import Charges, linear, marginal, shared
from prc3cfg.core.planner.init_dp import choose_inits, init_cost
from prc3cfg.core.planner.layout import Layout, Writes, members, runs_of
from prc3cfg.core.planner.pricing import FIELDS
from prc3cfg.core.planner.problem import A_BIT, INIT_AFTER, INIT_BEFORE, KEEP, PV_BITS, PlanningProblem
from prc3cfg.core.planner.terms import (
    ESTIMATE,
    INF,
    ITEM_BITS,
    KIND_OF_BIT,
    Kinds,
    Run,
    Table,
    all_of,
    all_runs,
)
from prc3cfg.core.planner.write_phase import WritePhase

#: Items per message assumed by one of the init choices (few items: headers matter).
INIT_SHARE = 4
#: How many init choices' write phases one module's `InitSearch` searches (the CPU of a plan must not
#: depend on the kind of change). Better plans come from the first few: searching half as many more
#: after each better plan, up to three times as many, changed no message of 1,680 plans of the change
#: mixes of `bench/plan_time_bench.py` or of `bench/plan_bench.py`'s, and cost planning the random mix a
#: tenth of its CPU where the turnaround is short (0 ms), a few per cent at 10 ms.
SEARCHED = 8
#: Probes of the header shares that make the init DP take a field's overflow out (`_header_targets`).
TARGET_PROBES = 4
#: Items of the overflow an init choice of `_header_targets` may leave for a 21h to take out.
SLACK_ITEMS = 2
#: How many init choices closest to the best (within an exchange) `_header_targets` starts from in each round.
TARGETED = 4


class ItemChannel(NamedTuple):
    """One 40h..46h field of a write phase."""

    bit: int  # FIELD_BIT
    mask: int  # the programs with an item
    kind: codec.ItemsKind  # its message


class Overflow(NamedTuple):
    """A field whose items overflow into one more message, which inits could take out (`_overflows`)."""

    bit: int  # FIELD_BIT
    goal: int  # the items that fit one message less
    over: int  # items above the goal
    counted: int  # the programs counted (P and V: those outside 33h runs)


def search(problem: PlanningProblem) -> list[Layout]:
    """Candidate layouts, cheapest estimate first."""
    keep = (KEEP,) * PROGRAM_COUNT
    phase = WritePhase(problem, keep)
    found = phase.solve()
    layouts = [Layout(keep, writes, problem.system_cost + writes.estimate) for writes in found]
    if problem.init_useful():
        charges = Charges(problem, phase.alike)
        floors = charges.alike(floor_of(problem.prices, phase.target_a, over_every_kind(problem)))
        if inits_floor(problem, floors) < layouts[0].estimate:
            layouts = InitSearch(problem, phase, layouts, charges).run(found[0], floors)
    unique = {(layout.kinds, layout.writes): layout for layout in layouts}
    return sorted(unique.values(), key=ESTIMATE)


class InitSearch:
    """The search over init choices (module docstring, 2.): a queue of init choices, cheapest lower
    bound first, each given its own write phase; when it runs dry, the neighbours of the best plan
    and the inits that save whole messages — until none is left or SEARCHED were."""

    def __init__(self, problem: PlanningProblem, phase: WritePhase, layouts: list[Layout],
                 charges: Charges) -> None:
        self.problem = problem
        self.phase = phase  # the write phase without inits
        self.layouts = layouts  # every candidate found, the plans without inits first
        self.best = layouts[0]
        self.tried = {layouts[0].kinds}
        self.targeted: set[Kinds] = set()  # the init choices `_targets` started from
        self.searched = 0  # init choices whose write phases were searched
        self.order = 0  # init choices queued: ties in `_queued` go to the first
        self.improved = 0  # better plans found
        self.phases: dict[Kinds, WritePhase] = {}
        self.charges = charges  # the init DP's, by residual

    def run(self, writes: Writes, floors: Table) -> list[Layout]:
        """Every candidate found, starting from `writes`, the best write phase without inits, and
        `floors`, the init DP's charges at the least they could be (`floor_of`). The
        init choices waiting are searched those from the latest better plan first, then lowest
        `floor` first, SEARCHED at most."""
        queue = self._queued(self._first(writes, floors))
        while self.searched < SEARCHED:
            if not queue:  # the neighbours of the best plan and the inits that save whole messages, alike
                queue = self._queued([*_neighbours(self.problem, self.best), *self._targets()])
            if not queue:
                break
            *_, kinds = heapq.heappop(queue)
            for found in self._queued(self._try(kinds)):
                heapq.heappush(queue, found)
        return self.layouts

    def _queued(self, choices: list[Kinds]) -> list[tuple[int, float, int, Kinds]]:
        """Init choices not tried yet, as a heap: those from the latest better plan first, then by
        what their plans cost at least."""
        problem, out = self.problem, []
        for kinds in dict.fromkeys(choices):
            if kinds not in self.tried:
                self.order += 1
                out.append((-self.improved, init_cost(problem, kinds) + self._phase(kinds).floor, self.order,
                            kinds))
        heapq.heapify(out)
        return out

    def _phase(self, kinds: Kinds) -> WritePhase:
        if (phase := self.phases.get(kinds)) is None:
            phase = self.phases[kinds] = WritePhase(self.problem, kinds)
        return phase

    def _first(self, writes: Writes, floors: Table) -> list[Kinds]:
        """The init DP with a program's charge estimated three ways (module docstring, 2.)."""
        phase, problem, charges = self.phase, self.problem, self.charges
        tables = [charges.each(marginal(phase, writes)),
                  charges.alike(linear(phase, problem.prices.field_header / INIT_SHARE)), floors]
        return [choose_inits(problem, table) for table in tables]

    def _try(self, kinds: Kinds) -> list[Kinds]:
        """Search the write phases of `kinds`; when that gives a better plan, the init choices to try from
        it."""
        problem = self.problem
        self.tried.add(kinds)
        base = problem.system_cost + init_cost(problem, kinds)
        with_inits = self._phase(kinds)
        if (base + with_inits.floor >= self.best.estimate or base
            + with_inits.at_least(0) >= self.best.estimate):
            return []
        self.searched += 1
        found = with_inits.solve(self.best.estimate - base)
        self.layouts += [Layout(kinds, writes, base + writes.estimate) for writes in found]
        if not found or base + found[0].estimate >= self.best.estimate:
            return []
        self.best = Layout(kinds, found[0], base + found[0].estimate)
        self.improved += 1
        return [choose_inits(problem, self.charges.each(marginal(with_inits, found[0]))),
                *_moved_across(problem, kinds)]

    def _targets(self) -> list[Kinds]:
        """Inits that save whole messages, from the plans closest to the best (within an exchange)."""
        problem, best = self.problem, self.best
        close = sorted({layout.kinds: layout for layout in self.layouts if layout.kinds not in self.targeted
                        and layout.estimate < best.estimate + problem.prices.exchange}.values(), key=ESTIMATE)
        queue: list[Kinds] = []
        for layout in close[:TARGETED]:
            self.targeted.add(layout.kinds)
            goals = _overflows(problem, layout)
            candidates = _header_targets(problem, self.phase, self.charges, goals,
                                         alone=self.searched > 0) + _harmless_inits(problem, layout, goals)
            queue += [kinds for kinds in candidates if kinds not in self.tried]
        return queue


def _item_channels(writes: Writes) -> list[ItemChannel]:
    """Every 40h..46h field of `writes`."""
    return [ItemChannel(bit, mask, KIND_OF_BIT[bit])
            for bit, mask in zip((*ITEM_BITS, A_BIT), (*writes.items, writes.addresses))]


def _overflows(problem: PlanningProblem, layout: Layout) -> list[Overflow]:
    """The fields whose 40h..46h items in `layout` overflow into one more message and whose
    programs could lose the overflow to an init. P and V count only outside the layout's
    33h runs."""
    outside = ~all_runs(layout.writes.part_runs)
    goals = []
    for bit, mask, kind in _item_channels(layout.writes):
        n = mask.bit_count()
        goal = n - kind.in_last(n)
        reducible = sum(1 for i in members(mask) if any(not problem.masks[k][i] & bit for k in problem.kinds))
        if goal and n - reducible <= goal:
            goals.append(Overflow(bit, goal, n - goal, outside if bit & PV_BITS else ~0))
    return goals


def _header_targets(problem: PlanningProblem, phase: WritePhase, charges: Charges, goals: list[Overflow],
                    alone: bool) -> list[Kinds]:
    """Init choices that take the overflow of the `goals` fields out, to save whole messages.

    For all of those fields together, and (`alone`) for each alone, header shares per field are bisected
    until the init DP just removes the overflow of each (a Lagrangian relaxation of the message
    count); every init choice met on the way that leaves at most SLACK_ITEMS of the overflow is a
    candidate (a 21h the search adds may take out the last items).
    """
    found: dict[Kinds, None] = {}  # a set in the order found
    for chosen in dict.fromkeys([tuple(goals), *((goal,) for goal in goals if alone)]) if goals else ():
        # removing the overflow saves a header: start from that header spread over the overflow
        shares = {bit: problem.prices.header(KIND_OF_BIT[bit]) / over for bit, _, over, _ in chosen}
        low, high = dict.fromkeys(shares, 0.0), dict.fromkeys(shares, INF)
        for _ in range(TARGET_PROBES):
            kinds = choose_inits(problem, charges.alike(shared(phase, shares)))
            left = 0
            for bit, goal, _, counted in chosen:
                items = sum(1 for i, k in enumerate(kinds) if problem.masks[k][i] & bit and counted >> i & 1)
                over = items - goal
                left += max(over, 0)
                if over > 0:
                    low[bit] = shares[bit]
                else:
                    high[bit] = shares[bit]
                shares[bit] = 2 * shares[bit] if high[bit] == INF else (low[bit] + high[bit]) / 2
            if left <= SLACK_ITEMS:
                found[kinds] = None
    return list(found)


def _harmless_inits(problem: PlanningProblem, layout: Layout, goals: list[Overflow]) -> list[Kinds]:
    """Per overflowing field, `layout` with init runs added that take its items out and add no
    difference, the runs taking out most first, until the overflow is out (where runs alike
    tie, the init DP takes all of them or none)."""
    out = []
    for goal in goals:
        changed, left = list(layout.kinds), goal.over
        for run in sorted(_harmless_runs(problem, layout.kinds, goal), key=len, reverse=True):
            if left <= 0:
                break
            for i, kind in run:
                changed[i] = kind
            left -= len(run)
        if left <= 0:
            out.append(tuple(changed))
    return out


def _harmless_runs(problem: PlanningProblem, kinds: Kinds, goal: Overflow) -> list[list[tuple[int, int]]]:
    """Runs of the programs counted in `goal` that an init (the first kind that does) would take
    out of its field without adding a difference: per run, (program index, its init kind)."""
    masks, keep = problem.masks, problem.masks[KEEP]
    harmless = [next((k for k in problem.kinds[1:] if masks[k][i] & goal.bit < keep[i] & goal.bit
                      and not masks[k][i] & ~keep[i]), None)
                if kind == KEEP and problem.managed[i] and goal.counted >> i & 1 else None
                for i, kind in enumerate(kinds)]
    runs: list[list[tuple[int, int]]] = []
    for i, init in enumerate(harmless):
        if init is not None and runs and runs[-1][-1][0] == i - 1:
            runs[-1].append((i, init))
        elif init is not None:
            runs.append([(i, init)])
    return runs


def _neighbours(problem: PlanningProblem, layout: Layout) -> list[Kinds]:
    """The init choice of `layout` changed where the init DP, charging programs one by one,
    cannot see the change pay: one init run left out; the shortest runs left out whose
    programs then differ in one set of fields only, as many as one message of items takes
    (their items share the headers); one program it writes whole (21h) initialised; every
    program with an item in one 40h..46h message, or in one 33h run, initialised where that
    takes its item out (together they save the message)."""
    kinds = layout.kinds
    runs = [(first, last) for kind in problem.kinds[1:] for first, last in runs_of(kinds, kind)]
    out = [kinds[:first] + (KEEP,) * (last - first + 1) + kinds[last + 1 :] for first, last in runs]
    out += _short_runs_out(problem, kinds, runs)
    out += [kinds[:i] + (kind,) + kinds[i + 1 :] for i in members(layout.writes.whole) if kinds[i] == KEEP
            for kind in problem.kinds[1:]]
    out += _message_initialised(problem, layout)
    return out


def _short_runs_out(problem: PlanningProblem, kinds: Kinds, runs: list[Run]) -> Iterator[Kinds]:
    """Per set of fields, the shortest init runs left out whose programs then differ only in those
    fields, as many as one message of items takes (those items share their headers; no run alone
    pays them)."""
    adds = [all_of(tuple(problem.masks[KEEP][i] for i in range(first, last + 1))) for first, last in runs]
    for fields in set(adds):
        changed, room = list(kinds), FIELDS.capacity
        for first, last in sorted((run for run, added in zip(runs, adds) if not added & ~fields),
                                  key=lambda run: run[1] - run[0]):
            room -= last - first + 1
            if room < 0:
                break
            changed[first : last + 1] = [KEEP] * (last - first + 1)
        yield tuple(changed)


def _message_initialised(problem: PlanningProblem, layout: Layout) -> Iterator[Kinds]:
    """Per 40h..46h message of `layout` (a field that fits one) and per 33h run, its programs
    initialised where that takes their item out (together they save the message) — and, the other
    way, its initialised programs kept where their init put the item there (an 11h that wipes
    programs already as wanted, restored by one 40h: a 14h and a 13h around them save that 40h)."""
    kinds = layout.kinds
    one_message = [(bit, mask) for bit, mask, kind in _item_channels(layout.writes)
                   if kind.messages(mask.bit_count()) <= 1]
    runs33 = [(PV_BITS, (1 << (last + 1)) - (1 << first)) for first, last in layout.writes.part_runs]
    for bits, mask in one_message + runs33:
        initialised, kept = list(kinds), list(kinds)
        for i in members(mask):
            fixing = [k for k in problem.kinds[1:] if not problem.masks[k][i] & bits]
            if kinds[i] == KEEP and fixing:
                initialised[i] = fixing[0]
            elif kinds[i] != KEEP and not problem.masks[KEEP][i] & bits:
                kept[i] = KEEP
        yield tuple(initialised)
        yield tuple(kept)


def _moved_across(problem: PlanningProblem, kinds: Kinds) -> list[Kinds]:
    """`kinds` with one init run moved to the other side of the system step (the residuals may tie)."""
    if INIT_BEFORE not in problem.kinds:
        return []
    out = []
    for kind, other in ((INIT_BEFORE, INIT_AFTER), (INIT_AFTER, INIT_BEFORE)):
        for first, last in runs_of(kinds, kind):
            out.append(kinds[:first] + (other,) * (last - first + 1) + kinds[last + 1 :])
    return out

