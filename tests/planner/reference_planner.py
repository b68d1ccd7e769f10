"""The reference planner: the cheapest plan of one module in the canonical order, by a plain DP.

    reference = reference_plan(actual, desired, cost)   # its messages, their bus time, its optimum

It is the oracle `prc3cfg.core.planner` must equal (issue 43): slow, small and written to be read, not
to be fast. It knows nothing of the planner's price tables or states; it uses the device model
(`prc3cfg.core.device`) for what a message does and the line (`LineCost.message_time`) for what it costs.

The plans it chooses from are the canonical order the planner searches (bench/exact_reference.py draws
the same space as an integer programme):

    inits before the system step · the system step · inits · link/unlink ranges · 21h · 32h/33h · 40h..46h

- the system step: none when the system parameters match, else 20h of the desired ones, or 10h where those
  are the factory defaults (both tried);
- init runs (11h..14h, the cheapest message of the run) of managed programs, on either side of the system
  step; a program under a run after the step holds the later init's defaults ("after"), one under a run
  before it only the old defaults clamped by the new parameters ("before"), any other keeps what it held;
- link (30h) and unlink (31h) ranges in two layers: outer ranges, and inner ranges of the other kind
  inside them, sent after them (a link range gives A(i) = i + 1 but 0 on its last program, an unlink
  range 0: an inner range's program shows the inner range's address);
- a 21h per program, 32h/33h runs of up to 15 programs (P and V), and then an item in 40h..46h for every
  field still wrong, each field's items in full messages in program order (as the planner sends them).

Every run covers managed programs only. The bases (what a program holds after the system step, with no
init, or an init after or before it) come from running 10h/20h and 14h on the device model.

The DP walks programs 1..64. Its state between program i and i + 1 is the runs still open past i (each
init layer's, each range layer's, the 33h's: what their message's price needs of their first program) and
the room left in each field's last 40h..46h message; its value the cheapest bus time so far, a header
counted where an item finds no room. Three things keep it small, each exact:
- at a program, of the choices that leave the same runs open and the same fields to items, only the
  cheapest is kept (the rest of the plan depends on nothing else);
- a room larger than the items its field can still take past i is cut to that many (no header follows);
- of two states with the same runs open, one is dropped where the other costs no more even with a header
  more in each field where it has less room (`_pareto`): at most one header a field separates them.
That is the whole algorithm: no bound, no heuristic, no order of search.

What is exact: every message but 40h..46h is priced by the line as sent; 40h..46h items by their header
and item bytes, measured on the line (the values' stuffed bytes on stx counted item by item). On stx
alone, a message whose checksum is 7Eh costs a byte more: the DP prices a 40h..46h message, and a run of
more than one program but a 33h, as if its checksum were not stuffed (so that an open run need not keep
its first program). The DP's optimum (`ReferencePlan.optimum`) is then a lower bound and the plan's bus
time (`bus_time`) exact for its own messages — equal on crc16 and open-driver.

What it takes (one core, measured): a second to 55 s on the found cases and most of bench/plan_bench.py's
fixed cases, on every framing; 170 s on a full rewrite on crc16 or stx, 606 s on open-driver. It gives up
(`TooBig`) beyond `limit` states a program.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator
from dataclasses import dataclass, replace

from prc3cfg.core import codec, device
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.image import DEFAULT_SYSTEM, PROGRAM_COUNT, PROGRAM_FIELDS, ModuleImage, default_program

#: What a program holds before any write: as the system step left it, initialised after it, or before it.
KEEP, BEFORE, AFTER = "keep", "before", "after"
#: The layers of runs, in the order their messages are sent (the system step after BEFORE's; 21h before
#: PARTS').
OUTER, INNER, PARTS = "outer", "inner", "parts"
LAYERS = (BEFORE, AFTER, OUTER, INNER, PARTS)
#: The kinds of run: an init, a link or an unlink range, P and V of consecutive programs.
INIT, LINK, UNLINK = "init", "link", "unlink"
#: States (runs open, item counts) beyond which one program's step of the DP gives up.
MAX_STATES = 200_000
ITEM_MESSAGES = {name: kind.message for name, kind in codec.FIELD_KINDS.items()}
CAPACITY = {name: kind.capacity for name, kind in codec.FIELD_KINDS.items()}
PARTS_CAPACITY = codec.ITEMS_KINDS[codec.WritePartPrograms.ID].capacity
NO_RUNS = (None,) * len(LAYERS)
#: Seconds below which two sums of the same prices in another order are the same bus time.
EPSILON = 1e-9

#: A run open past a program: its kind and what its price needs of its first program (`_Module.opened`).
Open = tuple[str, int] | None
#: A run over a program: its kind, whether it starts there, whether it ends there.
Mark = tuple[str, bool, bool] | None
#: A layer's choice at a program: the run over it, the run open past it, the price of the run that ends there.
LayerOption = tuple[Mark, Open, float]
#: The runs over a program, one a layer.
Marks = tuple[Mark, ...]
#: The runs open past a program, one a layer.
Runs = tuple[Open, ...]
#: Items each field's last 40h..46h message still takes (0: full, or none yet: an item there opens one).
Rooms = tuple[int, ...]


class TooBig(RuntimeError):
    """The module has more open runs and item counts at once than the reference enumerates."""


@dataclass(frozen=True, slots=True)
class ReferencePlan:
    messages: tuple[codec.Message, ...]
    bus_time: float  # the messages' bus time, by the line
    optimum: float  # the DP's: equal to bus_time but for a stx checksum of 7Eh in 40h..46h


@dataclass(frozen=True, slots=True)
class Choice:
    """What the DP decided at one program."""

    number: int
    marks: tuple[Mark, ...]  # per layer
    whole: bool  # a 21h
    items: tuple[str, ...]  # the fields written as 40h..46h items


#: The choices so far, the last first: (the last, the chain of the ones before it).
Chain = tuple[Choice, "Chain"] | None
#: A state's value: its bus time so far and its choices.
Entry = tuple[float, Chain]


def reference_plan(actual: ModuleImage, desired: ModuleImage, cost: LineCost, *,
                   limit: int = MAX_STATES) -> ReferencePlan:
    """The cheapest plan in the canonical order from `actual` to `desired` (`None` programs: unmanaged);
    `TooBig` where a program's step of the DP holds more than `limit` states."""
    start = starting_state(actual)
    steps: list[codec.Message | None] = [None]
    if actual.system != desired.system:
        steps = [codec.WriteSystem(desired.system),
                 *([codec.InitSystem()] if desired.system == DEFAULT_SYSTEM else [])]
    return min((_Module(start, desired, step, cost).solve(limit) for step in steps),
               key=lambda plan: plan.bus_time)


def starting_state(actual: ModuleImage) -> device.ModuleState:
    """The read-back as a module: programs not read hold their defaults (they are never written)."""
    filler = default_program(actual.system)
    return device.ModuleState(replace(actual, programs=tuple(filler if p is None else p
                                                             for p in actual.programs)))


def init_message(first: int, last: int) -> codec.Message:
    """The init of exactly programs first..last: 11h, 12h, 13h or 14h (the shortest that does)."""
    if first == last:
        return codec.InitProgram(first)
    if last == PROGRAM_COUNT:
        return codec.InitAllPrograms() if first == 1 else codec.InitProgramsFrom(first)
    return codec.InitPrograms(first, last)


class _Module:
    """One module and one system step: its bases, its prices and the DP (module docstring)."""

    def __init__(self, start: device.ModuleState, desired: ModuleImage, step: codec.Message | None,
                 cost: LineCost) -> None:
        self.desired, self.step, self.cost = desired, step, cost
        self.prices: dict[codec.Message, float] = {}
        # the DP asks the same of the same programs again and again: each answer is worked out once
        self.layer_options = functools.cache(self.layer_options)  # type: ignore[method-assign]
        self.filled = functools.cache(self.filled)  # type: ignore[method-assign]
        after_step = start if step is None else device.execute(start, step)
        before = device.execute(start, codec.InitAllPrograms())
        self.bases = {
            KEEP: after_step.image.programs,
            AFTER: device.execute(after_step, codec.InitAllPrograms()).image.programs,
            BEFORE: (before if step is None else device.execute(before, step)).image.programs,
        }
        # a layer that can change nothing is left out: it could only add messages
        wanted = [(n, w) for n, w in enumerate(desired.programs) if w is not None]
        self.offered = {
            BEFORE: self.bases[BEFORE] not in (self.bases[KEEP], self.bases[AFTER]),
            AFTER: self.bases[AFTER] != self.bases[KEEP],
            PARTS: any(getattr(base[n], f) != getattr(w, f) for base in self.bases.values()
                       for n, w in wanted for f in "PV"),
            OUTER: any(base[n].A != w.A for base in self.bases.values() for n, w in wanted),
        }
        self.offered[INNER] = self.offered[OUTER]

    def price(self, message: codec.Message) -> float:
        """The bus time of `message` by the line (each message priced once: the DP asks again and again)."""
        if message not in self.prices:
            self.prices[message] = self.cost.message_time(self.desired.address, message)
        return self.prices[message]

    # -- runs: their messages, and what of their first program their price needs ---------------

    def message(self, kind: str, first: int, last: int) -> codec.Message:
        if kind == INIT:
            return init_message(first, last)
        if kind == LINK:
            return codec.LinkPrograms(first, last)
        if kind == UNLINK:
            return codec.UnlinkPrograms(first, last)
        known = self.desired.known  # PARTS: a 32h for one program, a 33h for more
        if first == last:
            return codec.WritePartProgram(first, known(first).P, known(first).V)
        return codec.WritePartPrograms(first, tuple((known(n).P, known(n).V) for n in range(first, last + 1)))

    def opened(self, kind: str, first: int) -> int:
        """What an open run keeps of its first program: all of it where the run's values and length count
        (PARTS: a 33h's P and V); else, for an init, whether it is program 1 (a 14h from there to 64) — 0
        stands for any other, whose messages the line prices alike but for a stx checksum (`closing`)."""
        if kind == PARTS:
            return first
        return 1 if kind == INIT and first == 1 else 0

    def closing(self, kind: str, kept: int, last: int) -> float:
        """The price of a run of `kind` that started before `last` (at `kept`, or anywhere but program 1
        where 0) and ends there. On stx the one byte of an 11h..14h, 30h or 31h the line may stuff is its
        checksum (a program number, an address or a message ID is never 7Eh): the run is priced as the
        cheapest of two messages of its shape whose checksums differ — a price no dearer than its own."""
        if kept or not self.cost.framing.stuffs:
            return self.price(self.message(kind, kept or last - 1, last))
        firsts = range(max(2 if kind == INIT else 1, last - 2), last)
        return min(self.price(self.message(kind, first, last)) for first in firsts)

    def layer_options(self, open_: Open, number: int, must_end: bool, kinds: tuple[str, ...]
                      ) -> list[LayerOption]:
        """A layer at program `number`: (the run over it, the run open past it, the price of the run that
        ends here) for each choice."""
        if open_ is not None:
            kind, kept = open_
            ends: list[LayerOption] = [((kind, False, True), None, self.closing(kind, kept, number))]
            if must_end or (kind == PARTS and number - kept + 1 == PARTS_CAPACITY):
                return ends
            return [*ends, ((kind, False, False), open_, 0.0)]
        options: list[LayerOption] = [(None, None, 0.0)]
        for kind in kinds:
            if kind != LINK:  # a link range of one program is an unlink range of it
                options.append(((kind, True, True), None, self.price(self.message(kind, number, number))))
            if not must_end:
                options.append(((kind, True, False), (kind, self.opened(kind, number)), 0.0))
        return options

    # -- 40h..46h items: a header for each message opened, the item's bytes for each item ------

    def item_prices(self, name: str) -> tuple[float, float]:
        """The price of a 40h..46h message of field `name` without its items, and of one item: measured
        on one- and two-item messages, of two sets of values whose checksums differ the one the line
        does not stuff a byte into (exact where the line stuffs none)."""
        cls = ITEM_MESSAGES[name]

        def unstuffed(size: int) -> float:
            return min(self.price(cls(tuple((n + 1, value) for n in range(size)))) for value in (1, 2))

        return 2 * unstuffed(1) - unstuffed(2), unstuffed(2) - unstuffed(1)

    def stuffed(self, name: str, number: int, value: int) -> float:
        """What the bytes stx stuffs into one item's encoded values add (nothing on other framings)."""
        if not self.cost.framing.stuffs:
            return 0.0
        one = ITEM_MESSAGES[name](((number, value),))
        return one.encode()[2 * one.HEADER_WORDS :].count(0x7E) * self.cost.line.char_time

    def items_after(self, number: int) -> tuple[int, ...]:
        """The most items each field can still take after program `number`: the managed programs past
        it whose field some base (or, for A, a range) can leave wrong."""
        later = [n for n in range(number + 1, PROGRAM_COUNT + 1) if self.desired.programs[n - 1] is not None]
        ranges = self.offered[OUTER]

        def shown(name: str, n: int) -> set[int]:
            held = {getattr(base[n - 1], name) for base in self.bases.values()}
            return held | {n + 1, 0} if name == "A" and ranges else held

        wanted = self.desired.known
        return tuple(sum(shown(name, n) != {getattr(wanted(n), name)} for n in later)
                     for name in PROGRAM_FIELDS)

    def filled(self, rooms: Rooms, written: tuple[str, ...], number: int) -> tuple[Rooms, float]:
        """The rooms after program `number`'s items of `written`, and the headers and items they cost.
        A room larger than the items its field can still take is as good as any other such room: it is
        cut to that many (`items_after`), so that states which differ only there are one."""
        new, spent = list(rooms), 0.0
        for k, name in enumerate(PROGRAM_FIELDS):
            if name in written:
                spent += self.items[k] + (self.headers[k] if rooms[k] == 0 else 0.0)
                new[k] = CAPACITY[name] - 1 if rooms[k] == 0 else rooms[k] - 1
        return tuple(map(min, new, self.later[number])), spent

    # -- the DP --------------------------------------------------------------------------------

    def solve(self, limit: int) -> ReferencePlan:
        self.headers, self.items = zip(*map(self.item_prices, PROGRAM_FIELDS))
        self.later = {number: self.items_after(number) for number in range(1, PROGRAM_COUNT + 1)}
        # runs open (per layer) -> {rooms of each field's last message: (bus time so far, the choices)}
        states: dict[Runs, dict[Rooms, tuple[float, Chain]]] = {
            NO_RUNS: {(0,) * len(PROGRAM_FIELDS): (0.0 if self.step is None else self.price(self.step), None)}
        }
        for number in range(1, PROGRAM_COUNT + 1):
            following: dict[Runs, dict[Rooms, tuple[float, Chain]]] = {}
            for runs, entries in states.items():
                for (next_runs, written), (added, choice) in self.moves(number, runs).items():
                    bucket = following.setdefault(next_runs, {})
                    for rooms, (spent, chain) in entries.items():
                        key, items = self.filled(rooms, written, number)
                        total = spent + added + items
                        if key not in bucket or total < bucket[key][0]:
                            bucket[key] = (total, (choice, chain))
            states = {runs: _pareto(bucket, self.headers) for runs, bucket in following.items()}
            if sum(map(len, states.values())) > limit:
                raise TooBig(f"module {self.desired.address}: more than {limit} states at program {number}")
        optimum, chain = min(states[NO_RUNS].values(), key=lambda entry: entry[0])
        messages = self.messages(chain)
        return ReferencePlan(tuple(messages), math.fsum(map(self.price, messages)), optimum)

    def moves(self, number: int, runs: Runs) -> dict[tuple[Runs, tuple[str, ...]], tuple[float, Choice]]:
        """The cheapest choice at program `number` from the runs open, for each pair of the runs open past
        it and the fields it leaves to 40h..46h items: all that the rest of the plan depends on."""
        cheapest: dict[tuple[Runs, tuple[str, ...]], tuple[float, Choice]] = {}
        for next_runs, marks, added, whole, written in self.choices(number, runs):
            key = (next_runs, written)
            if key not in cheapest or added < cheapest[key][0]:
                cheapest[key] = (added, Choice(number, marks, whole, written))
        return cheapest

    def choices(self, number: int, runs: Runs) -> Iterator[tuple[Runs, Marks, float, bool, tuple[str, ...]]]:
        """Every choice at program `number` from the runs open: (the runs open past it, the runs over it,
        the price of the runs that end here and of its 21h, whether a 21h writes it, its items' fields)."""
        want = self.desired.programs[number - 1]
        if want is None:  # no run covers an unmanaged program, and nothing writes it
            if runs == NO_RUNS:
                yield NO_RUNS, NO_RUNS, 0.0, False, ()
            return
        must_end = number == PROGRAM_COUNT or self.desired.programs[number] is None
        before, after, outer, inner, parts = runs
        whole = self.price(codec.WriteProgram(number, want))
        stuffed = {f: self.stuffed(f, number, getattr(want, f)) for f in PROGRAM_FIELDS}

        def options(layer: str, open_: Open, kinds: tuple[str, ...]) -> list[LayerOption]:
            if not self.offered[layer]:
                return [(None, None, 0.0)]
            return self.layer_options(open_, number, must_end, kinds)

        for b_mark, b_open, b_price in options(BEFORE, before, (INIT,)):
            for a_mark, a_open, a_price in options(AFTER, after, (INIT,)):
                base = self.bases[AFTER if a_mark else BEFORE if b_mark else KEEP][number - 1]
                for o_mark, o_open, o_price in options(OUTER, outer, (LINK, UNLINK)):
                    inner_kinds = () if o_mark is None else (UNLINK,) if o_mark[0] == LINK else (LINK,)
                    for i_mark, i_open, i_price in options(INNER, inner, inner_kinds):
                        if i_mark is not None and (o_mark is None or (o_mark[2] and not i_mark[2])):
                            continue  # an inner range lies inside an outer range
                        shown = base.A
                        # the inner range, sent after the outer, has the last word
                        for mark in (o_mark, i_mark):
                            if mark is not None:
                                shown = number + 1 if mark[0] == LINK and not mark[2] else 0
                        for p_mark, p_open, p_price in options(PARTS, parts, (PARTS,)):
                            wrong = tuple(f for f in PROGRAM_FIELDS if not (p_mark and f in "PV")
                                          and (shown if f == "A" else getattr(base, f)) != getattr(want, f))
                            next_runs = (b_open, a_open, o_open, i_open, p_open)
                            marks = (b_mark, a_mark, o_mark, i_mark, p_mark)
                            price = math.fsum((b_price, a_price, o_price, i_price, p_price))
                            yield next_runs, marks, price + math.fsum(stuffed[f] for f in wrong), False, wrong
                            if wrong:
                                yield next_runs, marks, price + whole, True, ()

    def messages(self, chain: Chain) -> list[codec.Message]:
        """The plan of the DP's choices, in the canonical order."""
        choices: list[Choice] = []
        while chain is not None:
            choice, chain = chain
            choices.append(choice)
        choices.reverse()
        runs: dict[str, list[codec.Message]] = {}
        for k, layer in enumerate(LAYERS):
            first = 0
            for choice in choices:
                mark = choice.marks[k]
                if mark is not None and mark[1]:
                    first = choice.number
                if mark is not None and mark[2]:
                    runs.setdefault(layer, []).append(self.message(mark[0], first, choice.number))
        known = self.desired.known
        out = [*runs.get(BEFORE, []), *([] if self.step is None else [self.step]), *runs.get(AFTER, [])]
        for layer in (OUTER, INNER):  # links, then unlinks, of each layer
            out += sorted(runs.get(layer, []), key=lambda m: m.ID)
        out += [codec.WriteProgram(c.number, known(c.number)) for c in choices if c.whole]
        out += runs.get(PARTS, [])
        for name in PROGRAM_FIELDS:
            items = [(c.number, getattr(known(c.number), name)) for c in choices if name in c.items]
            out += [ITEM_MESSAGES[name](tuple(items[k : k + CAPACITY[name]]))
                    for k in range(0, len(items), CAPACITY[name])]
        return out


def _pareto(bucket: dict[Rooms, Entry], headers: tuple[float, ...]) -> dict[Rooms, Entry]:
    """The entries no other entry beats. The rest of a plan costs the same after two entries but for
    the headers of the 40h..46h messages it opens, and less room in a field's last message costs at
    most one header more there (the same items, at most one message more): an entry whose bus time
    and a header for each field where it has less room is at most another's beats it."""
    kept: list[tuple[Rooms, float]] = []
    for rooms, (spent, _) in sorted(bucket.items(), key=lambda pair: pair[1][0]):
        if kept and kept[0][1] + sum(headers) <= spent + EPSILON:
            break  # the cheapest, a header more in every field, beats this one and every dearer one
        if not any(cost + sum(h for h, r, o in zip(headers, rooms, other) if o < r) <= spent + EPSILON
                   for other, cost in kept):
            kept.append((rooms, spent))
    return {rooms: bucket[rooms] for rooms, _ in kept}


__all__ = ["ReferencePlan", "TooBig", "reference_plan"]
