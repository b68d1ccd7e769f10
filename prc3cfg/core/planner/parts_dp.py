"""The parts DP: P and V of every program — 33h runs (a 32h alone), 40h/41h items or a 21h — over
program numbers 1..64, with the headers in the state, not priced item by item.

The state holds the room left in the last 40h and 41h (the item that opens one pays its header, so a
40h is opened, or not, where that pays), and, per 42h..46h field where more 21h could save a message
(`live_channels`), the programs a 21h took out of it, up to those that save it one. So 21h that save
messages only together are found: four programs written whole so that the other 60 fit four messages
of each field, not five, and four 33h runs of 15 — and a 42h..45h with a few items is shut where 21h
cost less than its header. States that cannot win whatever follows are dropped (`parts_states.States`),
a few at most go on.

Owns the DP and its result (`Parts`). Does not own the jump addresses (`address_dp`) or which
channels are open (`write_phase`).
"""

from __future__ import annotations

import functools
import operator
from collections import deque
from collections.abc import Sequence
from enum import Enum
from math import fsum
from typing import NamedTuple, Protocol

from prc3cfg.core import codec
from prc3cfg.core.image import PROGRAM_COUNT
from prc3cfg.core.planner.layout import members
from prc3cfg.core.planner.parts_states import (
    BEAM,
    FIELD,
    NOT_ROOMS,
    STATE_BITS,
    States,
    Window,
    merged,
    with_rooms,
)
from prc3cfg.core.planner.pricing import ADDRESSES, FIELDS, PARTS, Prices
from prc3cfg.core.planner.problem import P_BIT, V_BIT
from prc3cfg.core.planner.terms import INF, KIND_OF_BIT, PLAIN_BITS, Channels, Run, all_of

#: The most 42h..46h fields (alike ones as one) `PartsDP` counts removals of:
#: those that need fewest.
LIVE = 4
#: A back pointer of `PartsDP`: the state before, the move, the program it starts
#: at, and the programs a run it ends passes over with a 21h.
Back = tuple[int, "PartsMove", int, int]
_rho = operator.attrgetter("rho")


class PartsMove(Enum):
    """How the P and V DP (`PartsDP`) covers a program: its backtracking's actions."""

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


class LiveChannel(NamedTuple):
    """42h..46h fields with the same items, whose removals by 21h `PartsDP` counts."""

    mask: int  # the programs with an item
    n: int  # how many
    rho: int  # removals that save a message
    kind: codec.ItemsKind  # the message of one of them (alike in capacity)
    header: float  # the headers of those fields, together


class PartsPhase(Protocol):
    """What the parts DP reads of its write phase (`write_phase.WritePhase`)."""

    @property
    def prices(self) -> Prices: ...

    @property
    def managed(self) -> Sequence[bool]: ...

    @property
    def masks(self) -> list[int]: ...  # per program, its difference mask

    @property
    def changed(self) -> dict[int, int]: ...  # per FIELD_BIT, the programs that differ in it

    @property
    def pv_changed(self) -> int: ...  # the programs that differ in P or V

    @property
    def relevant_programs(self) -> int: ...  # the programs that differ in anything

    @property
    def parts_price(self) -> list[float]: ...

    @property
    def plain_items(self) -> list[float]: ...


def live_channels(phase: PartsPhase, whole: int, addresses: int, need: int) -> list[LiveChannel]:
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
    prices = phase.prices
    fields = [(phase.changed[bit] & ~whole, KIND_OF_BIT[bit]) for bit in PLAIN_BITS]
    fields.append((addresses & ~whole, ADDRESSES))
    grouped: dict[tuple[int, int], tuple[codec.ItemsKind, list[float]]] = {}
    for mask, kind in fields:
        if mask:
            grouped.setdefault((mask, kind.capacity), (kind, []))[1].append(prices.header(kind))
    channels = []
    for (mask, _), (kind, headers) in grouped.items():
        n = mask.bit_count()
        channels.append(LiveChannel(mask, n, kind.in_last(n), kind, fsum(headers)))
    n = need.bit_count()  # a 33h saved too where the removals take the P and V left down a run
    runs_out = PARTS.in_last(n) if n else PROGRAM_COUNT + 1
    live = []
    extra = {i: _extra_cost(phase, i, need, addresses)
             for i in members(all_of(tuple(c.mask for c in channels)))}
    for c in channels:
        others = [o for o in channels if o is not c]
        ranked = sorted(members(c.mask),
                        key=lambda i: extra[i] - fsum(o.header / o.rho for o in others if o.mask >> i & 1))
        chosen = ranked[: c.rho]
        spent = fsum(extra[i] for i in chosen)
        taken = sum(1 << i for i in chosen)
        saved = fsum((c.header, prices.parts_header if (need & taken).bit_count() >= runs_out else 0.0,
                      *(o.header for o in others if (o.mask & taken).bit_count() >= o.rho)))
        if spent < saved:
            live.append(c)
    return sorted(live, key=_rho)[:LIVE]

def _extra_cost(phase: PartsPhase, i: int, need: int, addresses: int) -> float:
    """What a 21h of program i costs at least beyond the items it saves."""
    prices, m = phase.prices, phase.masks[i]
    pv = ((prices.field_item if m & P_BIT else 0.0) + (prices.field_item if m & V_BIT else 0.0)
          if need >> i & 1 else 0.0)
    return prices.program - phase.plain_items[i] - (prices.address_item if addresses >> i & 1 else 0.0) - pv

def solve_parts(phase: PartsPhase, whole: int, addresses: int, channels: Channels) -> Parts:
    """The DP over program numbers behind `parts` (`PartsDP`)."""
    need = phase.pv_changed & ~whole
    movable = (phase.relevant_programs | addresses) & ~whole  # programs a 21h could help
    if not need and not movable:
        return Parts((), 0, 0, 0, 0.0)
    dp = PartsDP(phase, need, movable, addresses, channels, live_channels(phase, whole, addresses, need))
    return _traced(phase, *dp.solve())

def _traced(phase: PartsPhase, back: list[dict[int, Back]], state: int) -> Parts:
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
            positions |= (phase.masks[i] & P_BIT and 1) << i
            speeds |= (phase.masks[i] & V_BIT and 1) << i
        elif move is PartsMove.WHOLE:
            whole |= 1 << i
        j -= 1
    runs.reverse()
    return Parts(tuple(runs), positions, speeds, whole,
                 fsum(phase.parts_price[last - first + 1] for first, last in runs))

class PartsDP:
    """One run of the DP behind `write_phase.WritePhase.parts`, over program numbers.

    best[j]: the cheapest way to write P and V of the programs before j, per state: the room
    left in the last 40h and in the last 41h (0: none open, the next item opens one and pays
    its header) and the programs taken out of each live 42h..46h field (`live_channels`) by
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

    def __init__(self, phase: PartsPhase, need: int, movable: int, addresses: int, channels: Channels,
                 live: list[LiveChannel]) -> None:
        prices = phase.prices
        self.phase, self.need, self.movable, self.addresses, self.live = phase, need, movable, addresses, live
        self.positions, self.speeds, self.runs_allowed = channels.positions, channels.speeds, channels.parts
        self.states = States((prices.field_header, prices.field_header, *(c.header for c in live)),
                             (FIELDS.capacity, FIELDS.capacity, *(c.rho for c in live)))
        self.more_p = suffix_counts(need & phase.changed[P_BIT])
        self.more_v = suffix_counts(need & phase.changed[V_BIT])
        self.windows: dict[int, Window] = {}  # per state a run may end in: its starts
        self.taken: dict[tuple[int, int], int] = {}
        self.rhos = [c.rho for c in live]

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
        address = phase.prices.address_item if self.addresses >> j & 1 else 0.0
        alone = phase.prices.program - phase.plain_items[j] - address
        return out, alone if self.need >> j & 1 or out or alone < 0 else INF

    def _after(self, state: int, out: int) -> int:
        after = self.taken.get((state, out))
        if after is None:
            after = self.taken[(state, out)] = States.taken_out(state, out, self.rhos)
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

    def moves(self, j: int, best: dict[int, float], out: int,
              alone: float) -> tuple[dict[int, float], dict[int, Back]]:
        """The states after program j by its own moves (items, a 32h, a 21h, nothing), and the
        runs that may start at it: one pass over the states, each state's moves in that order (a tie
        goes to the first)."""
        phase = self.phase
        prices, m, needs = phase.prices, phase.masks[j], self.need >> j & 1
        as_items = needs and (self.positions or not m & P_BIT) and (self.speeds or not m & V_BIT)
        left_p, left_v = self.more_p[j + 1], self.more_v[j + 1]
        opened = prices.field_item + prices.field_header  # an item that opens a 40h/41h
        add_p, rooms_p = _items_field(prices.field_item, opened, bool(m & P_BIT), left_p)
        add_v, rooms_v = _items_field(prices.field_item, opened, bool(m & V_BIT), left_v)
        runs = needs and self.runs_allowed
        # else no room is beyond what the programs left could use
        capped = left_p < FIELDS.capacity or left_v < FIELDS.capacity
        single = phase.parts_price[1]
        new: dict[int, float] = {}
        step: dict[int, Back] = {}
        for state, b in best.items():
            was_p, was_v = state & FIELD, state >> STATE_BITS & FIELD
            if as_items:
                c = b + add_p[was_p] + add_v[was_v]
                after = state & NOT_ROOMS | rooms_p[was_p] | rooms_v[was_v] << STATE_BITS
                if c < new.get(after, INF):
                    new[after], step[after] = c, (state, PartsMove.ITEMS, j, 0)
            # the other moves leave the state as it was, but for room no item left could use
            kept = with_rooms(state, was_p, was_v, left_p, left_v) if capped else state
            if runs:
                self._run_starts(kept, j, b - prices.parts_item * j, state)
                if b + single < new.get(kept, INF):
                    new[kept], step[kept] = b + single, (state, PartsMove.RUN, j, 0)
            elif not needs and b < new.get(kept, INF):
                new[kept], step[kept] = b, (state, PartsMove.NOTHING, j, 0)
            if alone < INF:
                after = self._after(kept, out) if out else kept
                if b + alone < new.get(after, INF):
                    new[after], step[after] = b + alone, (state, PartsMove.WHOLE, j, 0)
        return new, step

    def _run_starts(self, kept: int, j: int, key: float, state: int) -> None:
        """A 33h run may start at program j from `state`: pushed onto the window of `kept` (`Window`)."""
        if (starts := self.windows.get(kept)) is None:
            starts = self.windows[kept] = deque()
        while starts and starts[-1][0] >= key:
            starts.pop()
        starts.append((key, j, state, 0))

    def ends(self, j: int, new: dict[int, float], step: dict[int, Back]) -> None:
        """The 33h runs that end at program j, the cheapest start in each state's window."""
        prices, windows = self.phase.prices, self.windows
        head, to_j = prices.parts_header, prices.parts_item * (j + 1)
        gone = j - PARTS.capacity  # a run is at most 15 programs long: starts up to here are out
        left_p, left_v = self.more_p[j + 1], self.more_v[j + 1]
        capped = left_p < FIELDS.capacity or left_v < FIELDS.capacity  # as in `moves`
        for state, window in list(windows.items()):
            after = state
            if capped:
                if windows.get(state) is not window:
                    continue  # merged into another at this program
                # the state the runs end in, but for room no item left could use (as `moves` leaves it)
                room_p, room_v = state & FIELD, state >> STATE_BITS & FIELD
                if room_p > left_p or room_v > left_v:
                    after = with_rooms(state, room_p, room_v, left_p, left_v)
                    del windows[state]
                    window = windows[after] = merged(window, windows[after]) if after in windows else window
            while window and window[0][1] <= gone:
                window.popleft()
            if not window:
                del windows[after]
                continue
            key, i, began, inside = window[0]
            if (through := key + head + to_j) < new.get(after, INF):
                new[after], step[after] = through, (began, PartsMove.RUN, i, inside)

    def final(self, best: dict[int, float]) -> int:
        """The cheapest state after the last program, the live fields' headers counted."""
        final, total = 0, INF
        for state, b in best.items():
            value = b + fsum(c.header * c.kind.messages(c.n - States.field(state, k + 2))
                             for k, c in enumerate(self.live))
            if value < total:
                final, total = state, value
        return final


@functools.lru_cache(maxsize=1024)  # per line's prices and items left: a few hundred in a plant
def _items_field(item: float, opened: float, takes: bool,
                 left: int) -> tuple[tuple[float, ...], tuple[int, ...]]:
    """P (or V) of a program as a 40h (41h) item where it `takes` one, by the room left in the last such
    message (0: none open): what it adds — the item that opens a message pays its header — and the room
    after, no more than the `left` items from the next program on could use."""
    rooms = range(FIELDS.capacity + 1)
    if not takes:
        return (0.0,) * len(rooms), tuple(min(room, left) for room in rooms)
    return (tuple(item if room else opened for room in rooms),
            tuple(min((room or FIELDS.capacity) - 1, left) for room in rooms))


def suffix_counts(mask: int) -> list[int]:
    """For each index 0..64, how many of the programs from it on are in `mask`."""
    counts = [0] * (PROGRAM_COUNT + 1)
    for i in range(PROGRAM_COUNT - 1, -1, -1):
        counts[i] = counts[i + 1] + (mask >> i & 1)
    return counts
