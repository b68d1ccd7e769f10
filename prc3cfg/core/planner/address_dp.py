"""The jump-address DP: which link (30h) and unlink (31h) ranges, 46h items and 21h give the
programs their desired jump addresses, cheapest first.

A DP over program numbers 1..64 whose moves are a table (`ADDRESS_MOVES`): link and unlink ranges
against 46h items, with the 46h open or shut (a miss then costs a 21h). Where 46h items overflow a
message, the same DP with the items counted in its states gives the cheapest addresses in each fewer
message, exactly (`AddressDP._fewer_messages`).

Owns the ranges. Does not own what a 21h costs beyond its address (`parts_dp`) or which programs take
one (`write_phase`).
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import Enum, IntEnum
from typing import NamedTuple

from prc3cfg.core.image import PROGRAM_COUNT
from prc3cfg.core.planner.pricing import ADDRESSES, Prices
from prc3cfg.core.planner.terms import INF, Range

#: Jump addresses above what fewer 46h messages hold that `AddressDP._fewer_messages` leaves for
#: 21h to take out (`PartsDP` counts them: a program written whole for its other fields takes its
#: address item out too).
ADDRESS_SLACK = 5


class RangeMove(Enum):
    """What the jump-address DP (`AddressDP.solve`) does at a program: its backtracking's actions.

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


#: The jump-address DP's moves (`AddressDP.solve`), in the order its ties go to the
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
INNER_GOING = frozenset((RangeMove.INNER_LINK, RangeMove.INNER_LINK_ON, RangeMove.INNER_UNLINK,
                         RangeMove.INNER_UNLINK_ON))


class Addresses(NamedTuple):
    """Jump addresses of the programs left, as the DP writes them (`AddressDP.solve`)."""

    ranges: tuple[Range, ...]
    items: int  # 46h items
    whole: int  # programs whose A only a 21h can write (46h shut)


class AddressDP:
    """The jump-address DP of one write phase (its bases' addresses and the desired ones)."""

    def __init__(self, prices: Prices, managed: Sequence[bool], target_a: Sequence[int],
                 base_a: Sequence[int],
                 changed_a: int) -> None:
        self.prices, self.managed, self.target_a, self.base_a = prices, managed, target_a, base_a
        self.changed_a = changed_a  # the programs whose address differs from the desired one

    def solve(self, whole: int, open46: bool) -> tuple[Addresses, ...]:
        if not self.changed_a & ~whole:
            return (Addresses((), 0, 0),)
        steps = self._address_steps(whole)
        cheapest = self._ranges_and_misses(whole, open46, self._cheapest_moves(steps, open46))
        messages = ADDRESSES.messages(cheapest.items.bit_count())
        if not messages:  # one 46h saved may pay for ranges: its header too, where ranges take every item
            return (cheapest,)
        return (cheapest,
                *(self._ranges_and_misses(whole, True, moves)
                  for moves in self._fewer_messages(steps, messages)))

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

    def _cheapest_moves(self, steps: list[tuple[bool, tuple[bool, bool, bool]] | None],
                        open46: bool) -> list[RangeMove]:
        """The DP over program numbers (`ADDRESS_MOVES`) behind `addresses`: each wrong address
        costs a 46h item (when `open46`) or a 21h, each range its message."""
        miss = self.prices.address_item if open46 else self.prices.program
        link = self.prices.link
        cost = [0.0, INF, INF, INF, INF]
        back: list[dict[int, tuple[int, RangeMove]]] = []
        # per step as the DP sees it (a few kinds in all): each move's state after and before, and
        # what it adds in the order the sum is taken — a range's message, then the address's price
        priced_moves: dict[tuple[bool, tuple[bool, bool, bool]],
                           list[tuple[int, int, RangeMove, float, float]]] = {}
        for step in steps:
            if step is None:
                came = 0 if cost[0] <= cost[2] else 2
                back.append({0: (came, RangeMove.KEEP)})
                cost = [cost[came], INF, INF, INF, INF]
                continue
            if (allowed := priced_moves.get(step)) is None:
                goes_on, wrong = step
                allowed = priced_moves[step] = [
                    ((to, came, move, link, miss if wrong[gives] else 0.0) if starts
                     else (to, came, move, miss if wrong[gives] else 0.0, 0.0))
                    for to, came, move, starts, gives, _ in (ADDRESS_MOVES if goes_on else ENDING_MOVES)
                ]
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

    def _fewer_messages(self, steps: list[tuple[bool, tuple[bool, bool, bool]] | None],
                        messages: int) -> list[list[RangeMove]]:
        """The cheapest moves with each fewer 46h message than `messages`, where one exists: the DP of
        `_cheapest_moves` whose states also count the items so far — exact where pricing items one
        by one is not (one header saved may pay for ranges that no share of it on each item would
        draw) — and with up to ADDRESS_SLACK more, which 21h may take out (`PartsDP` counts them).
        Each state keeps the counts that cost less than every smaller count (a Pareto front), and
        none above what fewer messages hold with that slack."""
        most = ADDRESSES.capacity * (messages - 1) + ADDRESS_SLACK
        fronts: list[dict[int, float]] = [{0: 0.0}, {}, {}, {}, {}]
        back: list[list[dict[int, tuple[int, RangeMove, int]]]] = []
        for step in steps:
            fronts, moves = _outside(fronts) if step is None else self._counted_step(fronts, step, most)
            back.append(moves)
        # after the last program no range goes on, as after one outside the plan file: each count ends in
        # 0 or 2
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
                      most: int) -> tuple[list[dict[int, float]],
                                          list[dict[int, tuple[int, RangeMove, int]]]]:
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
        for i, move in enumerate(moves):
            if not self.managed[i]:
                continue
            if move in OUTER_STARTS:
                outer.append((move is RangeMove.LINK, i, i))
            elif move is not RangeMove.KEEP:  # the outer range goes on or ends here
                outer[-1] = (*outer[-1][:2], i)
                if move in INNER_STARTS:
                    inner.append((move is RangeMove.INNER_LINK, i, i))
                elif move in INNER_GOING or move in (RangeMove.INNER_END, RangeMove.INNER_UNLINK_END):
                    inner[-1] = (*inner[-1][:2], i)
            value = self.base_a[i] if move is RangeMove.KEEP else i + 2 if move in NEXT_MOVES else 0
            if not whole >> i & 1 and value != self.target_a[i]:
                if open46:
                    items |= 1 << i
                else:
                    extra |= 1 << i
        return Addresses((*outer, *inner), items, extra)

def _outside(fronts: list[dict[int, float]]) -> tuple[list[dict[int, float]],
                                                      list[dict[int, tuple[int, RangeMove, int]]]]:
    """A program outside the plan file in `AddressDP._fewer_messages` (and the end of its programs):
    no range goes on over it, so every count comes to state 0, from 0 or 2."""
    came: dict[int, tuple[int, RangeMove, int]] = {}
    kept: dict[int, float] = {}
    for state in (0, 2):
        for n, c in fronts[state].items():
            if c < kept.get(n, INF):
                kept[n], came[n] = c, (state, RangeMove.KEEP, n)
    return [_pareto(kept), {}, {}, {}, {}], [came, {}, {}, {}, {}]


def _fewer_counts(last: dict[int, float], messages: int) -> list[int]:
    """The item counts `AddressDP._fewer_messages` draws from the front after the last program (by
    count, the cost): per fewer 46h message and slack, the cheapest count that fits."""
    chosen: list[int] = []
    for fewer in range(messages - 1, -1, -1):
        for slack in range(ADDRESS_SLACK + 1):
            fit = [n for n in last if n <= ADDRESSES.capacity * fewer + slack]
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

