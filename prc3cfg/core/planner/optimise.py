"""The search for the cheapest plan of one module.

Bus time is dominated by the fixed cost of an exchange (turnaround, frame overhead, the
reply, open-driver gaps), so the question is which *messages* to open, not which bytes
to send. The search is built around that:

1. **Channels** (`WritePhase`). A candidate opens a subset of the per-field messages:
   40h..45h per field, 33h/32h (P and V of consecutive programs) and 46h. A program that
   still differs in a field none of its open messages can write takes a 21h. For a fixed
   subset the rest is dynamic programming over program numbers 1..64:
   - P and V: 33h runs (at most 15 consecutive managed programs, which may include
     programs that need no change: their desired P, V are rewritten; a run of one is a
     32h) against 40h/41h items, or a 21h where that is cheaper;
   - A: link (30h) and unlink (31h) ranges against 46h items (or a 21h when 46h is shut);
   - Vr, T, F1, F2: their items, counted.
   The DPs price an item on its own; the result is priced by its exact message count
   (ceil(n/15), ceil(n/31)). When items overflow a message, the DP runs again with a share
   of a header on each item (for 46h, 40h and 41h the least share that saves the message,
   found by bisection: a Lagrangian relaxation of the ceiling). Every subset of the
   channels that matter is tried, most open first; subsets that force the same 21h are
   tried once, and a subset whose lower bound (its forced 21h and items) cannot beat the
   best so far is skipped.
   The best few are then refined: programs take a 21h while that saves messages (an
   overflowing 40h..46h, a 33h run that regroups).
2. **Inits.** Which programs to initialise first (11h..14h, before or after the system
   step) is a second DP over program numbers: runs of initialised programs cost one
   message each and never cover an unmanaged program; each program is charged what its
   remaining differences would cost. That charge is estimated four ways — what they add to
   the best plan without inits (headers included), item by item with every channel open,
   the same with a share of a header per item, and as 21h — and again from each better
   plan found (and with each of its init runs moved across the system step); each init
   choice gets its own channel search. When that finds nothing better, two more sources:
   - neighbours of the best plan (`_neighbours`): each of its init runs left out; the
     shortest runs left out whose programs then differ in one set of fields only (as many
     as one message of items takes); each program it writes whole (21h) initialised; the
     programs with an item in one 40h..46h message, or in one 33h run, initialised where
     that takes the items out (together they save the message, one by one they never pay
     for an init);
   - inits that pay only by saving whole messages (`_header_targets`): the charges price
     items one by one, so when a field's items overflow into one more 40h..46h message and
     inits could take the overflow out, header shares per field are bisected until the init
     DP just takes it out (for every set of such fields); each init choice met on the way
     that leaves at most an item or two (a 21h may take those) is searched, and so are, per
     field, init runs that take its items out and add no difference, most items first,
     until the overflow is out (`_harmless_inits`: where runs alike tie, the DP takes all
     or none). This starts from the two plans closest to the best within an exchange (one
     that overflows may be one init away from the best); 40h and 41h count the programs
     outside 33h runs.
   Both start again from each better plan, until none improves.
3. The candidate layouts go back to the caller, cheapest estimate first, which prices the
   close ones exactly and keeps the cheapest. `whole_programs` is the fallback that is
   never dearer than the naive download.

Prices come from `prc3cfg.core.planner.pricing`, bases and masks from `prc3cfg.core.planner.problem`.
Owns the search. Does not own building messages (`layout`) or checking the result (the
caller runs it on `prc3cfg.core.device`).

Long because it is one search: the channel DP (`WritePhase`), the init DP (`InitSearch`) and the
neighbours and header targets that feed it share the priced masks of `problem` and each other's
candidates; split, each part would need the others' reasons. Issue 29's exact search reshapes it.
"""

from __future__ import annotations

import itertools
import operator
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from enum import Enum
from typing import NamedTuple

from prc3cfg.core import codec
from prc3cfg.core.image import PROGRAM_COUNT
from prc3cfg.core.planner.layout import Layout, Writes, members, runs_of
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
#: First and last index of consecutive programs (a 33h run).
Run = tuple[int, int]
#: A link (True) or unlink range: (link?, first, last index), a 30h or 31h.
Range = tuple[bool, int, int]
PLAIN_BITS = tuple(FIELD_BIT[name] for name in PLAIN_FIELDS)
#: The fields of 40h..45h, in `Writes.items` order.
ITEM_BITS = (P_BIT, V_BIT, *PLAIN_BITS)
ESTIMATE = operator.attrgetter("estimate")
#: How many of the best write phases of each init choice are refined and kept as candidates.
KEPT = 3
#: A bias far below any price (seconds): ties between keeping and initialising go to initialising.
TIE = 1e-9
#: Items per message assumed by one of the init choices (few items: headers matter).
INIT_SHARE = 4
#: Probes of the header share that makes overflowing 40h/41h items fit one message less.
BISECTIONS = 6
#: How many promising 21h moves `WritePhase.refine` re-plans with the DPs in each round.
REGROUPED = 4
#: Probes of the header shares that make the init DP take a field's overflow out (`_header_targets`).
TARGET_PROBES = 6
#: Items of the overflow an init choice of `_header_targets` may leave for a 21h to take out.
SLACK_ITEMS = 2
#: How many init choices closest to the best (within an exchange) `_header_targets` starts from in each round.
TARGETED = 2


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
        return cls(sum(PLAIN_BITS) if open_ else 0, open_, open_, open_, open_)


class Candidate(NamedTuple):
    """A write phase the channel search found, and the channels it was found with."""

    writes: Writes
    channels: Channels


def _writes_estimate(candidate: Candidate) -> float:
    return candidate.writes.estimate


class PartsMove(Enum):
    """How the P and V DP (`WritePhase._solve_parts`) covers a program: its backtracking's actions.

    The DPs bind the members they use to locals: looking a member up on its class costs more
    than the rest of a DP step (the class's metaclass has a `__getattr__`).
    """

    NOTHING = "no P or V to write"
    ITEMS = "40h/41h items"
    WHOLE = "a 21h"
    RUN = "the last program of a 33h run (a 32h alone)"


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
    the last program of a link range is unlinked by it (0).
    """

    NONE = "no way to get here"
    KEEP = "outside every range: the base's address"
    LINK = "a link range starts"
    LINK_ON = "a link range goes on"
    END = "a link range ends"
    UNLINK = "an unlink range starts"
    UNLINK_ON = "an unlink range goes on"


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


class Overflow(NamedTuple):
    """A field whose items overflow into one more message, which inits could take out (`_overflows`)."""

    bit: int  # FIELD_BIT
    goal: int  # the items that fit one message less
    over: int  # items above the goal
    counted: int  # the programs counted (P and V: those outside 33h runs)


class WritePhase:
    """The write phase for one choice of init kinds: its bases, masks and the exact DPs over them."""

    def __init__(self, problem: PlanningProblem, kinds: Kinds) -> None:
        self.prices = problem.prices
        self.managed = problem.managed
        self.masks = [problem.masks[k][i] for i, k in enumerate(kinds)]
        self.base_a = [problem.bases[k][i].A for i, k in enumerate(kinds)]
        self.target_a = [0 if p is None else p.A for p in problem.desired.programs]
        self.changed = {bit: sum(1 << i for i, m in enumerate(self.masks) if m & bit) for bit in FIELD_BIT.values()}
        self.relevant = 0
        for m in self.masks:
            self.relevant |= m
        self.pv_changed = self.changed[P_BIT] | self.changed[V_BIT]
        self.parts_price = [INF] + [self.prices.parts(n) for n in range(1, codec.MAX_FIELD_ITEMS + 1)]
        # What a 21h saves in plain items.
        self.plain_items = [sum(1 for bit in PLAIN_BITS if m & bit) * self.prices.field_item for m in self.masks]
        self._parts_cache: dict[tuple[int, int, bool, bool, bool, tuple[float, float]], Parts] = {}
        self._address_cache: dict[tuple[int, bool, float], Addresses] = {}

    # -- the channel subsets ---------------------------------------------------------------

    def subsets(self) -> list[Channels]:
        """Every subset of the channels some program differs in, most open first."""
        rel = self.relevant
        plain = [bit for bit in PLAIN_BITS if rel & bit]
        options = (True, False)
        out: list[Channels] = []
        for opened in itertools.product(options, repeat=len(plain)):
            for positions, speeds, parts, addresses in itertools.product(
                options if rel & P_BIT else (False,),
                options if rel & V_BIT else (False,),
                options if rel & PV_BITS else (False,),
                options if rel & A_BIT else (False,),
            ):
                mask = sum(bit for bit, o in zip(plain, opened) if o)
                out.append(Channels(mask, positions, speeds, parts, addresses))
        return out

    def solve(self, bound: float = INF) -> list[Candidate]:
        """The KEPT cheapest write phases found over every channel subset, cheapest first."""
        found: list[Candidate] = []
        seen: set[tuple[int, bool, bool, bool, bool]] = set()
        for channels in self.subsets():
            # A subset acts only through the 21h it forces and the messages left with work to do.
            whole = self.forced(channels)
            key = (
                whole,
                channels.positions and bool(self.changed[P_BIT] & ~whole),
                channels.speeds and bool(self.changed[V_BIT] & ~whole),
                channels.parts and bool(self.pv_changed & ~whole),
                channels.addresses and bool(self.changed[A_BIT] & ~whole),
            )
            if key in seen:
                continue
            seen.add(key)
            writes = self.evaluate(channels, bound)
            if writes is None:
                continue
            found.append(Candidate(writes, channels))
            bound = min(bound, writes.estimate)
        found.sort(key=_writes_estimate)
        return sorted((Candidate(self.refine(w, c), c) for w, c in found[:KEPT]), key=_writes_estimate)

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
        if self.lower_bound(whole) >= bound:
            return None
        # The DPs price items one by one. When the items of a 46h overflow into one more message,
        # find by bisection the least share of a header on each item that makes the DP save the
        # message (as for 40h/41h in `_with_addresses`); the shares that matter are small beside
        # the header, so the bisection is geometric.
        first = self._with_addresses(whole, channels, 0.0)
        n = first.addresses.bit_count()
        if n <= codec.MAX_ADDRESS_ITEMS:
            return first
        goal = codec.MAX_ADDRESS_ITEMS * ((n - 1) // codec.MAX_ADDRESS_ITEMS)
        tried = [first]
        low, high = self.prices.address_item / 16, self.prices.address_header
        for _ in range(BISECTIONS):
            middle = (low * high) ** 0.5
            tried.append(self._with_addresses(whole, channels, middle))
            if tried[-1].addresses.bit_count() <= goal:
                high = middle
            else:
                low = middle
        return min(tried, key=ESTIMATE)

    def _with_addresses(self, whole: int, channels: Channels, share: float) -> Writes:
        ranges, addresses, extra = self.addresses(whole, channels.addresses, share)
        whole |= extra
        first = self._with_parts(whole, ranges, addresses, channels, (0.0, 0.0))
        counts = [mask.bit_count() for mask in first.items[:2]]
        over = [n > codec.MAX_FIELD_ITEMS for n in counts]
        if not any(over):
            return first
        # 40h/41h items overflow: find by bisection the least share of a header on each of their
        # items that makes the DP save a message (a Lagrangian relaxation of ceil(n/15)).
        # The shares that matter are small beside the header, so the bisection is geometric.
        goal = [codec.MAX_FIELD_ITEMS * ((n - 1) // codec.MAX_FIELD_ITEMS) for n in counts]
        tried = [first]
        low, high = self.prices.field_item / 16, self.prices.field_header
        for _ in range(BISECTIONS):
            middle = (low * high) ** 0.5
            pair = (middle if over[0] else 0.0, middle if over[1] else 0.0)
            tried.append(self._with_parts(whole, ranges, addresses, channels, pair))
            n = [mask.bit_count() for mask in tried[-1].items[:2]]
            if all(n[k] <= goal[k] for k in (0, 1) if over[k]):
                high = middle
            else:
                low = middle
        return min(tried, key=ESTIMATE)

    def _with_parts(self, whole: int, ranges: tuple[Range, ...], addresses: int, channels: Channels,
                    share: tuple[float, float]) -> Writes:  # fmt: skip
        runs, positions, speeds, more, runs_cost = self.parts(whole, addresses, channels, share)
        whole |= more
        items = (positions, speeds, *(self.changed[bit] & ~whole for bit in PLAIN_BITS))
        return self._priced(whole, runs, runs_cost, items, ranges, addresses & ~whole)

    def lower_bound(self, whole: int) -> float:
        """No write phase that gives at least `whole` a 21h costs less.

        Each of those 21h, and at least an item for each remaining plain difference and each
        program left differing in P or V. Giving one more program a 21h never lowers this:
        a 21h (16 bytes and an exchange) costs more than the five items it can save.
        """
        prices = self.prices
        plain = sum((self.changed[bit] & ~whole).bit_count() for bit in PLAIN_BITS)
        need = (self.pv_changed & ~whole).bit_count()
        return whole.bit_count() * prices.program + (plain + need) * prices.field_item

    def _priced(self, whole: int, runs: tuple[Run, ...], runs_cost: float, items: tuple[int, ...],
                ranges: tuple[Range, ...], addresses: int) -> Writes:  # fmt: skip
        prices = self.prices
        estimate = (
            whole.bit_count() * prices.program
            + runs_cost
            + sum(prices.fields(mask.bit_count()) for mask in items)
            + len(ranges) * prices.link
            + prices.addresses(addresses.bit_count())
        )
        return Writes(whole, runs, items, ranges, addresses, estimate)

    def refine(self, writes: Writes, channels: Channels) -> Writes:
        """Give programs a 21h while that saves messages (the DPs price items one by one).

        A program that takes a 21h leaves its items; a 33h run shrinks to the programs that
        still need it (or goes); link ranges stay, its 21h comes after them.
        """
        while True:
            moves = self._refinements(writes)
            in_runs = _all_runs(writes.part_runs)
            # The best quick move; and, with the DPs run again (the 33h runs they leave may regroup
            # and save an exchange), the few in runs that come within an exchange of paying off.
            tries: list[Writes | None] = [self._moved(writes, moves[0][1])] if moves and moves[0][0] < -1e-12 else []
            tries += [self.evaluate(channels, whole=writes.whole | 1 << j)
                      for delta, j in moves[:REGROUPED] if delta < self.prices.exchange and in_runs >> j & 1]  # fmt: skip
            better = [moved for moved in tries if moved is not None and moved.estimate < writes.estimate - 1e-12]
            if not better:
                return writes
            writes = min(better, key=ESTIMATE)

    def _refinements(self, writes: Writes) -> list[tuple[float, int]]:
        """Every program with an item or in a 33h run given a 21h instead: (what that changes, in
        seconds, items priced one by one; the program), most saving first. Plain tuples: a plan
        makes tens of thousands."""
        prices = self.prices
        saving = [prices.fields(n) - prices.fields(n - 1) if n else 0.0 for n in map(int.bit_count, writes.items)]
        n = writes.addresses.bit_count()
        address_saving = prices.addresses(n) - prices.addresses(n - 1) if n else 0.0
        # by each program in a run: the programs of that run that still need their P and V, and its cost
        need = self.pv_changed & ~writes.whole
        run_of = {j: (need & ((1 << (last + 1)) - (1 << first)), self.parts_price[last - first + 1])
                  for first, last in writes.part_runs for j in range(first, last + 1)}  # fmt: skip
        savings = list(zip(saving, writes.items))
        parts_price, program, addresses = self.parts_price, prices.program, writes.addresses
        moves = []
        for j in members((_all_of(writes.items) | addresses | _all_runs(writes.part_runs)) & ~writes.whole):
            saved: float = 0  # summed as sum() would, in the same order: the same float
            for s, mask in savings:
                if mask >> j & 1:
                    saved += s
            delta = program - saved
            if addresses >> j & 1:
                delta -= address_saving
            if j in run_of:  # the run cut down to the programs that still need it without j: `_trimmed`, `_runs_cost` of one run
                inside, price = run_of[j]
                inside &= ~(1 << j)
                rest = parts_price[inside.bit_length() - (inside & -inside).bit_length() + 1] if inside else 0
                delta += rest - price
            moves.append((delta, j))
        moves.sort()
        return moves

    def _moved(self, writes: Writes, j: int) -> Writes:
        """`writes` with program j given a 21h instead of its items."""
        bit = 1 << j
        whole = writes.whole | bit
        runs = self._trimmed(writes.part_runs, self.pv_changed & ~whole)
        items = tuple(mask & ~bit for mask in writes.items)
        return self._priced(whole, runs, self._runs_cost(runs), items, writes.ranges, writes.addresses & ~bit)

    @staticmethod
    def _trimmed(runs: tuple[Run, ...], need: int) -> tuple[Run, ...]:
        """The runs cut down to their first and last program in `need`; runs needing none dropped."""
        out: list[Run] = []
        for first, last in runs:
            inside = need & ((1 << (last + 1)) - (1 << first))
            if inside:
                out.append(((inside & -inside).bit_length() - 1, inside.bit_length() - 1))
        return tuple(out)

    def _runs_cost(self, runs: tuple[Run, ...]) -> float:
        return sum(self.parts_price[last - first + 1] for first, last in runs)

    # -- P and V: 33h/32h runs against 40h/41h items (or a 21h) ---------------------------------

    def parts(self, whole: int, addresses: int, channels: Channels, share: tuple[float, float] = (0.0, 0.0)) -> Parts:
        """P and V of the programs not in `whole` that differ in P or V.

        A program may take a 21h instead when that costs less than its P and V writes plus its
        other items (`addresses`: its 46h item). Items are priced one by one, plus `share` (40h,
        41h) of their messages' headers.
        """
        need = self.pv_changed & ~whole
        key = (need, addresses & need, channels.positions, channels.speeds, channels.parts, share)
        cached = self._parts_cache.get(key)
        if cached is None:
            cached = self._parts_cache[key] = self._solve_parts(need, addresses, channels, share)
        return cached

    def _solve_parts(self, need: int, addresses: int, channels: Channels, share: tuple[float, float]) -> Parts:
        if not need:
            return Parts((), 0, 0, 0, 0.0)
        prices, masks, managed, price = self.prices, self.masks, self.managed, self.parts_price
        p_item = prices.field_item + share[0] if channels.positions else INF
        v_item = prices.field_item + share[1] if channels.speeds else INF
        program, address_item, runs_allowed = prices.program, prices.address_item, channels.parts
        plain_items, window = self.plain_items, codec.MAX_FIELD_ITEMS
        nothing, items, whole_, run = PartsMove.NOTHING, PartsMove.ITEMS, PartsMove.WHOLE, PartsMove.RUN  # locals: fast
        # best[j]: the cheapest way to write P and V of the programs before j. A 33h run i..j
        # costs head + per × (j - i + 1), so the best run ending at j starts at the i that
        # minimises best[i] - per × i over the last 15 managed programs: a sliding-window minimum.
        head, per = prices.parts_header, prices.parts_item
        best = [0.0] * (PROGRAM_COUNT + 1)
        back: list[tuple[int, PartsMove]] = [(0, nothing)] * (PROGRAM_COUNT + 1)
        starts: deque[tuple[float, int]] = deque()  # (best[i] - per × i, i), keys increasing
        for j in range(PROGRAM_COUNT):
            b = best[j]
            if not managed[j]:
                starts.clear()
            if not need >> j & 1:
                best[j + 1], back[j + 1] = b, (j, nothing)
                continue
            m = masks[j]
            c, how = b + (p_item if m & P_BIT else 0.0) + (v_item if m & V_BIT else 0.0), (j, items)
            alone = b + program - plain_items[j] - (address_item if addresses >> j & 1 else 0.0)
            if alone < c:
                c, how = alone, (j, whole_)
            if runs_allowed:
                key = b - per * j
                while starts and starts[-1][0] >= key:
                    starts.pop()
                starts.append((key, j))
                while starts[0][1] <= j - window:
                    starts.popleft()
                if b + price[1] < c:
                    c, how = b + price[1], (j, run)
                key, first = starts[0]
                if (through := key + head + per * (j + 1)) < c:
                    c, how = through, (first, run)
            best[j + 1], back[j + 1] = c, how
        return self._traced_parts(back)

    def _traced_parts(self, back: list[tuple[int, PartsMove]]) -> Parts:
        """The P and V writes of `_solve_parts`, followed back from the last program."""
        runs: list[Run] = []
        positions = speeds = whole = 0
        runs_cost = 0.0
        run, items, whole_ = PartsMove.RUN, PartsMove.ITEMS, PartsMove.WHOLE  # locals: fast
        j = PROGRAM_COUNT
        while j > 0:
            i, move = back[j]
            if move is run:
                runs.append((i, j - 1))
                runs_cost += self.parts_price[j - i]
            elif move is items:
                positions |= (self.masks[i] & P_BIT and 1) << i
                speeds |= (self.masks[i] & V_BIT and 1) << i
            elif move is whole_:
                whole |= 1 << i
            j = i
        return Parts(tuple(reversed(runs)), positions, speeds, whole, runs_cost)

    # -- A: link/unlink ranges against 46h items -----------------------------------------------

    def addresses(self, whole: int, open46: bool, share: float = 0.0) -> Addresses:
        """The jump addresses of the programs not in `whole`: link and unlink ranges, 46h items
        (when `open46`) or a 21h. 46h items are priced one by one plus `share` for their share of
        the 46h messages."""
        key = (whole, open46, share)
        cached = self._address_cache.get(key)
        if cached is None:
            cached = self._address_cache[key] = self._solve_addresses(whole, open46, share)
        return cached

    def _solve_addresses(self, whole: int, open46: bool, share: float) -> Addresses:
        if not self.changed[A_BIT] & ~whole:
            return Addresses((), 0, 0)
        managed, target, base = self.managed, self.target_a, self.base_a
        miss = self.prices.address_item + share if open46 else self.prices.program
        link = self.prices.link
        none, keep, end = RangeMove.NONE, RangeMove.KEEP, RangeMove.END  # locals: fast
        link_, link_on, unlink, unlink_on = RangeMove.LINK, RangeMove.LINK_ON, RangeMove.UNLINK, RangeMove.UNLINK_ON
        # States after program i: 0 no range open, 1 a link range goes on to i+1, 2 an unlink range
        # may go on. Moves give program i its A: kept, 0 (unlink, end of a link) or i+2 (link goes on).
        cost = [0.0, INF, INF]
        back: list[tuple[tuple[int, RangeMove], ...]] = []
        for i in range(PROGRAM_COUNT):
            c0, c1, c2 = cost
            if not managed[i]:
                back.append(((0, keep) if c0 <= c2 else (2, keep), (0, none), (0, none)))
                cost = [min(c0, c2), INF, INF]
                continue
            free = whole >> i & 1
            t = target[i]
            m_keep = 0.0 if free or base[i] == t else miss
            m_zero = 0.0 if free or t == 0 else miss
            m_next = 0.0 if free or t == i + 2 else miss
            goes_on = i + 1 < PROGRAM_COUNT and managed[i + 1]
            open_prev, open_cost = (0, c0) if c0 <= c2 else (2, c2)
            n0, b0 = open_cost + m_keep, (open_prev, keep)
            if c1 + m_zero < n0:
                n0, b0 = c1 + m_zero, (1, end)
            n1, b1 = INF, (0, none)
            if goes_on:
                n1, b1 = open_cost + link + m_next, (open_prev, link_)
                if c1 + m_next < n1:
                    n1, b1 = c1 + m_next, (1, link_on)
            n2, b2 = c0 + link + m_zero, (0, unlink)
            if c2 + m_zero < n2:
                n2, b2 = c2 + m_zero, (2, unlink_on)
            cost = [n0, n1, n2]
            back.append((b0, b1, b2))
        state = 0 if cost[0] <= cost[2] else 2
        moves = [none] * PROGRAM_COUNT
        for i in range(PROGRAM_COUNT - 1, -1, -1):
            state, moves[i] = back[i][state]
        return self._ranges_and_misses(whole, open46, moves)

    def _ranges_and_misses(self, whole: int, open46: bool, moves: list[RangeMove]) -> Addresses:
        """The ranges the DP's moves draw, and the programs whose address they leave wrong."""
        ranges: list[Range] = []
        items = extra = 0
        keep, link_, link_on, unlink = RangeMove.KEEP, RangeMove.LINK, RangeMove.LINK_ON, RangeMove.UNLINK  # locals: fast
        for i, move in enumerate(moves):
            if not self.managed[i]:
                continue
            if move is link_ or move is unlink:
                ranges.append((move is link_, i, i))
            elif move is not keep:  # a range goes on or ends here
                link, first, _ = ranges[-1]
                ranges[-1] = (link, first, i)
            value = self.base_a[i] if move is keep else i + 2 if move is link_ or move is link_on else 0
            if not whole >> i & 1 and value != self.target_a[i]:
                if open46:
                    items |= 1 << i
                else:
                    extra |= 1 << i
        return Addresses(tuple(ranges), items, extra)

    # -- what a program's differences cost, for the init DP ------------------------------------

    def linear(self, channels: Channels, share: float = 0.0) -> Residual:
        """A program's differences priced item by item under `channels`, each item with `share` of a header."""
        prices = self.prices
        item = prices.field_item + share

        def cost(i: int, mask: int) -> float:
            if not mask:
                return 0.0
            total = 0.0
            for bit in PLAIN_BITS:
                if mask & bit:
                    if not channels.plain & bit:
                        return prices.program
                    total += item
            if mask & PV_BITS:
                if channels.parts:
                    total += item
                elif (mask & P_BIT and not channels.positions) or (mask & V_BIT and not channels.speeds):
                    return prices.program
                else:
                    total += item * (mask & PV_BITS).bit_count()
            if mask & A_BIT:
                if channels.addresses:
                    total += prices.address_item + share
                elif self.target_a[i] in (0, i + 2):
                    total += prices.link
                else:
                    return prices.program
            return min(total, prices.program)

        return cost

    def shared(self, shares: dict[int, float]) -> Residual:
        """A program's differences with every channel open, each item of a field in `shares` (by
        field bit) with that share of a header: P and V as a 33h pair unless one of them has a
        share, a jump address a link or unlink range can give as free (a range over initialised
        programs restores their chain), any other as a 46h item."""
        prices = self.prices
        pv_items = any(bit & PV_BITS for bit in shares)

        def cost(i: int, mask: int) -> float:
            total = sum(prices.field_item + shares.get(bit, 0.0) for bit in PLAIN_BITS if mask & bit)
            if mask & PV_BITS:
                total += (sum(prices.field_item + shares.get(bit, 0.0) for bit in (P_BIT, V_BIT) if mask & bit)
                          if pv_items else prices.parts_item)  # fmt: skip
            if mask & A_BIT and self.target_a[i] not in (0, i + 2):
                total += prices.address_item + shares.get(A_BIT, 0.0)
            return min(total, prices.program)

        return cost

    def marginal(self, writes: Writes) -> Residual:
        """What a program's differences would add to `writes`, everything else staying as it is.

        Header-aware: a program that alone opens a message pays for the message, one that
        joins an open one pays its item, one inside a 33h run or a fitting link range nothing.
        """
        prices = self.prices
        counts = [mask.bit_count() for mask in writes.items]
        addresses = writes.addresses.bit_count()
        need = self.pv_changed & ~writes.whole
        run_of = {i: (first, last) for first, last in writes.part_runs for i in range(first, last + 1)}
        ranged = {i: (i + 2 if link and i < last else 0) for link, first, last in writes.ranges
                  for i in range(first, last + 1)}  # fmt: skip

        def items(k: int, i: int) -> float:
            n = counts[k] - (writes.items[k] >> i & 1)
            return prices.fields(n + 1) - prices.fields(n)

        def parts(i: int, mask: int) -> float:
            alone = min(self.parts_price[1], sum(items(k, i) for k, bit in enumerate((P_BIT, V_BIT)) if mask & bit))
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
            for k, bit in enumerate(PLAIN_BITS, start=2):
                if mask & bit:
                    total += items(k, i)
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
        for first, last in runs_of(kinds, kind):
            total += prices.init if first == last or last == PROGRAM_COUNT - 1 else prices.init_range
    return total


def choose_inits(problem: PlanningProblem, residual: list[dict[int, float]]) -> Kinds:
    """The init kind of every program minimising init messages + `residual[i][kind]`.

    A run of programs of one kind costs one 14h, or a 12h/13h/11h when it is one program
    or ends at 64. Unmanaged programs are always KEEP, so no run covers them.
    """
    prices = problem.prices
    refund, init_range = prices.init_range - prices.init, prices.init_range
    # state: (kind of the previous program, whether its run is a single program so far) — made once
    kept = (KEEP, False)
    begun = {kind: (kind, True) for kind in problem.kinds}
    going = {kind: (kind, False) for kind in problem.kinds}
    cost: dict[tuple[int, bool], float] = {kept: 0.0}
    back: list[dict[tuple[int, bool], tuple[int, bool]]] = []
    for i in range(PROGRAM_COUNT):
        allowed = problem.kinds if problem.managed[i] else (KEEP,)
        row = residual[i]
        new: dict[tuple[int, bool], float] = {}
        step: dict[tuple[int, bool], tuple[int, bool]] = {}
        best = new.get
        for before, c in cost.items():
            prev, single = before
            closing = c - refund if prev != KEEP and single else c
            for kind in allowed:
                if kind == KEEP:
                    state, value = kept, closing + row[KEEP]
                elif kind == prev:
                    state, value = going[kind], c + row[kind]
                else:
                    state, value = begun[kind], closing + init_range + row[kind]
                if value < best(state, INF):
                    new[state], step[state] = value, before
        cost = new
        back.append(step)
    state = min(cost, key=lambda s: cost[s] - (refund if s[0] != KEEP else 0.0))
    kinds = [KEEP] * PROGRAM_COUNT
    for i in range(PROGRAM_COUNT - 1, -1, -1):
        kinds[i] = state[0]
        state = back[i][state]
    return tuple(kinds)


def _table(problem: PlanningProblem, residual: Residual) -> list[dict[int, float]]:
    """Residuals per program and init kind; on a tie the init wins, so runs grow over programs they do not harm.
    A program's kinds often leave it the same differences: each is priced once."""
    table = []
    for i in range(PROGRAM_COUNT):
        priced: dict[int, float] = {}  # by mask
        row = {}
        for kind in problem.kinds:
            mask = problem.masks[kind][i]
            if (value := priced.get(mask)) is None:
                value = priced[mask] = residual(i, mask)
            row[kind] = value - (TIE if kind != KEEP else 0.0)
        table.append(row)
    return table


# -- the whole search ------------------------------------------------------------------------


def search(problem: PlanningProblem) -> list[Layout]:
    """Candidate layouts, cheapest estimate first."""
    keep = (KEEP,) * PROGRAM_COUNT
    phase = WritePhase(problem, keep)
    found = phase.solve()
    layouts = [Layout(keep, writes, problem.system_cost + writes.estimate) for writes, _ in found]
    if problem.init_useful():
        layouts = InitSearch(problem, phase, layouts).run(found[0].writes)
    unique = {(layout.kinds, layout.writes): layout for layout in layouts}
    return sorted(unique.values(), key=ESTIMATE)


class InitSearch:
    """The search over init choices (module docstring, 2.): a queue of init choices, each given
    its own channel search; when it runs dry, the neighbours of the best plan, then the inits
    that save whole messages, until none improves."""

    def __init__(self, problem: PlanningProblem, phase: WritePhase, layouts: list[Layout]) -> None:
        self.problem = problem
        self.phase = phase  # the write phase without inits
        self.layouts = layouts  # every candidate found, the plans without inits first
        self.best = layouts[0]
        self.tried = {layouts[0].kinds}
        self.targeted: set[Kinds] = set()  # the init choices `_targets` started from

    def run(self, writes: Writes) -> list[Layout]:
        """Every candidate found, starting from `writes`, the best write phase without inits."""
        queue = self._first(writes)
        while queue:
            kinds = queue.pop(0)
            if kinds not in self.tried:
                queue += self._try(kinds)
            if not queue:
                queue = [kinds for kinds in _neighbours(self.problem, self.best) if kinds not in self.tried]
            if not queue:
                queue = self._targets()
        return self.layouts

    def _first(self, writes: Writes) -> list[Kinds]:
        """The init DP with a program's charge estimated four ways (module docstring, 2.)."""
        phase, problem = self.phase, self.problem
        everything = Channels.everything(True)
        residuals = [
            phase.marginal(writes),
            phase.linear(everything),
            phase.linear(everything, problem.prices.field_header / INIT_SHARE),
            phase.linear(Channels.everything(False)),
        ]
        return [choose_inits(problem, _table(problem, residual)) for residual in residuals]

    def _try(self, kinds: Kinds) -> list[Kinds]:
        """Search the write phases of `kinds`; when that gives a better plan, the init choices to try from it."""
        problem = self.problem
        self.tried.add(kinds)
        base = problem.system_cost + init_cost(problem, kinds)
        with_inits = WritePhase(problem, kinds)
        found = with_inits.solve(bound=self.best.estimate - base + problem.prices.exchange)  # refine may still gain
        self.layouts += [Layout(kinds, writes, base + writes.estimate) for writes, _ in found]
        if not found or base + found[0].writes.estimate >= self.best.estimate:
            return []
        self.best = Layout(kinds, found[0].writes, base + found[0].writes.estimate)
        return [choose_inits(problem, _table(problem, with_inits.marginal(found[0].writes))),
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
            candidates = _header_targets(problem, self.phase, goals) + _harmless_inits(problem, layout, goals)
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


def _header_targets(problem: PlanningProblem, phase: WritePhase, goals: list[Overflow]) -> list[Kinds]:
    """Init choices that take the overflow of the `goals` fields out, to save whole messages.

    For every set of those fields, header shares per field are bisected until the init DP
    just removes the overflow of each (a Lagrangian relaxation of the message count); every
    init choice met on the way that leaves at most SLACK_ITEMS of the overflow is a candidate
    (a 21h the search adds may take out the last items).
    """
    found: dict[Kinds, None] = {}  # a set in the order found
    for size in range(len(goals), 0, -1):
        for chosen in itertools.combinations(goals, size):
            # removing the overflow saves a header: start from that header spread over the overflow
            shares = {bit: (problem.prices.address_header if bit == A_BIT else problem.prices.field_header) / over
                      for bit, _, over, _ in chosen}  # fmt: skip
            low, high = dict.fromkeys(shares, 0.0), dict.fromkeys(shares, INF)
            for _ in range(TARGET_PROBES):
                kinds = choose_inits(problem, _table(problem, phase.shared(shares)))
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
