"""The search for the cheapest plan of one module.

Bus time is dominated by the fixed cost of an exchange (turnaround, frame overhead, the
reply, open-driver gaps), so the question is which *messages* to open, not which bytes
to send. The search is built around that:

1. **The write phase** (`WritePhase`), for one choice of init kinds, is dynamic programming
   over program numbers 1..64 (`PartsDP`) that decides, per program, a 21h,
   or its P and V in a 33h run (at most 15 consecutive managed programs, which may include
   programs that need no change: their desired P, V are rewritten; a run of one is a 32h) or
   as 40h/41h items — with the headers in the state, not priced item by item: the room left
   in the last 40h and 41h (the item that opens one pays its header, so a 40h is opened, or
   not, where that pays), and, per 42h..46h field where more 21h could save a message
   (`_live`), the programs a 21h took out of it, up to those that save it one. So 21h that
   save messages only together are found: four programs written whole so that the other 60
   fit four messages of each field, not five, and four 33h runs of 15 — and a 42h..45h with
   a few items is shut where 21h cost less than its header. States that cannot win whatever
   follows are dropped (`States`), a few at most go on. Jump addresses come first, from a
   DP of their own: link (30h) and unlink (31h) ranges against 46h items, with the 46h open
   and shut (its misses a 21h), a table of moves (`ADDRESS_MOVES`); where 46h items overflow
   a message, the same DP with the items counted in its states gives the cheapest addresses in
   each fewer message, exactly (`_fewer_messages`).
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
   close ones exactly and keeps the cheapest. `whole_programs` is the fallback that is
   never dearer than the naive download.

Prices are added with `math.fsum` wherever they are compared (Python 3.12's `sum()` of floats
rounds otherwise than 3.11's: a near-tie must be decided alike on every version, or a plan made
on one is refused as edited on the other).

Long because it is one search: the write phase's DP (`WritePhase`, `PartsDP`), the init DP and
the init search that feeds it (`InitSearch`: neighbours, header targets) and the bounds that prune
both share the priced masks of `problem`, the state types and each other's candidates; split, each
part would need the others' reasons.
Prices come from `prc3cfg.core.planner.pricing`, bases and masks from `prc3cfg.core.planner.problem`.
Owns the search. Does not own building messages (`layout`) or checking the result (the
caller runs it on `prc3cfg.core.device`).
"""

from __future__ import annotations

import functools
import heapq
import itertools
import operator
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from enum import Enum, IntEnum
from math import fsum
from typing import NamedTuple

from prc3cfg.core import codec
from prc3cfg.core.image import PROGRAM_COUNT
from prc3cfg.core.planner.layout import Layout, Writes, init_runs, members, runs_of
from prc3cfg.core.planner.pricing import Prices
from prc3cfg.core.planner.problem import (
    A_BIT,
    FIELD_BIT,
    INIT_AFTER,
    INIT_BEFORE,
    KEEP,
    P_BIT,
    PLAIN_FIELDS,
    PV_BITS,
    V_BIT,
    PlanningProblem,
)

INF = float("inf")
#: What a program (index) with a difference mask costs to fix, in seconds.
Residual = Callable[[int, int], float]
#: An init kind (`problem` KEEP, INIT_BEFORE, INIT_AFTER) per program.
Kinds = tuple[int, ...]
#: A start of a 33h run in `PartsDP`: best[i] - per × i, i, the state at i, the programs inside the run
#: that take a 21h as well.
Start = tuple[float, int, int, int]
#: The starts of the 33h runs that may end at the next program, for one state of `PartsDP`, by i,
#: keys increasing — the front is the cheapest start. A start added drops those before it that cost
#: as much or more: it lasts longer.
Window = deque[Start]
#: Per program, a charge (seconds) per init kind, in the order of `problem.kinds` (`Charges`).
Table = list[Sequence[float]]
#: First and last index of consecutive programs (a 33h run).
Run = tuple[int, int]
#: A link (True) or unlink range: (link?, first, last index), a 30h or 31h.
Range = tuple[bool, int, int]
PLAIN_BITS = tuple(FIELD_BIT[name] for name in PLAIN_FIELDS)
#: The bits of `PLAIN_FIELDS` as one mask.
PLAIN_MASK = sum(PLAIN_BITS)
#: The field bits of each difference mask.
_FIELDS_OF = [tuple(bit for bit in FIELD_BIT.values() if mask & bit) for mask in range(1 << len(FIELD_BIT))]
#: The fields of 40h..45h, in `Writes.items` order.
ITEM_BITS = (P_BIT, V_BIT, *PLAIN_BITS)
ESTIMATE = operator.attrgetter("estimate")
_second = operator.itemgetter(1)
_rho = operator.attrgetter("rho")
#: A bias far below any price (seconds): ties between keeping and initialising go to initialising.
TIE = 1e-9
#: Costs closer than this (seconds) are the same cost, the difference rounding's (the DP's sums of the
#: same prices in another order): a state the same cost as one ahead of it is beaten (`States`).
#: `States.windows_kept` rounds its starts' costs to NEAR_DIGITS to sort them.
NEAR_DIGITS = 12
NEAR = 10.0**-NEAR_DIGITS
#: Items per message assumed by one of the init choices (few items: headers matter).
INIT_SHARE = 4
#: How many init choices' write phases one module's `InitSearch` searches (the CPU of a plan must not
#: depend on the kind of change). Better plans come from the first few: searching half as many more
#: after each better plan, up to three times as many, changed no message of 1,680 plans of the change
#: mixes of `bench/plan_time_bench.py` or of `bench/plan_bench.py`'s, and cost planning the random mix a
#: tenth of its CPU where the turnaround is short (0 ms), a few per cent at 10 ms.
SEARCHED = 8
#: The most 42h..46h fields (alike ones as one) `PartsDP` counts removals of:
#: those that need fewest.
LIVE = 4
#: The most states `PartsDP` keeps after each program (`States`); runs going on, once twice as
#: many, are cut to as many and UNCREDITED more.
BEAM = 24
#: Runs going on kept by their cheapest start alone, beside the BEAM kept once credited (`States.windows_kept`).
UNCREDITED = 8
#: Probes of the header shares that make the init DP take a field's overflow out (`_header_targets`).
TARGET_PROBES = 4
#: Items of the overflow an init choice of `_header_targets` may leave for a 21h to take out.
SLACK_ITEMS = 2
#: Jump addresses above what fewer 46h messages hold that `WritePhase._fewer_messages` leaves for
#: 21h to take out (`PartsDP` counts them: a program written whole for its other fields takes its
#: address item out too).
ADDRESS_SLACK = 5
#: How many init choices closest to the best (within an exchange) `_header_targets` starts from in each round.
TARGETED = 4


@dataclass(frozen=True, slots=True)
class Channels:
    """The per-field messages a candidate may use."""

    plain: int  # FIELD_BIT mask of the Vr, T, F1, F2 whose 42h..45h is open
    positions: bool  # 40h
    speeds: bool  # 41h
    parts: bool  # 33h / 32h
    addresses: bool  # 46h

    @classmethod
    def everything(cls, open_: bool) -> Channels:
        return cls(PLAIN_MASK if open_ else 0, open_, open_, open_, open_)


#: Bits of a field of a `States` state (values up to 31, and a guard bit) and the mask of one.
STATE_BITS = 6
FIELD = (1 << (STATE_BITS - 1)) - 1
#: A state's fields but its rooms (the live fields' removals).
NOT_ROOMS = ~(FIELD | FIELD << STATE_BITS)
#: A back pointer of `PartsDP`: the state before, the move, the program it starts
#: at, and the programs a run it ends passes over with a 21h.
Back = tuple[int, "PartsMove", int, int]


class PartsMove(Enum):
    """How the P and V DP (`PartsDP`) covers a program: its backtracking's actions.

    The DPs bind the members they use to locals: looking a member up on its class costs more
    than the rest of a DP step (the class's metaclass has a `__getattr__`).
    """

    NOTHING = "no P or V to write"
    ITEMS = "40h/41h items"
    WHOLE = "a 21h"
    RUN = "a 33h run (a 32h alone) from the program in the back pointer to this one"


class Parts(NamedTuple):
    """P and V of the programs left, as the DP writes them (`WritePhase.parts`)."""

    runs: tuple[Run, ...]  # 33h/32h
    positions: int  # 40h items
    speeds: int  # 41h items
    whole: int  # programs better off with a 21h
    runs_cost: float


class RangeMove(Enum):
    """What the jump-address DP (`WritePhase._solve_addresses`) does at a program: its backtracking's actions.

    A link range gives a program the address of the next (i+2 by number), an unlink range 0;
    the last program of a link range is unlinked by it (0). A range may hold one of the other
    kind inside it, sent after it: an unlink range with a link range inside (two messages where
    side by side they take three), a link range with an unlink range inside (the program before
    the unlink range still jumps to its first, which no link range ending there can give).
    """

    NONE = "no way to get here"
    KEEP = "outside every range: the base's address"
    LINK = "a link range starts"
    LINK_ON = "a link range goes on"
    END = "a link range ends"
    UNLINK = "an unlink range starts"
    UNLINK_ON = "an unlink range goes on"
    INNER_LINK = "a link range starts inside an unlink range"
    INNER_LINK_ON = "a link range inside an unlink range goes on"
    INNER_END = "a link range inside an unlink range ends (the unlink range may go on)"
    INNER_UNLINK = "an unlink range starts inside a link range (which goes on)"
    INNER_UNLINK_ON = "an unlink range inside a link range goes on"
    INNER_UNLINK_END = "an unlink range inside a link range ends (the link range goes on)"
    INNER_UNLINK_ONE = "an unlink range of one program inside a link range (which goes on)"


class Gives(IntEnum):
    """The address a move of the jump-address DP gives its program."""

    KEEP = 0  # the base's
    ZERO = 1  # 0: an unlink range, or a link range's last program
    NEXT = 2  # the next program's number: a link range


#: The jump-address DP's moves (`WritePhase._solve_addresses`), in the order its ties go to the
#: first: (state after program i, state after i-1, the move, whether it starts a range (one 30h
#: or 31h more), the address it gives program i, whether a range goes on past i, so program i+1
#: must be managed). States: 0 no range open; 1 a link range goes on to i+1; 2 an unlink range
#: covers i (and may go on); 3 a link range inside an unlink range goes on to i+1; 4 an unlink
#: range inside a link range covers i and goes on, the link range too.
ADDRESS_MOVES: tuple[tuple[int, int, RangeMove, bool, Gives, bool], ...] = (
    (0, 0, RangeMove.KEEP, False, Gives.KEEP, False),
    (0, 2, RangeMove.KEEP, False, Gives.KEEP, False),
    (0, 1, RangeMove.END, False, Gives.ZERO, False),
    (1, 0, RangeMove.LINK, True, Gives.NEXT, True),
    (1, 2, RangeMove.LINK, True, Gives.NEXT, True),
    (1, 1, RangeMove.LINK_ON, False, Gives.NEXT, True),
    (1, 1, RangeMove.INNER_UNLINK_ONE, True, Gives.ZERO, True),
    (1, 4, RangeMove.INNER_UNLINK_END, False, Gives.ZERO, True),
    (2, 0, RangeMove.UNLINK, True, Gives.ZERO, False),
    (2, 2, RangeMove.UNLINK_ON, False, Gives.ZERO, False),
    (2, 3, RangeMove.INNER_END, False, Gives.ZERO, False),
    (3, 2, RangeMove.INNER_LINK, True, Gives.NEXT, True),
    (3, 3, RangeMove.INNER_LINK_ON, False, Gives.NEXT, True),
    (4, 1, RangeMove.INNER_UNLINK, True, Gives.ZERO, True),
    (4, 4, RangeMove.INNER_UNLINK_ON, False, Gives.ZERO, True),
)
#: The moves where no range goes on past program i (i is the last managed program of a run of them).
ENDING_MOVES = tuple(move for move in ADDRESS_MOVES if not move[5])
#: The states a program outside the plan file leaves (no range goes on over it): 0, from 0 or 2.
ADDRESS_STATES = 5
#: The moves of `RangeMove` that give a program the address of the next.
NEXT_MOVES = frozenset((RangeMove.LINK, RangeMove.LINK_ON, RangeMove.INNER_LINK, RangeMove.INNER_LINK_ON))
#: The moves that start a range inside another, and those that start an outer one.
INNER_STARTS = frozenset((RangeMove.INNER_LINK, RangeMove.INNER_UNLINK, RangeMove.INNER_UNLINK_ONE))
OUTER_STARTS = frozenset((RangeMove.LINK, RangeMove.UNLINK))
#: The moves where an inner range goes on past the program.
INNER_GOING = frozenset((RangeMove.INNER_LINK, RangeMove.INNER_LINK_ON, RangeMove.INNER_UNLINK, RangeMove.INNER_UNLINK_ON))


class Addresses(NamedTuple):
    """Jump addresses of the programs left, as the DP writes them (`WritePhase.addresses`)."""

    ranges: tuple[Range, ...]
    items: int  # 46h items
    whole: int  # programs whose A only a 21h can write (46h shut)


class ItemChannel(NamedTuple):
    """One 40h..46h field of a write phase."""

    bit: int  # FIELD_BIT
    mask: int  # the programs with an item
    capacity: int  # items per message


class LiveChannel(NamedTuple):
    """42h..46h fields with the same items, whose removals by 21h `PartsDP` counts."""

    mask: int  # the programs with an item
    n: int  # how many
    rho: int  # removals that save a message
    capacity: int  # items per message
    header: float  # the headers of those fields, together


class Overflow(NamedTuple):
    """A field whose items overflow into one more message, which inits could take out (`_overflows`)."""

    bit: int  # FIELD_BIT
    goal: int  # the items that fit one message less
    over: int  # items above the goal
    counted: int  # the programs counted (P and V: those outside 33h runs)


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
                for bit in _FIELDS_OF[m]:
                    changed[bit] |= 1 << i
        self.relevant, self.relevant_programs = relevant, relevant_programs
        self.changed = changed
        self.pv_changed = changed[P_BIT] | changed[V_BIT]
        self._at_least: dict[tuple[int, int], float] = {}
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
        return [INF, *(self.prices.parts(n) for n in range(1, codec.MAX_FIELD_ITEMS + 1))]

    @functools.cached_property
    def plain_items(self) -> list[float]:
        """What a 21h of each program saves in plain items."""
        return [(m & PLAIN_MASK).bit_count() * self.prices.field_item for m in self.masks]

    # -- the channel subsets ---------------------------------------------------------------

    def subsets(self) -> list[Channels]:
        """46h open, then shut (where some program differs in A): every other choice of messages
        is the DP's (`PartsDP`)."""
        plain = self.relevant & PLAIN_MASK
        return [Channels(plain, True, True, True, addresses) for addresses in ((True, False) if self.relevant & A_BIT else (False,))]

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
        (`_live`: removals up to `rho`), and judges each field alone: 21h that pay only by emptying
        a field of more than one message, or several fields and a run together, it does not see.
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
        """The cheapest write phase with these channels (and 21h for `whole`); None when it cannot beat `bound`."""
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
    def _items(self) -> tuple[int, list[float]]:
        """The programs whose jump address takes a 46h item (or a 21h), and each program's
        differences as items at their cheapest (`at_least`)."""
        prices, target_a = self.prices, self.target_a
        itemised = sum(1 << i for i, m in enumerate(self.masks) if m & A_BIT and target_a[i] not in (0, i + 2))
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
        plain = [(self.changed[bit] & ~whole).bit_count() for bit in PLAIN_BITS]
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
                *(prices.field_header * _messages(n - w, codec.MAX_FIELD_ITEMS) for n in plain),
                prices.address_header * _messages(addresses - w, codec.MAX_ADDRESS_ITEMS),
                self._pv_headers(p - w, v - w, both - w),
                max(ranges * prices.link, min(prices.link, (ranged - w) * prices.address_item) if ranged > w else 0.0),
            ))  # fmt: skip
            least = min(least, paid + headers)  # two floats: rounded once, as fsum's sum is
        known = self._at_least[whole, ranges] = fsum((whole.bit_count() * prices.program, *spent, least))
        return known

    def _pv_headers(self, p: int, v: int, both: int) -> float:
        """The headers of P and V at least, for `p` programs that differ in P, `v` in V, `both` in either:
        with R 33h (or 32h), each over at most 15 of them, the rest need 40h for P and 41h for V."""
        prices, capacity = self.prices, codec.MAX_FIELD_ITEMS
        run, header, least = min(prices.parts_header, self.parts_price[1] - prices.parts_item), prices.field_header, INF
        for r in range(_messages(both, capacity) + 1):
            covered = capacity * r  # a sum of two floats is rounded once, as fsum's is
            value = r * run + header * max(_messages(p - covered, capacity) + _messages(v - covered, capacity),
                                           _messages(both - covered, capacity))  # fmt: skip
            if value < least:
                least = value
        return least

    def _priced(self, whole: int, runs: tuple[Run, ...], runs_cost: float, items: tuple[int, ...],
                ranges: tuple[Range, ...], addresses: int) -> Writes:  # fmt: skip
        prices = self.prices
        estimate = fsum((
            whole.bit_count() * prices.program,
            runs_cost,
            *(prices.fields(mask.bit_count()) for mask in items),
            len(ranges) * prices.link,
            prices.addresses(addresses.bit_count()),
        ))  # fmt: skip
        return Writes(whole, runs, items, ranges, addresses, estimate)

    # -- P and V (33h/32h runs, 40h/41h items) and the 21h: one DP ------------------------------

    def parts(self, whole: int, addresses: int, channels: Channels) -> Parts:
        """P and V of the programs not in `whole` that differ in P or V, and which programs take a 21h.

        `addresses`: the programs with a 46h item (a 21h saves it). The DP (`PartsDP`)
        charges every 40h/41h header as its items open it, and the headers of 42h..46h that
        21h save where a few more could save one (`_live`).
        """
        key = (whole, addresses, channels.positions, channels.speeds, channels.parts)
        cached = self._parts_cache.get(key)
        if cached is None:
            cached = self._parts_cache[key] = self._solve_parts(whole, addresses, channels)
        return cached

    def _live(self, whole: int, addresses: int, need: int) -> list[LiveChannel]:
        """The 42h..46h fields whose message count more 21h could lower with profit, fields with
        the same programs as one (their headers summed: full rewrites differ in every field).

        A field saves its header once `rho` of its programs take a 21h, each costing at least
        `_extra_cost` beyond the items it saves. Its best candidates are the `rho` programs whose
        21h costs least less a share of the headers of the other fields it is in (the header over
        the removals that save it); they pay where their cost is below the headers they save
        together — the field's, each other field's whose removals they reach, and a 33h's where
        they take the programs that need P or V down by as many as fill the last run. A
        field where they do not is left out: its items are priced one by one (its header count
        is that of the programs left to it). Of the rest, the LIVE that need fewest removals."""
        prices = self.prices
        fields = [(self.changed[bit] & ~whole, codec.MAX_FIELD_ITEMS, prices.field_header) for bit in PLAIN_BITS]
        fields.append((addresses & ~whole, codec.MAX_ADDRESS_ITEMS, prices.address_header))
        grouped: dict[tuple[int, int], list[float]] = {}
        for mask, capacity, header in fields:
            if mask:
                grouped.setdefault((mask, capacity), []).append(header)
        channels = []
        for (mask, capacity), headers in grouped.items():
            n = mask.bit_count()
            channels.append(LiveChannel(mask, n, n - capacity * ((n - 1) // capacity), capacity, fsum(headers)))
        n = need.bit_count()  # a 33h saved too where the removals take the P and V left down a run
        runs_out = n - codec.MAX_FIELD_ITEMS * ((n - 1) // codec.MAX_FIELD_ITEMS) if n else PROGRAM_COUNT + 1
        live = []
        extra = {i: self._extra_cost(i, need, addresses) for i in members(_all_of(tuple(c.mask for c in channels)))}
        for c in channels:
            others = [o for o in channels if o is not c]
            ranked = sorted(members(c.mask), key=lambda i: extra[i] - fsum(o.header / o.rho for o in others if o.mask >> i & 1))
            chosen = ranked[: c.rho]
            spent = fsum(extra[i] for i in chosen)
            taken = sum(1 << i for i in chosen)
            saved = fsum((c.header, prices.parts_header if (need & taken).bit_count() >= runs_out else 0.0,
                          *(o.header for o in others if (o.mask & taken).bit_count() >= o.rho)))  # fmt: skip
            if spent < saved:
                live.append(c)
        return sorted(live, key=_rho)[:LIVE]

    def _extra_cost(self, i: int, need: int, addresses: int) -> float:
        """What a 21h of program i costs at least beyond the items it saves."""
        prices, m = self.prices, self.masks[i]
        pv = (prices.field_item if m & P_BIT else 0.0) + (prices.field_item if m & V_BIT else 0.0) if need >> i & 1 else 0.0
        return prices.program - self.plain_items[i] - (prices.address_item if addresses >> i & 1 else 0.0) - pv

    def _solve_parts(self, whole: int, addresses: int, channels: Channels) -> Parts:
        """The DP over program numbers behind `parts` (`PartsDP`)."""
        need = self.pv_changed & ~whole
        movable = (self.relevant_programs | addresses) & ~whole  # programs a 21h could help
        if not need and not movable:
            return Parts((), 0, 0, 0, 0.0)
        dp = PartsDP(self, need, movable, addresses, channels, self._live(whole, addresses, need))
        return self._traced(*dp.solve())

    def _traced(self, back: list[dict[int, Back]], state: int) -> Parts:
        """The writes of a `PartsDP`, followed back from the last program in `state`."""
        runs: list[Run] = []
        positions = speeds = whole = 0
        j = PROGRAM_COUNT
        while j > 0:
            state, move, i, inside = back[j - 1][state]
            if move is PartsMove.RUN:
                runs.append((i, j - 1))
                whole |= inside
                j = i
                continue
            if move is PartsMove.ITEMS:
                positions |= (self.masks[i] & P_BIT and 1) << i
                speeds |= (self.masks[i] & V_BIT and 1) << i
            elif move is PartsMove.WHOLE:
                whole |= 1 << i
            j -= 1
        runs.reverse()
        return Parts(tuple(runs), positions, speeds, whole, fsum(self.parts_price[last - first + 1] for first, last in runs))

    # -- A: link/unlink ranges against 46h items -----------------------------------------------

    def addresses(self, whole: int, open46: bool) -> tuple[Addresses, ...]:
        """The jump addresses of the programs not in `whole`: link and unlink ranges, 46h items
        (when `open46`) or a 21h — the cheapest with 46h items priced one by one, and where those
        overflow a message, the cheapest in each fewer 46h message (`_fewer_messages`)."""
        key = (whole, open46)
        cached = self._address_cache.get(key)
        if cached is None:
            cached = self._address_cache[key] = self._solve_addresses(whole, open46)
        return cached

    def _solve_addresses(self, whole: int, open46: bool) -> tuple[Addresses, ...]:
        if not self.changed[A_BIT] & ~whole:
            return (Addresses((), 0, 0),)
        steps = self._address_steps(whole)
        cheapest = self._ranges_and_misses(whole, open46, self._cheapest_moves(steps, open46))
        messages = -(-cheapest.items.bit_count() // codec.MAX_ADDRESS_ITEMS)
        if not messages:  # one 46h saved may pay for ranges: its header too, where ranges take every item
            return (cheapest,)
        return (cheapest, *(self._ranges_and_misses(whole, True, moves) for moves in self._fewer_messages(steps, messages)))

    def _address_steps(self, whole: int) -> list[tuple[bool, tuple[bool, bool, bool]] | None]:
        """What the jump-address DP sees of each program: None outside the plan file; else whether
        a range may go on past it (the next program is managed), and per `Gives` whether that
        address would be wrong (a 46h item or a 21h; never for a program a 21h writes anyway)."""
        managed, target, base = self.managed, self.target_a, self.base_a
        steps: list[tuple[bool, tuple[bool, bool, bool]] | None] = []
        for i in range(PROGRAM_COUNT):
            if not managed[i]:
                steps.append(None)
                continue
            free, t = whole >> i & 1, target[i]
            goes_on = i + 1 < PROGRAM_COUNT and managed[i + 1]
            steps.append((goes_on, (not free and base[i] != t, not free and t != 0, not free and t != i + 2)))
        return steps

    def _cheapest_moves(self, steps: list[tuple[bool, tuple[bool, bool, bool]] | None], open46: bool) -> list[RangeMove]:
        """The DP over program numbers (`ADDRESS_MOVES`) behind `addresses`: each wrong address
        costs a 46h item (when `open46`) or a 21h, each range its message."""
        miss = self.prices.address_item if open46 else self.prices.program
        link = self.prices.link
        cost = [0.0, INF, INF, INF, INF]
        back: list[dict[int, tuple[int, RangeMove]]] = []
        # per step as the DP sees it (a few kinds in all): each move's state after and before, and
        # what it adds in the order the sum is taken — a range's message, then the address's price
        priced_moves: dict[tuple[bool, tuple[bool, bool, bool]], list[tuple[int, int, RangeMove, float, float]]] = {}
        for step in steps:
            if step is None:
                came = 0 if cost[0] <= cost[2] else 2
                back.append({0: (came, RangeMove.KEEP)})
                cost = [cost[came], INF, INF, INF, INF]
                continue
            if (allowed := priced_moves.get(step)) is None:
                goes_on, wrong = step
                allowed = priced_moves[step] = [
                    (to, came, move, link, miss if wrong[gives] else 0.0) if starts else (to, came, move, miss if wrong[gives] else 0.0, 0.0)
                    for to, came, move, starts, gives, _ in (ADDRESS_MOVES if goes_on else ENDING_MOVES)
                ]  # fmt: skip
            new = [INF] * ADDRESS_STATES
            moves: dict[int, tuple[int, RangeMove]] = {}
            for to, came, move, first, then in allowed:
                c = cost[came] + first + then  # + 0.0 leaves a sum as it is
                if c < new[to]:
                    new[to], moves[to] = c, (came, move)
            cost = new
            back.append(moves)
        state = 0 if cost[0] <= cost[2] else 2
        found = [RangeMove.NONE] * PROGRAM_COUNT
        for i in range(PROGRAM_COUNT - 1, -1, -1):
            state, found[i] = back[i][state]
        return found

    def _fewer_messages(self, steps: list[tuple[bool, tuple[bool, bool, bool]] | None], messages: int) -> list[list[RangeMove]]:
        """The cheapest moves with each fewer 46h message than `messages`, where one exists: the DP of
        `_cheapest_moves` whose states also count the items so far — exact where pricing items one
        by one is not (one header saved may pay for ranges that no share of it on each item would
        draw) — and with up to ADDRESS_SLACK more, which 21h may take out (`PartsDP` counts them).
        Each state keeps the counts that cost less than every smaller count (a Pareto front), and
        none above what fewer messages hold with that slack."""
        most = codec.MAX_ADDRESS_ITEMS * (messages - 1) + ADDRESS_SLACK
        fronts: list[dict[int, float]] = [{0: 0.0}, {}, {}, {}, {}]
        back: list[list[dict[int, tuple[int, RangeMove, int]]]] = []
        for step in steps:
            fronts, moves = _outside(fronts) if step is None else self._counted_step(fronts, step, most)
            back.append(moves)
        # after the last program no range goes on, as after one outside the plan file: each count ends in 0 or 2
        (last, *_), (ends, *_) = _outside(fronts)
        found = []
        for n in _fewer_counts(last, messages):
            state = ends[n][0]
            moves_found = [RangeMove.NONE] * PROGRAM_COUNT
            for i in range(PROGRAM_COUNT - 1, -1, -1):
                state, moves_found[i], n = back[i][state][n]
            found.append(moves_found)
        return found

    def _counted_step(self, fronts: list[dict[int, float]], step: tuple[bool, tuple[bool, bool, bool]],
                      most: int) -> tuple[list[dict[int, float]], list[dict[int, tuple[int, RangeMove, int]]]]:  # fmt: skip
        """One managed program of `_fewer_messages`: each state's front after it, and how each count came."""
        link, item = self.prices.link, self.prices.address_item
        goes_on, wrong = step
        new: list[dict[int, float]] = [{} for _ in range(ADDRESS_STATES)]
        moves: list[dict[int, tuple[int, RangeMove, int]]] = [{} for _ in range(ADDRESS_STATES)]
        for to, came_from, move, starts, gives, _ in ADDRESS_MOVES if goes_on else ENDING_MOVES:
            more = 1 if wrong[gives] else 0
            added = (link if starts else 0.0) + (item if more else 0.0)
            into, how = new[to], moves[to]
            for n, c in fronts[came_from].items():
                if n + more <= most and c + added < into.get(n + more, INF):
                    into[n + more], how[n + more] = c + added, (came_from, move, n)
        return [_pareto(front) for front in new], moves

    def _ranges_and_misses(self, whole: int, open46: bool, moves: list[RangeMove]) -> Addresses:
        """The ranges the DP's moves draw — the outer ones, then those inside them, sent after
        them — and the programs whose address they leave wrong."""
        outer: list[Range] = []
        inner: list[Range] = []
        items = extra = 0
        keep = RangeMove.KEEP  # locals: fast
        for i, move in enumerate(moves):
            if not self.managed[i]:
                continue
            if move in OUTER_STARTS:
                outer.append((move is RangeMove.LINK, i, i))
            elif move is not keep:  # the outer range goes on or ends here
                outer[-1] = (*outer[-1][:2], i)
                if move in INNER_STARTS:
                    inner.append((move is RangeMove.INNER_LINK, i, i))
                elif move in INNER_GOING or move in (RangeMove.INNER_END, RangeMove.INNER_UNLINK_END):
                    inner[-1] = (*inner[-1][:2], i)
            value = self.base_a[i] if move is keep else i + 2 if move in NEXT_MOVES else 0
            if not whole >> i & 1 and value != self.target_a[i]:
                if open46:
                    items |= 1 << i
                else:
                    extra |= 1 << i
        return Addresses((*outer, *inner), items, extra)

    # -- what a program's differences cost, for the init DP ------------------------------------

    def alike(self, i: int, mask: int) -> object:
        """What `linear` and `shared` see of program i with differences `mask`: the mask, and
        whether a link or unlink range could give its jump address."""
        return (mask, self.target_a[i] in (0, i + 2)) if mask & A_BIT else mask

    def linear(self, share: float) -> Residual:
        """A program's differences priced item by item with every channel open, each item with `share`
        of a header (P and V one item: a 33h's)."""
        prices = self.prices
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

    def shared(self, shares: dict[int, float]) -> Residual:
        """A program's differences with every channel open, each item of a field in `shares` (by
        field bit) with that share of a header: P and V as a 33h pair unless one of them has a
        share, a jump address a link or unlink range can give as free (a range over initialised
        programs restores their chain), any other as a 46h item."""
        prices = self.prices
        pv_items = any(bit & PV_BITS for bit in shares)
        item = {bit: prices.field_item + shares.get(bit, 0.0) for bit in ITEM_BITS}
        address = prices.address_item + shares.get(A_BIT, 0.0)

        def cost(i: int, mask: int) -> float:
            total = fsum(item[bit] for bit in PLAIN_BITS if mask & bit)
            if mask & PV_BITS:
                total += fsum(item[bit] for bit in (P_BIT, V_BIT) if mask & bit) if pv_items else prices.parts_item
            if mask & A_BIT and self.target_a[i] not in (0, i + 2):
                total += address
            return min(total, prices.program)

        return cost

    def marginal(self, writes: Writes) -> Residual:
        """What a program's differences would add to `writes`, everything else staying as it is.

        Header-aware: a program that alone opens a message pays for the message, one that
        joins an open one pays its item, one inside a 33h run or a fitting link range nothing.
        """
        prices = self.prices
        # per field, what program i's item adds to the others' — by whether i is among its n items
        added = [(prices.fields(n + 1) - prices.fields(n) if n < PROGRAM_COUNT else INF, prices.fields(n) - prices.fields(n - 1) if n else INF)
                 for n in (mask.bit_count() for mask in writes.items)]  # fmt: skip
        addresses = writes.addresses.bit_count()
        need = self.pv_changed & ~writes.whole
        run_of = {i: (first, last) for first, last in writes.part_runs for i in range(first, last + 1)}
        ranged = {i: (i + 2 if link and i < last else 0) for link, first, last in writes.ranges
                  for i in range(first, last + 1)}  # fmt: skip

        (p_added, v_added, *_), (p_items, v_items, *_) = added, writes.items
        plain = list(zip(PLAIN_BITS, added[2:], writes.items[2:]))
        single = self.parts_price[1]

        def parts(i: int, mask: int) -> float:
            p = p_added[p_items >> i & 1] if mask & P_BIT else 0.0
            v = v_added[v_items >> i & 1] if mask & V_BIT else 0.0
            alone = min(single, p + v)  # one addition, rounded once as fsum's is
            return min(alone, self._joining(i, run_of[i], need)) if i in run_of else alone

        def jump(i: int, mask: int) -> float:
            if i in ranged:
                return 0.0 if ranged[i] == self.target_a[i] else prices.addresses(addresses + 1) - prices.addresses(addresses)
            if not mask & A_BIT:
                return 0.0
            n = addresses - (writes.addresses >> i & 1)
            single = prices.link if self.target_a[i] == 0 else INF
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

    def _joining(self, i: int, run: Run, need: int) -> float:
        """What P and V of program i add to the 33h run `run` as it is over the other programs in
        `need` (INF when there are none, or it would grow over 15 programs)."""
        first, last = run
        others = need & ((1 << (last + 1)) - (1 << first)) & ~(1 << i)
        if not others:
            return INF
        low, high = (others & -others).bit_length() - 1, others.bit_length() - 1
        span = max(high, i) - min(low, i) + 1
        if span > codec.MAX_FIELD_ITEMS:
            return INF
        return self.parts_price[span] - self.parts_price[high - low + 1]


class PartsDP:
    """One run of the DP behind `WritePhase.parts`, over program numbers.

    best[j]: the cheapest way to write P and V of the programs before j, per state: the room
    left in the last 40h and in the last 41h (0: none open, the next item opens one and pays
    its header) and the programs taken out of each live 42h..46h field (`WritePhase._live`) by
    a 21h, up to those that save it a message (their headers are counted at the end; the items
    of 42h..46h are priced outside: a 21h is credited with those it saves). A state ahead of
    another — more room, more taken out — is never worse and worth at most a header for each
    such field, so a state that costs that much more than another is dropped (`States`); room
    beyond the items the programs left could use is no room.

    A 33h run i..j costs head + per × (j - i + 1), so the best run ending at j starts at the i
    that minimises best[i] - per × i over the last 15 managed programs: a sliding-window
    minimum (`Window`), one per state the run is in at j. A run leaves the state as it was, but
    for the programs inside it that take a 21h as well (their P and V written twice, a 33h
    spared a split): the window of a state moves, each start dearer by that 21h, to the state
    the 21h leads to (`carry`).
    """

    def __init__(self, phase: WritePhase, need: int, movable: int, addresses: int, channels: Channels,
                 live: list[LiveChannel]) -> None:  # fmt: skip
        prices = phase.prices
        self.phase, self.need, self.movable, self.addresses, self.live = phase, need, movable, addresses, live
        self.positions, self.speeds, self.runs_allowed = channels.positions, channels.speeds, channels.parts
        self.states = States((prices.field_header, prices.field_header, *(c.header for c in live)),
                             (codec.MAX_FIELD_ITEMS, codec.MAX_FIELD_ITEMS, *(c.rho for c in live)))  # fmt: skip
        self.more_p = _suffix_counts(need & phase.changed[P_BIT])
        self.more_v = _suffix_counts(need & phase.changed[V_BIT])
        self.windows: dict[int, Window] = {}  # per state a run may end in: its starts
        self.taken: dict[tuple[int, int], int] = {}

    def solve(self) -> tuple[list[dict[int, Back]], int]:
        """The back pointers of every program and the cheapest state after the last."""
        managed, need = self.phase.managed, self.need
        best: dict[int, float] = {0: 0.0}
        back: list[dict[int, Back]] = []
        for j in range(PROGRAM_COUNT):
            if not managed[j]:
                self.windows.clear()
            out, alone = self._whole(j)
            if (out or alone < 0) and self.windows:  # a 21h that changes nothing only costs
                self.carry(j, out, alone)
            new, step = self.moves(j, best, out, alone)
            if need >> j & 1 and self.runs_allowed:
                self.ends(j, new, step)
            if len(new) > 1:
                new = self.states.undominated(new)
            best = new
            back.append(step)
        return back, self.final(best)

    def _whole(self, j: int) -> tuple[int, float]:
        """The live fields a 21h of j takes it out of (a bit each), and what it costs beyond the
        items it saves (INF where it could only cost)."""
        if not self.movable >> j & 1:
            return 0, INF
        phase = self.phase
        out = sum(1 << k for k, c in enumerate(self.live) if c.mask >> j & 1)
        alone = phase.prices.program - phase.plain_items[j] - (phase.prices.address_item if self.addresses >> j & 1 else 0.0)
        return out, alone if self.need >> j & 1 or out or alone < 0 else INF

    def _after(self, state: int, out: int) -> int:
        after = self.taken.get((state, out))
        if after is None:
            after = self.taken[(state, out)] = States.taken_out(state, out, self.live)
        return after

    def carry(self, j: int, out: int, alone: float) -> None:
        """Runs going on over a 21h of program j: of those that come to the same state, the
        cheapest started, each start dearer by the 21h."""
        windows = self.windows
        moved: dict[int, Window] = {}
        for state, window in windows.items():
            after = self._after(state, out)
            if (after == state and alone >= 0) or not window:
                continue  # the same runs, dearer
            if after not in moved or window[0][0] < moved[after][0][0]:
                moved[after] = window
        taken = 1 << j
        for state, window in moved.items():
            dearer = [(key + alone, i, began, inside | taken) for key, i, began, inside in window]
            windows[state] = merged(dearer, windows[state]) if state in windows else deque(dearer)
        if len(windows) > 2 * BEAM:  # runs going on: up to twice as many as states, then as many
            self.windows = self.states.windows_kept(windows)

    def moves(self, j: int, best: dict[int, float], out: int, alone: float) -> tuple[dict[int, float], dict[int, Back]]:
        """The states after program j by its own moves (items, a 32h, a 21h, nothing), and the
        runs that may start at it. Complex because it is the DP's inner loop, one pass over the
        states with every move in it, run for each state of each program: split, each move would
        cost a call per state."""
        phase, windows = self.phase, self.windows
        prices, m, needs = phase.prices, phase.masks[j], self.need >> j & 1
        item, capacity = prices.field_item, codec.MAX_FIELD_ITEMS
        opened = item + prices.field_header  # an item that opens a 40h/41h
        p, v = m & P_BIT, m & V_BIT
        as_items = needs and (self.positions or not p) and (self.speeds or not v)
        runs = needs and self.runs_allowed
        left_p, left_v = self.more_p[j + 1], self.more_v[j + 1]
        capped = left_p < capacity or left_v < capacity  # else no room is beyond what the programs left could use
        single, per = phase.parts_price[1], prices.parts_item
        nothing, items, whole, run = PartsMove.NOTHING, PartsMove.ITEMS, PartsMove.WHOLE, PartsMove.RUN  # locals: fast
        new: dict[int, float] = {}
        step: dict[int, Back] = {}
        for state, b in best.items():
            was_p, was_v = state & FIELD, state >> STATE_BITS & FIELD
            if as_items:
                c, room_p, room_v = b, was_p, was_v
                if p:
                    c += item if room_p else opened
                    room_p = (room_p or capacity) - 1
                if v:
                    c += item if room_v else opened
                    room_v = (room_v or capacity) - 1
                # `_with_rooms`, written out: the DP's inner loop
                after = (state & NOT_ROOMS | (room_p if room_p < left_p else left_p)
                         | (room_v if room_v < left_v else left_v) << STATE_BITS)  # fmt: skip
                if c < new.get(after, INF):
                    new[after], step[after] = c, (state, items, j, 0)
            # the other moves leave the state as it was, but for room no item left could use
            kept = _with_rooms(state, was_p, was_v, left_p, left_v) if capped else state
            if runs:  # a run may start here: pushed onto its state's window (`Window`)
                if (starts := windows.get(kept)) is None:
                    starts = windows[kept] = deque()
                key = b - per * j
                while starts and starts[-1][0] >= key:
                    starts.pop()
                starts.append((key, j, state, 0))
                if b + single < new.get(kept, INF):
                    new[kept], step[kept] = b + single, (state, run, j, 0)
            elif not needs and b < new.get(kept, INF):
                new[kept], step[kept] = b, (state, nothing, j, 0)
            if alone < INF:
                after = self._after(kept, out) if out else kept
                if b + alone < new.get(after, INF):
                    new[after], step[after] = b + alone, (state, whole, j, 0)
        return new, step

    def ends(self, j: int, new: dict[int, float], step: dict[int, Back]) -> None:
        """The 33h runs that end at program j, the cheapest start in each state's window."""
        prices, windows = self.phase.prices, self.windows
        head, run, to_j = prices.parts_header, PartsMove.RUN, prices.parts_item * (j + 1)
        gone = j - codec.MAX_FIELD_ITEMS  # a run is at most 15 programs long: starts up to here are out
        left_p, left_v = self.more_p[j + 1], self.more_v[j + 1]
        capped = left_p < codec.MAX_FIELD_ITEMS or left_v < codec.MAX_FIELD_ITEMS  # as in `moves`
        for state, window in list(windows.items()):
            after = state
            if capped:
                if windows.get(state) is not window:
                    continue  # merged into another at this program
                # the state the runs end in, but for room no item left could use (as `moves` leaves it)
                room_p, room_v = state & FIELD, state >> STATE_BITS & FIELD
                if room_p > left_p or room_v > left_v:
                    after = _with_rooms(state, room_p, room_v, left_p, left_v)
                    del windows[state]
                    window = windows[after] = merged(window, windows[after]) if after in windows else window
            while window and window[0][1] <= gone:
                window.popleft()
            if not window:
                del windows[after]
                continue
            key, i, began, inside = window[0]
            if (through := key + head + to_j) < new.get(after, INF):
                new[after], step[after] = through, (began, run, i, inside)

    def final(self, best: dict[int, float]) -> int:
        """The cheapest state after the last program, the live fields' headers counted."""
        final, total = 0, INF
        for state, b in best.items():
            value = b + fsum(c.header * -((States.field(state, k + 2) - c.n) // c.capacity) for k, c in enumerate(self.live))
            if value < total:
                final, total = state, value
        return final


def merged(mine: Iterable[Start], theirs: Iterable[Start]) -> Window:
    """A window of the starts of two (each by i, keys increasing)."""
    starts: Window = deque()
    for start in sorted((*mine, *theirs), key=_second):  # stable: `mine` first on a tie
        while starts and starts[-1][0] >= start[0]:
            starts.pop()
        starts.append(start)
    return starts


class States:
    """The states of `PartsDP` as ints of 6-bit fields — field 0 the room left in
    the last 40h, 1 in the last 41h, 2 + k the programs taken out of live field k — and which of
    them may go: a state ahead of another in some fields (more room, more taken out) can gain at
    most those fields' headers (`worth`) over it whatever follows, so it goes when it costs that
    much more than the other (to NEAR: a state that costs the same as one ahead of it in every field
    goes — met by cost, the one ahead first at the same cost, the larger int; one that costs a hair
    less, a rounding, goes when the one ahead comes next).
    Which fields one state is ahead in is found for all fields at once: with a guard bit above
    each field, 31 + x - y reaches it exactly where x > y.

    Of the states left, at most BEAM go on: the cheapest once each is credited with what it is
    ahead of nothing — a header's share per room left (header / 15 a slot), and a live field's
    headers in the share of the removals that save them it has made — so that states that have
    paid for 21h that save headers only together are not crowded out by cheaper ones that have not.
    """

    def __init__(self, worth: tuple[float, ...], needed: tuple[int, ...]) -> None:
        fields = range(len(worth))
        self.guards = sum(1 << (STATE_BITS * f + STATE_BITS - 1) for f in fields)
        self.ones = sum(1 << (STATE_BITS * f) for f in fields)
        # what being ahead in each set of fields is worth, by the guard bits of those fields, less NEAR
        self.ahead = {sum(1 << (STATE_BITS * f + STATE_BITS - 1) for f in chosen): fsum(worth[f] for f in chosen) - NEAR
                      for size in range(len(worth) + 1) for chosen in itertools.combinations(fields, size)}  # fmt: skip
        self.ceiling = fsum(worth)
        self.credit = [(STATE_BITS * f, worth[f] / count) for f, count in enumerate(needed)]
        self.credits: dict[int, float] = {}  # by state: what `credited` takes off

    @staticmethod
    def field(state: int, f: int) -> int:
        return state >> (STATE_BITS * f) & FIELD

    @staticmethod
    def taken_out(state: int, out: int, live: list[LiveChannel]) -> int:
        """`state` with one more program taken out of each live field in the bit mask `out`."""
        for k, c in enumerate(live):
            shift = STATE_BITS * (k + 2)
            if out >> k & 1 and (state >> shift & FIELD) < c.rho:
                state += 1 << shift
        return state

    def undominated(self, states: dict[int, float]) -> dict[int, float]:
        """The states no other beats whatever follows, at most BEAM of them (class docstring)."""
        guards, ones, ahead = self.guards, self.ones, self.ahead
        kept: list[tuple[int, float]] = []
        ceiling = INF
        for c, state in sorted([(c, -state) for state, c in states.items()]):  # at the same cost, ahead first
            state = -state
            if c >= ceiling:  # more than every header above the cheapest: beaten by the cheapest
                break
            raised = (state | guards) - ones
            for other, c2 in kept:
                if c - c2 >= ahead[(raised - other) & guards]:
                    break
            else:
                if not kept:
                    ceiling = c + self.ceiling
                # those met just before it that cost the same to NEAR (a hair less) and it beats go
                while kept and c - kept[-1][1] < NEAR and kept[-1][1] - c >= ahead[((kept[-1][0] | guards) - ones - state) & guards]:
                    kept.pop()
                kept.append((state, c))
        if len(kept) > BEAM:
            kept = sorted(kept, key=lambda pair: self.credited(*pair))[:BEAM]
        return dict(kept)

    def windows_kept(self, windows: dict[int, Window]) -> dict[int, Window]:
        """The windows of `PartsDP`'s runs going on that no other beats wherever a run may end, at most
        BEAM + UNCREDITED.

        Not by their cheapest starts: a start leaves its window 15 programs on, so a window whose
        cheapest start is early may be the dearer one by the time a run ends. One window beats
        another when its dearest start is no earlier than every start of the other and cheaper
        than the other's cheapest by what its state may gain (`undominated`). Of the windows left,
        the BEAM cheapest once credited as states are, and the UNCREDITED cheapest as they are: a
        run over programs none of which a 21h took out may be the cheapest to end (its state has
        no credit, but the states ahead of it paid for 21h whose headers are not saved yet).
        """
        guards, ones, ahead = self.guards, self.ones, self.ahead
        # (cheapest start, state, dearest start, its program, the window), by cheapest start to NEAR_DIGITS,
        # the state ahead first at the same start (`undominated` sorts exactly and drops the one a rounding
        # cheaper after; here, run only past 2 × BEAM windows, rounding costs little)
        kept: list[tuple[float, int, float, int, Window]] = []
        for _, state, window in sorted((round(w[0][0], NEAR_DIGITS), -s, w) for s, w in windows.items() if w):
            state, cheapest = -state, window[0][0]
            dear, latest = window[-1][:2]
            raised = (state | guards) - ones
            for _, other, dearest, last, _ in kept:
                if last >= latest and cheapest - dearest >= ahead[(raised - other) & guards]:
                    break
            else:
                kept.append((cheapest, state, dear, latest, window))
        if len(kept) > BEAM:  # the first few, and those first once credited
            kept = [*kept[:UNCREDITED], *sorted(kept, key=lambda row: self.credited(row[1], row[0]))[:BEAM]]
        return {state: window for _, state, _, _, window in kept}

    def credited(self, state: int, cost: float) -> float:
        """`cost` less what `state` is ahead of nothing (class docstring)."""
        if (credit := self.credits.get(state)) is None:
            credit = self.credits[state] = fsum((state >> shift & FIELD) * each for shift, each in self.credit)
        return cost - credit


def _with_rooms(state: int, room_p: int, room_v: int, left_p: int, left_v: int) -> int:
    """`state` with these rooms in the last 40h and 41h, but for room no item left could use (`PartsDP`:
    `left_p`, `left_v` programs from the next on need a P, a V item at most)."""
    return state & NOT_ROOMS | (room_p if room_p < left_p else left_p) | (room_v if room_v < left_v else left_v) << STATE_BITS


def _outside(fronts: list[dict[int, float]]) -> tuple[list[dict[int, float]], list[dict[int, tuple[int, RangeMove, int]]]]:
    """A program outside the plan file in `WritePhase._fewer_messages` (and the end of its programs):
    no range goes on over it, so every count comes to state 0, from 0 or 2."""
    came: dict[int, tuple[int, RangeMove, int]] = {}
    kept: dict[int, float] = {}
    for state in (0, 2):
        for n, c in fronts[state].items():
            if c < kept.get(n, INF):
                kept[n], came[n] = c, (state, RangeMove.KEEP, n)
    return [_pareto(kept), {}, {}, {}, {}], [came, {}, {}, {}, {}]


def _fewer_counts(last: dict[int, float], messages: int) -> list[int]:
    """The item counts `WritePhase._fewer_messages` draws from the front after the last program (by
    count, the cost): per fewer 46h message and slack, the cheapest count that fits."""
    chosen: list[int] = []
    for fewer in range(messages - 1, -1, -1):
        for slack in range(ADDRESS_SLACK + 1):
            fit = [n for n in last if n <= codec.MAX_ADDRESS_ITEMS * fewer + slack]
            if fit and (n := min(fit, key=last.__getitem__)) not in chosen:
                chosen.append(n)
    return chosen


def _pareto(front: dict[int, float]) -> dict[int, float]:
    """The counts of `front` that cost less than every smaller count."""
    kept, least = {}, INF
    for n in sorted(front):
        if front[n] < least:
            kept[n] = least = front[n]
    return kept


def _messages(n: int, capacity: int) -> int:
    """How many messages n items need (none for none or fewer)."""
    return -(-n // capacity) if n > 0 else 0


def _suffix_counts(mask: int) -> list[int]:
    """For each index 0..64, how many of the programs from it on are in `mask`."""
    counts = [0] * (PROGRAM_COUNT + 1)
    for i in range(PROGRAM_COUNT - 1, -1, -1):
        counts[i] = counts[i + 1] + (mask >> i & 1)
    return counts


def floor_of(prices: Prices, target_a: Sequence[int], changed: dict[int, int]) -> Residual:
    """What the differences `mask` of program i cost at least, in any write phase where at most
    the programs in `changed` (per FIELD_BIT) have an item of each field: each at its cheapest,
    every item with its share of a header. A field of n <= N items needs ceil(n/15) headers: at
    least n/15 of one, and one at least n/N of one — so header / min(N, 15) an item (31 for 46h;
    a 33h run carries its header over at most 15 programs, and at most all that need P or V; a
    32h writes one program's P and V alone)."""

    def share(bit: int, header: float, capacity: int) -> float:
        return header / max(min(changed[bit].bit_count(), capacity), 1)

    field = {bit: prices.field_item + share(bit, prices.field_header, codec.MAX_FIELD_ITEMS) for bit in (P_BIT, V_BIT, *PLAIN_BITS)}
    address = prices.address_item + share(A_BIT, prices.address_header, codec.MAX_ADDRESS_ITEMS)
    needers = max(min((changed[P_BIT] | changed[V_BIT]).bit_count(), codec.MAX_FIELD_ITEMS), 1)
    pair, single = prices.parts_item + prices.parts_header / needers, prices.parts(1)  # a 33h's share, a 32h

    def cost(i: int, mask: int) -> float:
        total = fsum(field[bit] for bit in PLAIN_BITS if mask & bit)
        if mask & PV_BITS:
            total += min(pair, single, fsum(field[bit] for bit in (P_BIT, V_BIT) if mask & bit))
        if mask & A_BIT and target_a[i] not in (0, i + 2):
            total += address
        return min(total, prices.program)

    return cost


def _over_every_kind(problem: PlanningProblem) -> dict[int, int]:
    """Per FIELD_BIT, the programs that differ in it under some init kind."""
    union = [0] * PROGRAM_COUNT
    for masks in problem.masks.values():
        union = [u | m for u, m in zip(union, masks)]
    return {bit: sum(1 << i for i, u in enumerate(union) if u & bit) for bit in FIELD_BIT.values()}


def inits_floor(problem: PlanningProblem, floors: Table) -> float:
    """No plan with an init costs less: its init messages and each program's differences at their
    cheapest under its init kind (`floors`: `floor_of`, every field's items counted over every
    kind, as `Charges`), for the init choice with at least one init where that is least
    (`choose_inits`' DP, with whether an init has been sent yet in the state)."""
    prices, count = problem.prices, len(problem.kinds) - 1
    refund, init_range = prices.init_range - prices.init, prices.init_range
    # states once an init has been sent: 0 kept; 2n - 1 after the first program of a run of the
    # n-th init kind, 2n further on; `before`: no init sent yet (every program so far kept)
    size = 1 + 2 * count
    before, cost = 0.0, [INF] * size
    for i, row in enumerate(floors):
        closed = [cost[0], *(min(cost[2 * n - 1] - refund, cost[2 * n]) for n in range(1, count + 1))]  # per kind
        least, then = sorted(closed)[:2]  # the least of the others' is `then` where it is `least`
        new = [least + row[0], *[INF] * (size - 1)]
        if problem.managed[i]:
            for n in range(1, count + 1):
                new[2 * n - 1] = min(before, then if closed[n] == least else least) + init_range + row[n]
                new[2 * n] = min(cost[2 * n - 1], cost[2 * n]) + row[n]
        before += row[0]
        cost = new
    return problem.system_cost + min(c - (refund if state else 0.0) for state, c in enumerate(cost))


def _all_runs(runs: tuple[Run, ...]) -> int:
    return sum((1 << (last + 1)) - (1 << first) for first, last in runs)


def _all_of(masks: tuple[int, ...]) -> int:
    union = 0
    for mask in masks:
        union |= mask
    return union


# -- inits -----------------------------------------------------------------------------------


def init_cost(problem: PlanningProblem, kinds: Kinds) -> float:
    """What the init messages of `kinds` cost: one 14h per run, a 12h/13h/11h for one program or a run to 64."""
    prices = problem.prices
    total = 0.0
    for kind in problem.kinds[1:]:
        for first, last in init_runs(kinds, kind):
            total += prices.init if first == last or last == PROGRAM_COUNT - 1 else prices.init_range
    return total


def choose_inits(problem: PlanningProblem, charges: Table) -> Kinds:
    """The init kind of every program minimising init messages + `charges[i][n]` (n: the kind's
    place in `problem.kinds`, KEEP first).

    A run of programs of one kind costs one 14h, or a 12h/13h/11h when it is one program
    or ends at 64. Unmanaged programs are always KEEP, so no run covers them. States: 0, kept;
    for the n-th init kind, 2n - 1 after the first program of its run and 2n further on. A run
    begins from the cheapest state of another kind once closed (a run of one refunded: a 12h,
    not a 14h); on a tie the lowest state. With one init kind (the system step leaves the
    defaults as they were), the DP is `_one_kind`'s.
    """
    prices = problem.prices
    refund, init_range = prices.init_range - prices.init, prices.init_range
    inits = problem.kinds[1:]
    count = len(inits)
    if all(_best_run(problem.managed, charges, n) < prices.init - TIE for n in range(1, count + 1)):
        return (KEEP,) * PROGRAM_COUNT  # no run of any kind saves what its message costs
    if count == 1:
        back, cost = _one_kind(problem.managed, charges, refund, init_range)
    else:
        back, cost = _kinds(problem.managed, charges, count, refund, init_range)
    state = min(range(len(cost)), key=lambda s: cost[s] - (refund if s else 0.0))
    kinds = [KEEP] * PROGRAM_COUNT
    for i in range(PROGRAM_COUNT - 1, -1, -1):
        kinds[i] = inits[(state - 1) // 2] if state else KEEP
        state = back[i][state]
    return tuple(kinds)


def _kinds(managed: tuple[bool, ...], charges: Table, count: int, refund: float,
           init_range: float) -> tuple[list[Sequence[int]], list[float]]:  # fmt: skip
    """`choose_inits`' DP: per program the state each state came from, and the cost of each state after the last."""
    ends = [(2 * n - 1, 2 * n) for n in range(1, count + 1)]  # per init kind: its run's first state, further on
    no_cost, no_step = [INF] * (2 * count), [0] * (2 * count)
    cost = [0.0, *no_cost]
    back: list[Sequence[int]] = []
    for i, row in enumerate(charges):
        # per kind (KEEP: state 0), its cheapest state closed here; the cheapest of all, and the next
        closed = [(cost[0], 0)]
        for first, further in ends:
            one, more = cost[first] - refund, cost[further]
            closed.append((one, first) if one <= more else (more, further))
        best, *others = sorted(closed)
        new, step = [best[0] + row[0], *no_cost], [best[1], *no_step]
        if managed[i]:
            for n, (first, further) in enumerate(ends, start=1):
                value = row[n]
                c, state = best if best is not closed[n] else others[0]
                new[first], step[first] = c + init_range + value, state
                one, more = cost[first], cost[further]
                new[further], step[further] = (one + value, first) if one <= more else (more + value, further)
        cost = new
        back.append(step)
    return back, cost


def _one_kind(managed: tuple[bool, ...], charges: Table, refund: float,
              init_range: float) -> tuple[list[Sequence[int]], list[float]]:  # fmt: skip
    """`_kinds` with one init kind, the same sums in the same order: a run of it can only begin
    from a kept program (state 0), and the cheapest closed state is kept or the kind's."""
    keep, first, further = 0.0, INF, INF
    back: list[Sequence[int]] = []
    for i, (kept, initialised) in enumerate(charges):
        one = first - refund
        closed, came = (one, 1) if one <= further else (further, 2)
        if keep <= closed:
            closed, came = keep, 0
        if managed[i]:
            step = (came, 0, 1) if first <= further else (came, 0, 2)
            keep, first, further = (closed + kept, keep + init_range + initialised,
                                    (first if first <= further else further) + initialised)  # fmt: skip
        else:
            step = (came, 0, 0)
            keep, first, further = closed + kept, INF, INF
        back.append(step)
    return back, [keep, first, further]


def _best_run(managed: tuple[bool, ...], charges: Table, n: int) -> float:
    """The most a run of the n-th kind could save on `charges` (the maximum subarray, over managed programs)."""
    best = run = 0.0
    for i, row in enumerate(charges):
        run = run + row[0] - row[n] if managed[i] else 0.0
        if run < 0.0:
            run = 0.0
        elif run > best:
            best = run
    return best


class Charges:
    """What `choose_inits` charges each program for each init kind, by a residual: per program the
    differences each kind leaves it priced — where kinds leave it the same differences, once; and
    where the residual depends on the program only through `alike(i, mask)`, once for all programs
    alike. On a tie the init wins, so runs grow over programs they do not harm."""

    def __init__(self, problem: PlanningProblem, alike: Callable[[int, int], object]) -> None:
        kinds = problem.kinds
        self.ties = [0.0, *[TIE] * (len(kinds) - 1)]
        # per program its distinct masks; over all programs the keys of `alike` (by place)
        self.own: list[list[int]] = []  # per program and kind: its mask's place among the program's distinct masks
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


# -- the whole search ------------------------------------------------------------------------


def search(problem: PlanningProblem) -> list[Layout]:
    """Candidate layouts, cheapest estimate first."""
    keep = (KEEP,) * PROGRAM_COUNT
    phase = WritePhase(problem, keep)
    found = phase.solve()
    layouts = [Layout(keep, writes, problem.system_cost + writes.estimate) for writes in found]
    if problem.init_useful():
        charges = Charges(problem, phase.alike)
        floors = charges.alike(floor_of(problem.prices, phase.target_a, _over_every_kind(problem)))
        if inits_floor(problem, floors) < layouts[0].estimate:
            layouts = InitSearch(problem, phase, layouts, charges).run(found[0], floors)
    unique = {(layout.kinds, layout.writes): layout for layout in layouts}
    return sorted(unique.values(), key=ESTIMATE)


class InitSearch:
    """The search over init choices (module docstring, 2.): a queue of init choices, cheapest lower
    bound first, each given its own write phase; when it runs dry, the neighbours of the best plan
    and the inits that save whole messages — until none is left or SEARCHED were."""

    def __init__(self, problem: PlanningProblem, phase: WritePhase, layouts: list[Layout], charges: Charges) -> None:
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
                out.append((-self.improved, init_cost(problem, kinds) + self._phase(kinds).floor, self.order, kinds))
        heapq.heapify(out)
        return out

    def _phase(self, kinds: Kinds) -> WritePhase:
        if (phase := self.phases.get(kinds)) is None:
            phase = self.phases[kinds] = WritePhase(self.problem, kinds)
        return phase

    def _first(self, writes: Writes, floors: Table) -> list[Kinds]:
        """The init DP with a program's charge estimated three ways (module docstring, 2.)."""
        phase, problem, charges = self.phase, self.problem, self.charges
        tables = [charges.each(phase.marginal(writes)), charges.alike(phase.linear(problem.prices.field_header / INIT_SHARE)), floors]
        return [choose_inits(problem, table) for table in tables]

    def _try(self, kinds: Kinds) -> list[Kinds]:
        """Search the write phases of `kinds`; when that gives a better plan, the init choices to try from it."""
        problem = self.problem
        self.tried.add(kinds)
        base = problem.system_cost + init_cost(problem, kinds)
        with_inits = self._phase(kinds)
        if base + with_inits.floor >= self.best.estimate or base + with_inits.at_least(0) >= self.best.estimate:
            return []
        self.searched += 1
        found = with_inits.solve(self.best.estimate - base)
        self.layouts += [Layout(kinds, writes, base + writes.estimate) for writes in found]
        if not found or base + found[0].estimate >= self.best.estimate:
            return []
        self.best = Layout(kinds, found[0], base + found[0].estimate)
        self.improved += 1
        return [choose_inits(problem, self.charges.each(with_inits.marginal(found[0]))),
                *_moved_across(problem, kinds)]  # fmt: skip

    def _targets(self) -> list[Kinds]:
        """Inits that save whole messages, from the plans closest to the best (within an exchange)."""
        problem, best = self.problem, self.best
        close = sorted({layout.kinds: layout for layout in self.layouts if layout.kinds not in self.targeted
                        and layout.estimate < best.estimate + problem.prices.exchange}.values(), key=ESTIMATE)  # fmt: skip
        queue: list[Kinds] = []
        for layout in close[:TARGETED]:
            self.targeted.add(layout.kinds)
            goals = _overflows(problem, layout)
            candidates = _header_targets(problem, self.phase, self.charges, goals, alone=self.searched > 0) + _harmless_inits(problem, layout, goals)
            queue += [kinds for kinds in candidates if kinds not in self.tried]
        return queue


def _item_channels(writes: Writes) -> list[ItemChannel]:
    """Every 40h..46h field of `writes`."""
    channels = [ItemChannel(bit, mask, codec.MAX_FIELD_ITEMS) for bit, mask in zip(ITEM_BITS, writes.items)]
    return [*channels, ItemChannel(A_BIT, writes.addresses, codec.MAX_ADDRESS_ITEMS)]


def _overflows(problem: PlanningProblem, layout: Layout) -> list[Overflow]:
    """The fields whose 40h..46h items in `layout` overflow into one more message and whose
    programs could lose the overflow to an init. P and V count only outside the layout's
    33h runs."""
    outside = ~_all_runs(layout.writes.part_runs)
    goals = []
    for bit, mask, capacity in _item_channels(layout.writes):
        n = mask.bit_count()
        goal = capacity * ((n - 1) // capacity)
        reducible = sum(1 for i in members(mask) if any(not problem.masks[k][i] & bit for k in problem.kinds))
        if goal and n - reducible <= goal:
            goals.append(Overflow(bit, goal, n - goal, outside if bit & PV_BITS else ~0))
    return goals


def _header_targets(problem: PlanningProblem, phase: WritePhase, charges: Charges, goals: list[Overflow], alone: bool) -> list[Kinds]:
    """Init choices that take the overflow of the `goals` fields out, to save whole messages.

    For all of those fields together, and (`alone`) for each alone, header shares per field are bisected
    until the init DP just removes the overflow of each (a Lagrangian relaxation of the message
    count); every init choice met on the way that leaves at most SLACK_ITEMS of the overflow is a
    candidate (a 21h the search adds may take out the last items).
    """
    found: dict[Kinds, None] = {}  # a set in the order found
    for chosen in dict.fromkeys([tuple(goals), *((goal,) for goal in goals if alone)]) if goals else ():
        # removing the overflow saves a header: start from that header spread over the overflow
        shares = {bit: (problem.prices.address_header if bit == A_BIT else problem.prices.field_header) / over
                  for bit, _, over, _ in chosen}  # fmt: skip
        low, high = dict.fromkeys(shares, 0.0), dict.fromkeys(shares, INF)
        for _ in range(TARGET_PROBES):
            kinds = choose_inits(problem, charges.alike(phase.shared(shares)))
            left = 0
            for bit, goal, _, counted in chosen:
                over = sum(1 for i, k in enumerate(kinds) if problem.masks[k][i] & bit and counted >> i & 1) - goal
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
                for i, kind in enumerate(kinds)]  # fmt: skip
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
            for kind in problem.kinds[1:]]  # fmt: skip
    out += _message_initialised(problem, layout)
    return out


def _short_runs_out(problem: PlanningProblem, kinds: Kinds, runs: list[Run]) -> Iterator[Kinds]:
    """Per set of fields, the shortest init runs left out whose programs then differ only in those
    fields, as many as one message of items takes (those items share their headers; no run alone
    pays them)."""
    adds = [_all_of(tuple(problem.masks[KEEP][i] for i in range(first, last + 1))) for first, last in runs]
    for fields in set(adds):
        changed, room = list(kinds), codec.MAX_FIELD_ITEMS
        for first, last in sorted((run for run, added in zip(runs, adds) if not added & ~fields),
                                  key=lambda run: run[1] - run[0]):  # fmt: skip
            room -= last - first + 1
            if room < 0:
                break
            changed[first : last + 1] = [KEEP] * (last - first + 1)
        yield tuple(changed)


def _message_initialised(problem: PlanningProblem, layout: Layout) -> Iterator[Kinds]:
    """Per 40h..46h message of `layout` (a field that fits one) and per 33h run, its programs
    initialised where that takes their item out (together they save the message)."""
    kinds = layout.kinds
    one_message = [(bit, mask) for bit, mask, capacity in _item_channels(layout.writes) if mask.bit_count() <= capacity]
    runs33 = [(PV_BITS, (1 << (last + 1)) - (1 << first)) for first, last in layout.writes.part_runs]
    for bits, mask in one_message + runs33:
        changed = list(kinds)
        for i in members(mask):
            fixing = [k for k in problem.kinds[1:] if not problem.masks[k][i] & bits]
            if kinds[i] == KEEP and fixing:
                changed[i] = fixing[0]
        yield tuple(changed)


def _moved_across(problem: PlanningProblem, kinds: Kinds) -> list[Kinds]:
    """`kinds` with one init run moved to the other side of the system step (the residuals may tie)."""
    if INIT_BEFORE not in problem.kinds:
        return []
    out = []
    for kind, other in ((INIT_BEFORE, INIT_AFTER), (INIT_AFTER, INIT_BEFORE)):
        for first, last in runs_of(kinds, kind):
            out.append(kinds[:first] + (other,) * (last - first + 1) + kinds[last + 1 :])
    return out


def whole_programs(problem: PlanningProblem) -> Layout:
    """The system step, then a 21h for every program that still differs (a link or unlink range
    where only a jump address does and that is cheaper): never dearer than the naive download."""
    keep = (KEEP,) * PROGRAM_COUNT
    writes = WritePhase(problem, keep).evaluate(Channels.everything(False))
    assert writes is not None
    return Layout(keep, writes, problem.system_cost + writes.estimate)
