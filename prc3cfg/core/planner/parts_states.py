"""The states of the parts DP (`parts_dp.PartsDP`) and which of them may go.

A state is an int of 6-bit fields (the room left in the last 40h and 41h, the programs taken out of
each live 42h..46h field) with a guard bit above each, so that which fields one state is ahead of
another in is found for all fields at once (`States`). The starts of the 33h runs that may end at
the next program are kept per state as a sliding-window minimum (`Window`).

Owns the states, their dominance and the windows. Does not own the DP's moves (`parts_dp`).
"""

from __future__ import annotations

import itertools
import operator
from collections import deque
from collections.abc import Iterable, Sequence
from math import fsum

from prc3cfg.core.planner.terms import INF, NEAR, NEAR_DIGITS

#: The most states `PartsDP` keeps after each program (`States`); runs going on, once twice as
#: many, are cut to as many and UNCREDITED more.
BEAM = 24
#: Runs going on kept by their cheapest start alone, beside the BEAM kept once credited
#: (`States.windows_kept`).
UNCREDITED = 8
#: Bits of a field of a `States` state (values up to 31, and a guard bit) and the mask of one.
STATE_BITS = 6
FIELD = (1 << (STATE_BITS - 1)) - 1
#: A state's fields but its rooms (the live fields' removals).
NOT_ROOMS = ~(FIELD | FIELD << STATE_BITS)
#: A start of a 33h run in `PartsDP`: best[i] - per × i, i, the state at i, the programs inside the run
#: that take a 21h as well.
Start = tuple[float, int, int, int]
#: The starts of the 33h runs that may end at the next program, for one state of `PartsDP`, by i,
#: keys increasing — the front is the cheapest start. A start added drops those before it that cost
#: as much or more: it lasts longer.
Window = deque[Start]
_second = operator.itemgetter(1)


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
        self.ahead = {}
        for size in range(len(worth) + 1):
            for chosen in itertools.combinations(fields, size):
                guards = sum(1 << (STATE_BITS * f + STATE_BITS - 1) for f in chosen)
                self.ahead[guards] = fsum(worth[f] for f in chosen) - NEAR
        self.ceiling = fsum(worth)
        self.credit = [(STATE_BITS * f, worth[f] / count) for f, count in enumerate(needed)]
        self.credits: dict[int, float] = {}  # by state: what `credited` takes off

    @staticmethod
    def field(state: int, f: int) -> int:
        return state >> (STATE_BITS * f) & FIELD

    @staticmethod
    def taken_out(state: int, out: int, rhos: Sequence[int]) -> int:
        """`state` with one more program taken out of each live field in the bit mask `out`
        (`rhos`: per live field, the removals that save it a message)."""
        for k, rho in enumerate(rhos):
            shift = STATE_BITS * (k + 2)
            if out >> k & 1 and (state >> shift & FIELD) < rho:
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
                while (kept and c - kept[-1][1] < NEAR
                       and kept[-1][1] - c >= ahead[((kept[-1][0] | guards) - ones - state) & guards]):
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
            credit = fsum((state >> shift & FIELD) * each for shift, each in self.credit)
            self.credits[state] = credit
        return cost - credit


def with_rooms(state: int, room_p: int, room_v: int, left_p: int, left_v: int) -> int:
    """`state` with these rooms in the last 40h and 41h, but for room no item left could use (`PartsDP`:
    `left_p`, `left_v` programs from the next on need a P, a V item at most)."""
    p = room_p if room_p < left_p else left_p  # (min() costs a call: this runs per state and program)
    v = room_v if room_v < left_v else left_v
    return state & NOT_ROOMS | p | v << STATE_BITS

