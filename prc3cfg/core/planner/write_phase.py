"""The write phase for one choice of init kinds: which messages write what the bases leave different.

Per program, a 21h, or its P and V in a 33h run (at most 15 consecutive managed programs, which may
include programs that need no change: their desired P, V are rewritten; a run of one is a 32h) or as
40h/41h items (`parts_dp`), its other fields as 42h..45h items and its jump address by a link or
unlink range or a 46h item (`address_dp`) — the jump addresses first. `WritePhase.solve` tries the
46h open and shut and, where the DPs' field-by-field view misses it, a field's or a run's programs
written whole together (`_groups_whole`). `whole_programs` is the fallback that is never dearer than
the naive download.

Owns a write phase. Does not own the choice of inits (`init_search`) or building messages (`layout`).
"""

from __future__ import annotations

import functools
from math import fsum

from prc3cfg.core.image import PROGRAM_COUNT
from prc3cfg.core.planner.address_dp import AddressDP, Addresses
from prc3cfg.core.planner.bounds import HeadersBound, floor_of
from prc3cfg.core.planner.layout import Layout, Writes
from prc3cfg.core.planner.parts_dp import Parts, solve_parts
from prc3cfg.core.planner.pricing import PARTS
from prc3cfg.core.planner.problem import A_BIT, FIELD_BIT, KEEP, P_BIT, V_BIT, PlanningProblem
from prc3cfg.core.planner.terms import (
    ESTIMATE,
    FIELDS_OF,
    INF,
    NEAR,
    PLAIN_BITS,
    PLAIN_MASK,
    Channels,
    Kinds,
    Range,
    Run,
)


class WritePhase:
    """The write phase for one choice of init kinds: its bases, masks and the exact DPs over them."""

    def __init__(self, problem: PlanningProblem, kinds: Kinds) -> None:
        self.problem, self.kinds = problem, kinds
        self.prices = problem.prices
        self.managed = problem.managed
        self.masks = masks = [problem.masks[k][i] for i, k in enumerate(kinds)]
        self.target_a = problem.target_a
        changed = dict.fromkeys(FIELD_BIT.values(), 0)  # per field, the programs that differ in it
        relevant = relevant_programs = 0
        for i, m in enumerate(masks):
            if m:
                relevant |= m
                relevant_programs |= 1 << i
                for bit in FIELDS_OF[m]:
                    changed[bit] |= 1 << i
        self.relevant, self.relevant_programs = relevant, relevant_programs
        self.changed = changed
        self.pv_changed = changed[P_BIT] | changed[V_BIT]
        self._parts_cache: dict[tuple[int, int, bool, bool, bool], Parts] = {}
        self._address_cache: dict[tuple[int, bool], tuple[Addresses, ...]] = {}

    # Worked out when first asked: most init choices' phases are only bounded (`floor`), never searched.

    @functools.cached_property
    def base_a(self) -> list[int]:
        """Each program's jump address after its init kind (and the system step)."""
        bases = self.problem.bases
        return [bases[k][i].A for i, k in enumerate(self.kinds)]

    @functools.cached_property
    def parts_price(self) -> list[float]:
        """P and V of n programs (a 32h, a 33h) by n; INF for none."""
        return [INF, *(self.prices.parts(n) for n in range(1, PARTS.capacity + 1))]

    @functools.cached_property
    def plain_items(self) -> list[float]:
        """What a 21h of each program saves in plain items."""
        return [(m & PLAIN_MASK).bit_count() * self.prices.field_item for m in self.masks]

    # -- the channel subsets ---------------------------------------------------------------

    def subsets(self) -> list[Channels]:
        """46h open, then shut (where some program differs in A): every other choice of messages
        is the DP's (`parts_dp.PartsDP`)."""
        plain = self.relevant & PLAIN_MASK
        return [Channels(plain, True, True, True, addresses)
                for addresses in ((True, False) if self.relevant & A_BIT else (False,))]

    def solve(self, bound: float = INF) -> list[Writes]:
        """The cheapest write phases found, with the 46h open and shut, cheapest first; none that
        cannot beat `bound`."""
        found: list[Writes] = []
        for channels in self.subsets():
            writes = self.evaluate(channels, bound)
            if writes is not None:
                writes = self._groups_whole(channels, writes)
                found.append(writes)
                bound = min(bound, writes.estimate)
        return sorted(found, key=ESTIMATE)

    def _groups_whole(self, channels: Channels, writes: Writes) -> Writes:
        """`writes`, or cheaper: the programs of one of its 40h..46h fields or 33h runs written whole
        (21h), the rest of the phase searched again — until no such group pays.

        The DP credits 21h only with the header of the first message of a field they empty
        (`parts_dp.live_channels`: removals up to `rho`), and judges each field alone: 21h that pay only by
        emptying a field of more than one message, or several fields and a run together, it does not see.
        """
        while True:
            groups = {mask for mask in (*writes.items, writes.addresses) if mask}
            groups.update(sum(1 << i for i in range(first, last + 1)) for first, last in writes.part_runs)
            better = writes
            for mask in sorted(groups):
                found = self.evaluate(channels, better.estimate - NEAR, whole=writes.whole | mask)
                if found is not None and found.estimate < better.estimate - NEAR:
                    better = found
            if better is writes:
                return writes
            writes = better

    def forced(self, channels: Channels) -> int:
        """Programs that differ in a field no open message writes: they take a 21h."""
        whole = 0
        for bit in PLAIN_BITS:
            if not channels.plain & bit:
                whole |= self.changed[bit]
        if not channels.parts:
            if not channels.positions:
                whole |= self.changed[P_BIT]
            if not channels.speeds:
                whole |= self.changed[V_BIT]
        return whole

    def evaluate(self, channels: Channels, bound: float = INF, whole: int = 0) -> Writes | None:
        """The cheapest write phase with these channels (and 21h for `whole`); None when it cannot beat
        `bound`."""
        whole |= self.forced(channels)
        if bound < INF and self.at_least(whole) >= bound:
            return None
        # The jump-address DP prices 46h items one by one against link and unlink ranges; where they
        # overflow into one more message, it also gives the cheapest addresses in each fewer message
        # (`addresses`): each is tried with the rest of the write phase, where its ranges and the 21h
        # it needs could beat the cheapest so far.
        cheapest: Writes | None = None
        for found in self.addresses(whole, channels.addresses):
            limit = bound if cheapest is None else min(bound, cheapest.estimate)
            if limit < INF and self.at_least(whole | found.whole, len(found.ranges)) >= limit:
                continue
            writes = self._with_addresses(whole, channels, found)
            if cheapest is None or writes.estimate < cheapest.estimate:
                cheapest = writes
        return cheapest

    def _with_addresses(self, whole: int, channels: Channels, found: Addresses) -> Writes:
        ranges, addresses, extra = found
        whole |= extra
        runs, positions, speeds, more, runs_cost = self.parts(whole, addresses, channels)
        whole |= more
        items = (positions, speeds, *(self.changed[bit] & ~whole for bit in PLAIN_BITS))
        return self._priced(whole, runs, runs_cost, items, ranges, addresses & ~whole)

    @functools.cached_property
    def floor(self) -> float:
        """No write phase of these init kinds costs less (`floor_of`: quicker than `at_least`, less tight)."""
        at_least, priced = floor_of(self.prices, self.target_a, self.changed), {}
        keys = [(i, m, self.alike(i, m)) for i, m in enumerate(self.masks) if m]
        for i, m, key in keys:
            if key not in priced:
                priced[key] = at_least(i, m)
        return fsum(priced[key] for _, _, key in keys)

    @functools.cached_property
    def _bound(self) -> HeadersBound:
        return HeadersBound(self.prices, self.masks, self.target_a, self.changed, self.relevant_programs)

    def at_least(self, whole: int, ranges: int = 0) -> float:
        """No write phase that gives at least `whole` a 21h (and has `ranges` link and unlink ranges)
        costs less, its headers counted whole (`bounds.HeadersBound.at_least`)."""
        return self._bound.at_least(whole, ranges)

    def _priced(self, whole: int, runs: tuple[Run, ...], runs_cost: float, items: tuple[int, ...],
                ranges: tuple[Range, ...], addresses: int) -> Writes:
        prices = self.prices
        estimate = fsum((
            whole.bit_count() * prices.program,
            runs_cost,
            *(prices.fields(mask.bit_count()) for mask in items),
            len(ranges) * prices.link,
            prices.addresses(addresses.bit_count()),
        ))
        return Writes(whole, runs, items, ranges, addresses, estimate)

    # -- P and V (33h/32h runs, 40h/41h items) and the 21h: one DP ------------------------------

    def parts(self, whole: int, addresses: int, channels: Channels) -> Parts:
        """P and V of the programs not in `whole` that differ in P or V, and which programs take a 21h.

        `addresses`: the programs with a 46h item (a 21h saves it). The DP (`parts_dp.PartsDP`)
        charges every 40h/41h header as its items open it, and the headers of 42h..46h that
        21h save where a few more could save one (`parts_dp.live_channels`).
        """
        key = (whole, addresses, channels.positions, channels.speeds, channels.parts)
        cached = self._parts_cache.get(key)
        if cached is None:
            cached = self._parts_cache[key] = solve_parts(self, whole, addresses, channels)
        return cached

    # -- A: link/unlink ranges against 46h items -----------------------------------------------

    def addresses(self, whole: int, open46: bool) -> tuple[Addresses, ...]:
        """The jump addresses of the programs not in `whole`: link and unlink ranges, 46h items
        (when `open46`) or a 21h — the cheapest with 46h items priced one by one, and where those
        overflow a message, the cheapest in each fewer 46h message (`AddressDP`)."""
        key = (whole, open46)
        cached = self._address_cache.get(key)
        if cached is None:
            cached = self._address_cache[key] = self._address_dp.solve(whole, open46)
        return cached

    @functools.cached_property
    def _address_dp(self) -> AddressDP:
        return AddressDP(self.prices, self.managed, self.target_a, self.base_a, self.changed[A_BIT])

    # -- what a program's differences cost, for the init DP ------------------------------------

    def alike(self, i: int, mask: int) -> object:
        """What `linear` and `shared` see of program i with differences `mask`: the mask, and
        whether a link or unlink range could give its jump address."""
        return (mask, self.target_a[i] in (0, i + 2)) if mask & A_BIT else mask


def whole_programs(problem: PlanningProblem) -> Layout:
    """The system step, then a 21h for every program that still differs (a link or unlink range
    where only a jump address does and that is cheaper): never dearer than the naive download."""
    keep = (KEEP,) * PROGRAM_COUNT
    writes = WritePhase(problem, keep).evaluate(Channels.everything(False))
    assert writes is not None
    return Layout(keep, writes, problem.system_cost + writes.estimate)
