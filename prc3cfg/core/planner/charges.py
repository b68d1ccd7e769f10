"""What the init DP (`init_dp.choose_inits`) charges each program for each init kind: its remaining
differences priced by a residual — item by item with a share of a header (`linear`, `shared`), or
what they would add to a plan found (`marginal`) — and the table of those charges (`Charges`).

Owns the residuals and the charges. Does not own the DP (`init_dp`).
"""

from __future__ import annotations

import operator
from collections.abc import Callable
from math import fsum

from prc3cfg.core.image import PROGRAM_COUNT
from prc3cfg.core.planner.init_dp import TIE
from prc3cfg.core.planner.layout import Writes
from prc3cfg.core.planner.pricing import PARTS
from prc3cfg.core.planner.problem import A_BIT, P_BIT, PV_BITS, V_BIT, PlanningProblem
from prc3cfg.core.planner.terms import INF, ITEM_BITS, PLAIN_BITS, Residual, Run, Table
from prc3cfg.core.planner.write_phase import WritePhase


def linear(phase: WritePhase, share: float) -> Residual:
    """A program's differences priced item by item with every channel open, each item with `share`
    of a header (P and V one item: a 33h's)."""
    prices = phase.prices
    item, address = prices.field_item + share, prices.address_item + share

    def cost(i: int, mask: int) -> float:
        if not mask:
            return 0.0
        total = 0.0
        for bit in PLAIN_BITS:
            if mask & bit:
                total += item
        if mask & PV_BITS:
            total += item
        if mask & A_BIT:
            total += address
        return min(total, prices.program)

    return cost

def shared(phase: WritePhase, shares: dict[int, float]) -> Residual:
    """A program's differences with every channel open, each item of a field in `shares` (by
    field bit) with that share of a header: P and V as a 33h pair unless one of them has a
    share, a jump address a link or unlink range can give as free (a range over initialised
    programs restores their chain), any other as a 46h item."""
    prices = phase.prices
    pv_items = any(bit & PV_BITS for bit in shares)
    item = {bit: prices.field_item + shares.get(bit, 0.0) for bit in ITEM_BITS}
    address = prices.address_item + shares.get(A_BIT, 0.0)

    def cost(i: int, mask: int) -> float:
        total = fsum(item[bit] for bit in PLAIN_BITS if mask & bit)
        if mask & PV_BITS:
            total += (fsum(item[bit] for bit in (P_BIT, V_BIT) if mask & bit) if pv_items
                      else prices.parts_item)
        if mask & A_BIT and phase.target_a[i] not in (0, i + 2):
            total += address
        return min(total, prices.program)

    return cost

def marginal(phase: WritePhase, writes: Writes) -> Residual:
    """What a program's differences would add to `writes`, everything else staying as it is.

    Header-aware: a program that alone opens a message pays for the message, one that
    joins an open one pays its item, one inside a 33h run or a fitting link range nothing.
    """
    prices = phase.prices
    # per field, what program i's item adds to the others' — by whether i is among its n items
    added = [(prices.fields(n + 1) - prices.fields(n) if n < PROGRAM_COUNT else INF,
              prices.fields(n) - prices.fields(n - 1) if n else INF)
             for n in (mask.bit_count() for mask in writes.items)]
    addresses = writes.addresses.bit_count()
    need = phase.pv_changed & ~writes.whole
    run_of = {i: (first, last) for first, last in writes.part_runs for i in range(first, last + 1)}
    ranged = {i: (i + 2 if link and i < last else 0) for link, first, last in writes.ranges
              for i in range(first, last + 1)}

    (p_added, v_added, *_), (p_items, v_items, *_) = added, writes.items
    plain = list(zip(PLAIN_BITS, added[2:], writes.items[2:]))
    single = phase.parts_price[1]

    def parts(i: int, mask: int) -> float:
        p = p_added[p_items >> i & 1] if mask & P_BIT else 0.0
        v = v_added[v_items >> i & 1] if mask & V_BIT else 0.0
        alone = min(single, p + v)  # one addition, rounded once as fsum's is
        return min(alone, _joining(phase, i, run_of[i], need)) if i in run_of else alone

    def jump(i: int, mask: int) -> float:
        if i in ranged:
            return (0.0 if ranged[i] == phase.target_a[i]
                    else prices.addresses(addresses + 1) - prices.addresses(addresses))
        if not mask & A_BIT:
            return 0.0
        n = addresses - (writes.addresses >> i & 1)
        single = prices.link if phase.target_a[i] == 0 else INF
        return min(single, prices.addresses(n + 1) - prices.addresses(n))

    def cost(i: int, mask: int) -> float:
        total = jump(i, mask)
        for bit, each, among in plain:
            if mask & bit:
                total += each[among >> i & 1]
        if mask & PV_BITS:
            total += parts(i, mask)
        return min(total, prices.program) if mask else total

    return cost

def _joining(phase: WritePhase, i: int, run: Run, need: int) -> float:
    """What P and V of program i add to the 33h run `run` as it is over the other programs in
    `need` (INF when there are none, or it would grow over 15 programs)."""
    first, last = run
    others = need & ((1 << (last + 1)) - (1 << first)) & ~(1 << i)
    if not others:
        return INF
    low, high = (others & -others).bit_length() - 1, others.bit_length() - 1
    span = max(high, i) - min(low, i) + 1
    if span > PARTS.capacity:
        return INF
    return phase.parts_price[span] - phase.parts_price[high - low + 1]

class Charges:
    """What `choose_inits` charges each program for each init kind, by a residual: per program the
    differences each kind leaves it priced — where kinds leave it the same differences, once; and
    where the residual depends on the program only through `alike(i, mask)`, once for all programs
    alike. On a tie the init wins, so runs grow over programs they do not harm."""

    def __init__(self, problem: PlanningProblem, alike: Callable[[int, int], object]) -> None:
        kinds = problem.kinds
        self.ties = [0.0, *[TIE] * (len(kinds) - 1)]
        # per program its distinct masks; over all programs the keys of `alike` (by place)
        # per program and kind: its mask's place among the program's distinct masks
        self.own: list[list[int]] = []
        self.distinct: list[list[int]] = []
        alikes: dict[object, int] = {}
        self.first: list[tuple[int, int]] = []  # per key of `alike`: the first program and mask with it
        shared: list[list[int]] = []  # per program and kind: its key's place in `first`
        for i in range(PROGRAM_COUNT):
            masks = [problem.masks[k][i] for k in kinds]
            distinct = list(dict.fromkeys(masks))
            self.distinct.append(distinct)
            self.own.append([distinct.index(mask) for mask in masks])
            places = []
            for mask in masks:
                if (place := alikes.get(key := alike(i, mask))) is None:
                    place = alikes[key] = len(self.first)
                    self.first.append((i, mask))
                places.append(place)
            shared.append(places)
        # per program, its row of `alike` from the keys' values and then the same less TIE (the inits')
        keys = len(self.first)
        self.rows = [operator.itemgetter(keep, *(place + keys for place in inits)) for keep, *inits in shared]

    def each(self, residual: Residual) -> Table:
        """Charges priced program by program."""
        ties = self.ties
        table: Table = []
        for i, (distinct, own) in enumerate(zip(self.distinct, self.own)):
            values = [residual(i, mask) for mask in distinct]
            table.append([values[k] - tie for k, tie in zip(own, ties)])
        return table

    def alike(self, residual: Residual) -> Table:
        """Charges of a residual that sees a program only through `alike`."""
        values = [residual(i, mask) for i, mask in self.first]
        values += [value - TIE for value in values]
        return [row(values) for row in self.rows]
