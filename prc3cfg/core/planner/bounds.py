"""Lower bounds on what a plan costs: they let the search skip what cannot beat the best plan found.

- `floor_of`: a program's differences at their cheapest, every item with its share of a header;
- `HeadersBound`: a write phase's differences with the headers counted in whole messages;
- `inits_floor`: any plan with an init.

Owns the bounds. Does not own the search that uses them (`write_phase`, `init_search`).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from math import fsum

from prc3cfg.core.image import PROGRAM_COUNT
from prc3cfg.core.planner.layout import members
from prc3cfg.core.planner.pricing import ADDRESSES, FIELDS, PARTS, Prices
from prc3cfg.core.planner.problem import A_BIT, FIELD_BIT, P_BIT, PV_BITS, V_BIT, PlanningProblem
from prc3cfg.core.planner.terms import INF, KIND_OF_BIT, PLAIN_BITS, Residual, Table


def floor_of(prices: Prices, target_a: Sequence[int], changed: dict[int, int]) -> Residual:
    """What the differences `mask` of program i cost at least, in any write phase where at most
    the programs in `changed` (per FIELD_BIT) have an item of each field: each at its cheapest,
    every item with its share of a header. A field of n <= N items needs ceil(n/15) headers: at
    least n/15 of one, and one at least n/N of one — so header / min(N, 15) an item (31 for 46h;
    a 33h run carries its header over at most 15 programs, and at most all that need P or V; a
    32h writes one program's P and V alone)."""

    def share(bit: int, header: float, capacity: int) -> float:
        return header / max(min(changed[bit].bit_count(), capacity), 1)

    field = {bit: prices.item(kind) + share(bit, prices.header(kind), kind.capacity)
             for bit, kind in KIND_OF_BIT.items()}
    address = field[A_BIT]
    needers = max(min((changed[P_BIT] | changed[V_BIT]).bit_count(), PARTS.capacity), 1)
    pair, single = prices.parts_item + prices.parts_header / needers, prices.parts(1)  # a 33h's share, a 32h

    def cost(i: int, mask: int) -> float:
        total = fsum(field[bit] for bit in PLAIN_BITS if mask & bit)
        if mask & PV_BITS:
            total += min(pair, single, fsum(field[bit] for bit in (P_BIT, V_BIT) if mask & bit))
        if mask & A_BIT and target_a[i] not in (0, i + 2):
            total += address
        return min(total, prices.program)

    return cost


def over_every_kind(problem: PlanningProblem) -> dict[int, int]:
    """Per FIELD_BIT, the programs that differ in it under some init kind."""
    union = [0] * PROGRAM_COUNT
    for masks in problem.masks.values():
        union = [u | m for u, m in zip(union, masks)]
    return {bit: sum(1 << i for i, u in enumerate(union) if u & bit) for bit in FIELD_BIT.values()}


def inits_floor(problem: PlanningProblem, floors: Table) -> float:
    """No plan with an init costs less: its init messages and each program's differences at their
    cheapest under its init kind (`floors`: `floor_of`, every field's items counted over every
    kind, as `Charges`), for the init choice with at least one init where that is least
    (`init_dp.choose_inits`' DP, with whether an init has been sent yet in the state)."""
    prices, count = problem.prices, len(problem.kinds) - 1
    refund, init_range = prices.init_range - prices.init, prices.init_range
    # states once an init has been sent: 0 kept; 2n - 1 after the first program of a run of the
    # n-th init kind, 2n further on; `before`: no init sent yet (every program so far kept)
    size = 1 + 2 * count
    before, cost = 0.0, [INF] * size
    for i, row in enumerate(floors):
        # per kind
        closed = [cost[0], *(min(cost[2 * n - 1] - refund, cost[2 * n]) for n in range(1, count + 1))]
        least, then = sorted(closed)[:2]  # the least of the others' is `then` where it is `least`
        new = [least + row[0], *[INF] * (size - 1)]
        if problem.managed[i]:
            for n in range(1, count + 1):
                new[2 * n - 1] = min(before, then if closed[n] == least else least) + init_range + row[n]
                new[2 * n] = min(cost[2 * n - 1], cost[2 * n]) + row[n]
        before += row[0]
        cost = new
    return problem.system_cost + min(c - (refund if state else 0.0) for state, c in enumerate(cost))


class HeadersBound:
    """`at_least` of one write phase, remembered by its arguments."""

    def __init__(self, prices: Prices, masks: list[int], target_a: Sequence[int], changed: dict[int, int],
                 relevant_programs: int) -> None:
        self.prices, self.masks, self.target_a, self.changed = prices, masks, target_a, changed
        self.relevant_programs = relevant_programs
        self.pv_changed = changed[P_BIT] | changed[V_BIT]
        self._at_least: dict[tuple[int, int], float] = {}

    @functools.cached_property
    def _items(self) -> tuple[int, list[float]]:
        """The programs whose jump address takes a 46h item (or a 21h), and each program's
        differences as items at their cheapest (`at_least`)."""
        prices, target_a = self.prices, self.target_a
        itemised = sum(1 << i for i, m in enumerate(self.masks)
                       if m & A_BIT and target_a[i] not in (0, i + 2))
        by_mask: dict[int, float] = {}
        costs = []
        for i, mask in enumerate(self.masks):
            key = mask | (itemised >> i & 1) << len(FIELD_BIT)
            if (cost := by_mask.get(key)) is None:
                total = [prices.field_item for bit in PLAIN_BITS if mask & bit]
                if mask & PV_BITS:
                    total.append(min(prices.parts_item, prices.field_item * (mask & PV_BITS).bit_count()))
                if itemised >> i & 1:
                    total.append(prices.address_item)
                cost = by_mask[key] = fsum(total)
            costs.append(cost)
        return itemised, costs

    def at_least(self, whole: int, ranges: int = 0) -> float:
        """No write phase that gives at least `whole` a 21h (and has `ranges` link and unlink
        ranges) costs less, its headers counted whole.

        Each of those 21h; each other program's differences as items at their cheapest (P and V
        as a 33h's share or 40h/41h items) or as a 21h of its own; and the headers that the
        items left need, in whole messages: w more 21h take at most w items out of each field,
        so a field of n items needs ceil((n - w) / 15) messages (46h: 31) — and P and V, with R
        33h runs of at most 15 programs, the 40h and 41h for the rest (`_pv_headers`). A jump
        address a link or unlink range can give costs a range, or an item each, or its 21h.
        The least over w, the w programs whose 21h cost least beyond their items.
        """
        if (known := self._at_least.get((whole, ranges))) is not None:
            return known
        prices, (itemised, items) = self.prices, self._items
        rest = self.relevant_programs & ~whole
        spent = [items[i] for i in members(rest)]
        extra = sorted(prices.program - c for c in spent)
        plain = [(prices.header(KIND_OF_BIT[bit]), KIND_OF_BIT[bit], (self.changed[bit] & ~whole).bit_count())
                 for bit in PLAIN_BITS]
        addresses = (itemised & ~whole).bit_count()
        ranged = (self.changed[A_BIT] & ~itemised & ~whole).bit_count()
        p, v = (self.changed[P_BIT] & ~whole).bit_count(), (self.changed[V_BIT] & ~whole).bit_count()
        both = (self.pv_changed & ~whole).bit_count()
        least, paid = INF, 0.0
        for w in range(len(extra) + 1):
            if w:
                paid += extra[w - 1]
            if paid >= least and (w == len(extra) or extra[w] >= 0):
                break  # more 21h, each costing more than its items: no fewer headers pay for them
            headers = fsum((
                *(header * kind.messages(n - w) for header, kind, n in plain),
                prices.address_header * ADDRESSES.messages(addresses - w),
                self._pv_headers(p - w, v - w, both - w),
                max(ranges * prices.link,
                    min(prices.link, (ranged - w) * prices.address_item) if ranged > w else 0.0),
            ))
            least = min(least, paid + headers)  # two floats: rounded once, as fsum's sum is
        known = self._at_least[whole, ranges] = fsum((whole.bit_count() * prices.program, *spent, least))
        return known

    def _pv_headers(self, p: int, v: int, both: int) -> float:
        """The headers of P and V at least, for `p` programs that differ in P, `v` in V, `both` in either:
        with R 33h (or 32h), each over at most 15 of them, the rest need 40h for P and 41h for V."""
        prices, capacity = self.prices, PARTS.capacity
        run, header, least = min(prices.parts_header,
                                 prices.parts(1) - prices.parts_item), prices.field_header, INF
        for r in range(PARTS.messages(both) + 1):
            covered = capacity * r  # a sum of two floats is rounded once, as fsum's is
            value = r * run + header * max(FIELDS.messages(p - covered) + FIELDS.messages(v - covered),
                                           FIELDS.messages(both - covered))
            if value < least:
                least = value
        return least
