"""Broadcasts: what every module of a line needs alike is sent once, to address 0.

The manual's ring call (address 0) is processed by every module on the line and answered by
none. When several modules of a line need the same values — a plant-wide speed limit, a
shared program, one system block — one broadcast can replace an addressed message per
module. It is used only where the plan can prove what it does to *every* receiver:

- every module on the line is a module of the plan: the plant lists every module of the line
  (a full line of 30 modules, or its own declaration) and the plan covers all of them — and,
  since a declaration in a file is no proof, the caller probes every other address in the same
  run and finds it silent; that costs line time (`proof_time`), which a broadcast must save;
- the broadcasts come first on the line, and each module's own plan is made from the state
  the broadcasts leave (the device model predicts it: defaults, clamping, refusals);
- each module's whole sequence — broadcasts, then its own steps — passes the proof every plan
  passes (`prc3cfg.core.planner.check.run_steps`): nothing refused, nothing written that the plant
  does not manage, no axis release for a module whose system parameters already match (so a
  10h/20h is broadcast only when every receiver needs exactly it, and every receiver is then
  in the axis gate);
- it is cheaper in bus time than the addressed plans, counting the verifying read-back of
  every receiver (a broadcast has no reply: each module is verified by reading back what it
  can have changed, and repaired with addressed writes if it does not match).

Candidates are the values every module of the line is to hold alike: the system block,
then per field (P, V, Vr, T, F1, F2, A) the programs whose desired value is the same on every
module and differs on at least two of them — sent as 40h..46h items. Groups that pay only
together (P and V, which one 33h run writes per module) are found by starting from all of
them and dropping what does not pay, beside adding them one by one; the cheaper wins. A set
of broadcasts is planned on every module only where it could win: what each module must cost
behind it whatever its own steps (`_Floor`: the words of the values it must still send, the
verification it must pay) drops the others unplanned — a line of modules that each hold
programs of their own is planned behind the set that wins, and hardly another. Pure.

It is long because the search and its bound are one algorithm: `_Floors` prunes the candidates of
`_Search` by the very prices `_attempt` charges, and apart each would have to repeat the other's terms.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from itertools import accumulate
from math import inf
from typing import NamedTuple

from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.image import (
    DEFAULT_SYSTEM,
    PROGRAM_NUMBERS,
    ModuleImage,
    Program,
    SystemParameters,
    default_program,
)
from prc3cfg.core.planner import (
    ModulePlan,
    PlanVerificationError,
    Step,
    StepProblem,
    UnreachableImage,
    after,
    cheapest_messages,
    run_steps,
    summarise,
)
from prc3cfg.core.what_to_read import reading_time, verification_time

#: A set of broadcasts wins by more than this; a floor drops one unplanned only where it is above
#: the bound by more than this (floors and prices add the same figures in other orders).
_WINS_BY = 1e-9
_FLOOR_MARGIN = 1e-7
#: The program fields a message carries as one word each (all but A), and the most words of them
#: one message carries (64 bytes, its ID word among them).
_WORD_FIELDS = ("P", "V", "Vr", "T", "F1", "F2")
_WORDS_PER_MESSAGE = codec.MAX_MESSAGE_BYTES // 2 - 1
#: The additions are checked for being out of reach (`_Search.add`) only where at most this many
#: sets are left to them: beyond, the check costs more than it saves.
_REACH_LIMIT = 64


@dataclass(frozen=True, slots=True)
class SharingModule:
    """One module of the line as the sharing sees it: read-back, desired image, its own plan."""

    actual: ModuleImage
    desired: ModuleImage
    plan: ModulePlan
    kind: int | None = None  # modules of one kind cost alike (`alike`)


def alike(actual: ModuleImage, desired: ModuleImage, cost: LineCost) -> tuple[object, ...]:
    """What a module's plan depends on: what it holds and should hold, and the line — its address
    only on stx, where it can change a frame's stuffing."""
    address = actual.address if cost.framing.name == "stx" else None
    return (actual.system, actual.programs, desired.system, desired.programs, address, cost)


class SharingMemo:
    """The broadcast search's memo, shared by the lines of a plant: each kind of module (`alike`)
    numbered once, and what reaches a kind behind each set of broadcasts (`_priced`)."""

    def __init__(self) -> None:
        self._kinds: dict[tuple[object, ...], int] = {}
        self.owns: dict[tuple[tuple[codec.Message, ...], int | None], _Own | None] = {}

    def kind(self, module: SharingModule, cost: LineCost) -> int:
        return self._kinds.setdefault(alike(module.actual, module.desired, cost), len(self._kinds))


class _Attempt(NamedTuple):
    """A set of broadcasts priced (`_attempt`): each module's own steps, the line's bus time."""

    broadcasts: tuple[Step, ...]
    owns: tuple[_Own, ...]
    seconds: float


@dataclass(frozen=True, slots=True)
class Shared:
    """The broadcasts of a line, and each module's plan: the broadcasts first, then its own steps."""

    broadcasts: tuple[Step, ...]
    plans: tuple[ModulePlan, ...]  # in the order of the modules given; steps include the broadcasts
    bus_time: float  # the broadcasts once, plus every module's own steps


def share(modules: Sequence[SharingModule], cost: LineCost, memo: SharingMemo | None = None,
          proof_time: float = 0.0) -> Shared:
    """The cheapest broadcasts found for a line whose every module is in `modules`: groups added
    one by one while they pay, or all of them with those dropped that do not — the cheaper.
    `proof_time` is what any broadcast costs besides: proving that nobody else is on the line
    (every address outside `modules` probed, and silent), so broadcasts must save more than it.

    `memo` (shared by the lines of a plant) plans, proves and prices each kind of module once per
    set of broadcasts: modules alike but for their address cost the same (the address counts only
    on stx, where it can change a frame's stuffing), so a line of modules alike costs one module's
    search. A set of broadcasts that cannot beat the best found is dropped unplanned where what
    its modules must cost at least (`_Floors`) says so, else at the first module that makes it
    dearer; the drops are searched first, so that the additions stop as soon as nothing they can
    still reach could beat what the drops found."""
    memo = SharingMemo() if memo is None else memo
    groups = _candidates(modules)
    modules = [replace(m, kind=memo.kind(m, cost)) for m in modules]
    search = _Search(groups, modules, cost, memo)
    nothing = search.attempt(0)
    assert nothing is not None  # without broadcasts, every module's own plan stands
    dropped, dropped_set = search.drop(nothing)
    best = min(nothing.seconds, dropped.seconds + (proof_time if dropped.broadcasts else 0.0))
    added = search.add(nothing, best, dropped_set, proof_time)
    broadcasts, owns, _ = min((nothing, added, dropped), key=lambda priced: priced[2]
                              + (proof_time if priced[0] else 0.0))
    # the broadcasts, summarised as each module sees them
    received: dict[SystemParameters, tuple[Step, ...]] = {}
    plans = (tuple(_plan(module, own, received, broadcasts) for module, own in zip(modules, owns))
             if broadcasts else tuple(m.plan for m in modules))
    bus_time = sum(cost.broadcast_time(step.message) for step in broadcasts) + sum(p.bus_time for p in plans)
    return Shared(broadcasts, plans, bus_time)


def _plan(module: SharingModule, own: _Own, received: dict[SystemParameters, tuple[Step, ...]],
          broadcasts: tuple[Step, ...]) -> ModulePlan:
    """A module's plan behind the broadcasts: the steps that reach it, its own bus time."""
    actual = module.actual
    if actual.system not in received:
        received[actual.system] = tuple(Step(s.message, summarise(s.message, actual.system),
                                             s.message.RELEASES_AXES) for s in broadcasts)
    steps = (*received[actual.system], *own.steps)
    predicted = own.predicted
    if predicted.address != actual.address:
        predicted = replace(predicted, address=actual.address)
    return ModulePlan(module.desired.address, steps, own.bus_time, module.plan.naive_bus_time,
                      any(step.releases_axes for step in steps), predicted)


def _candidates(modules: Sequence[SharingModule]) -> list[tuple[Step, ...]]:
    """Groups of broadcast steps: the system block, then per field the items every module shares."""
    first = modules[0]
    groups: list[tuple[Step, ...]] = []
    wanted = first.desired.system
    if (all(m.desired.system == wanted for m in modules)
        and sum(m.actual.system != wanted for m in modules) >= 2):
        message = codec.InitSystem() if wanted == DEFAULT_SYSTEM else codec.WriteSystem(wanted)
        groups.append((Step(message, summarise(message, first.actual.system), True),))
    # by program, then module
    desired = [[m.desired.programs[n - 1] for m in modules] for n in PROGRAM_NUMBERS]
    actual = [[m.actual.programs[n - 1] for m in modules] for n in PROGRAM_NUMBERS]
    for field, kind in codec.FIELD_KINDS.items():
        if not kind.broadcast:
            continue
        items = _shared_items(field, desired, actual)
        cls = codec.WriteAddresses if field == "A" else codec.FIELD_MESSAGES[field]
        messages = [cls(tuple(items[i : i + kind.capacity])) for i in range(0, len(items), kind.capacity)]
        if messages:
            groups.append(tuple(Step(m, summarise(m, first.actual.system), False) for m in messages))
    return groups


def _shared_items(field: str, desired: list[list[Program | None]],
                  actual: list[list[Program | None]]) -> list[tuple[int, int]]:
    """(program, value) of `field` for each program every module wants alike and two or more do not hold yet
    (`desired`, `actual`: each program's, module by module)."""
    items = []
    for number, wanted, held in zip(PROGRAM_NUMBERS, desired, actual):
        if not all(wanted):  # a module that does not manage it (a Program is always true)
            continue
        values = {getattr(p, field) for p in wanted if p is not None}
        if len(values) != 1:
            continue
        (value,) = values
        differing = sum(p is None or getattr(p, field) != value for p in held)
        if differing >= 2:
            items.append((number, value))
    return items


class _Search:
    """The broadcast search of one line. A set of broadcasts is a set of candidate groups: a bit per
    group, in `groups`' order, and its steps theirs in that order."""

    def __init__(self, groups: list[tuple[Step, ...]], modules: list[SharingModule], cost: LineCost,
                 memo: SharingMemo) -> None:
        self.groups, self.modules, self.cost, self.memo = groups, modules, cost, memo
        self.floors = _Floors(groups, modules, cost)

    def attempt(self, chosen: int, bound: float = inf) -> _Attempt | None:
        steps = tuple(step for i, group in enumerate(self.groups) if chosen >> i & 1 for step in group)
        floors = self.floors.of(chosen) if bound < inf else ()
        return _attempt(steps, self.modules, self.cost, self.memo, bound, floors)

    def drop(self, nothing: _Attempt) -> tuple[_Attempt, int]:
        """From all the groups, drop while that pays: the cheapest set found, priced, and its bits."""
        kept = every = (1 << len(self.groups)) - 1
        found = self.attempt(every)
        dropped, dropped_set = (nothing, 0) if found is None else (found, every)
        for i in range(len(self.groups)):
            rest = kept & ~(1 << i)
            # a bound only where a set the modules cannot take (`nothing` in its place) could not win either
            bound = dropped.seconds - _WINS_BY if nothing.seconds >= dropped.seconds - _WINS_BY else inf
            trial = self.attempt(rest, bound)
            trial, trial_set = (nothing, 0) if trial is None else (trial, rest)
            if trial.seconds < dropped.seconds - _WINS_BY:
                kept, dropped, dropped_set = rest, trial, trial_set
        return dropped, dropped_set

    def add(self, nothing: _Attempt, best: float, dropped_set: int, proof_time: float) -> _Attempt:
        """Add the groups one by one while they pay — or `nothing`, as soon as no set the additions
        can still end at could be chosen: none can cost `best` or less (what no broadcast or the
        drops cost, the proof included), but the drops' own set, which is then chosen alike."""
        added, chosen = nothing, 0
        for i in range(len(self.groups)):
            if self._out_of_reach(chosen, added.seconds, i, best, dropped_set, proof_time):
                return nothing
            trial = self.attempt(chosen | 1 << i, bound=added.seconds - _WINS_BY)
            if trial is not None and trial.seconds < added.seconds - _WINS_BY:
                added, chosen = trial, chosen | 1 << i
        return added

    def _out_of_reach(self, chosen: int, seconds: float, first: int, best: float, dropped_set: int,
                      proof_time: float) -> bool:
        """Whether the additions, at `chosen` (priced: `seconds`) with the groups from `first` on
        still to try, can only end at a set that is not chosen: one dearer than `best` — by its
        floor, where it is not priced — or the drops' own."""
        if chosen not in (0, dropped_set) and seconds + proof_time <= best:
            return False
        rest = len(self.groups) - first
        if 1 << rest > _REACH_LIMIT:
            return False
        for more in range(1, 1 << rest):
            reached = chosen | more << first
            if reached != dropped_set and self.floors.total(reached) + proof_time <= best + _FLOOR_MARGIN:
                return False
        return True


class _Group(NamedTuple):
    """A candidate group as the floors see it: whether it writes the system block, and the word
    field and programs its items write (`field` None: the system block, or 46h's jump addresses)."""

    system: bool
    field: str | None
    programs: int  # a bit per program, program 1 the lowest

    @classmethod
    def of(cls, steps: tuple[Step, ...]) -> _Group:
        messages = [step.message for step in steps]
        field = messages[0].FIELD if isinstance(messages[0], codec.WriteField) else None
        return cls(any(m.RELEASES_AXES for m in messages), field,
                   _bits(n for m in messages for n in m.touched_programs()))


class _Chosen(NamedTuple):
    """A set of groups as the floors see it: the system block among them, what each word field's
    group writes, and every program they write."""

    system: bool
    fields: dict[str, int]
    programs: int


class _Floors:
    """What each module of a line must cost at least behind a set of broadcasts, its plan not made
    (`_Floor`), by set; the line's total with the broadcasts. Made when first asked: a line
    whose search needs no bound needs no floor."""

    def __init__(self, groups: list[tuple[Step, ...]], modules: list[SharingModule], cost: LineCost) -> None:
        self._groups = [_Group.of(group) for group in groups]
        self._broadcast = [sum(cost.broadcast_time(step.message) for step in group) for group in groups]
        self._line, self._cost = modules, cost
        self._modules: list[_Floor] = []
        self._of: dict[int, tuple[float, ...]] = {}

    @property
    def modules(self) -> list[_Floor]:
        """Each module's floor, in order; modules alike share one."""
        if not self._modules:
            floors: dict[int | None, _Floor] = {}
            for module in self._line:
                if module.kind not in floors:
                    floors[module.kind] = _Floor(module, self._cost)
            self._modules = [floors[module.kind] for module in self._line]
        return self._modules

    def chosen(self, chosen: int) -> _Chosen:
        """The groups `chosen` as the floors see them."""
        groups = [g for i, g in enumerate(self._groups) if chosen >> i & 1]
        programs = 0
        for g in groups:
            programs |= g.programs
        return _Chosen(any(g.system for g in groups),
                       {g.field: g.programs for g in groups if g.field is not None}, programs)

    def of(self, chosen: int) -> tuple[float, ...]:
        """Each module's floor behind the groups `chosen`."""
        if chosen not in self._of:
            seen = self.chosen(chosen)
            by_kind: dict[int, float] = {}  # modules alike have one floor
            for floor in self.modules:
                if id(floor) not in by_kind:
                    by_kind[id(floor)] = floor.seconds(seen)
            self._of[chosen] = tuple(by_kind[id(floor)] for floor in self.modules)
        return self._of[chosen]

    def total(self, chosen: int) -> float:
        """The line's floor behind the groups `chosen`: their broadcasts, and every module's floor."""
        return sum(t for i, t in enumerate(self._broadcast) if chosen >> i & 1) + sum(self.of(chosen))


class _Floor:
    """What a module must cost at least behind broadcasts, whatever its own steps: every plan the
    proof passes (`run_steps`) ends at its desired image, with at most one 10h/20h, and writes no
    program it does not manage — so, proven without planning:

    - each program field a word carries (all but the jump address: one word in 21h, 32h, 33h and
      40h..45h alike) that differs after the broadcasts, and whose desired value no init,
      clamping or link can leave, costs a word of a message of its own steps — and each message
      its ID word and the line's turnaround;
    - a desired system block the broadcasts do not write costs the cheapest 10h/20h to it;
    - the verifying read-back (`what_to_read.reach`) reads the system block where one is written
      — and then every program whose prediction differs from its read-back: each managed one
      that differs, each other one that the new system block clamps — and what the broadcasts
      write, and what the own steps write: at least what they must, at most what is managed.
      Where the first already come to every program managed, what it reads is known exactly;
      else only its 50h is.
    """

    __slots__ = ("_address", "_changed", "_cost", "_managed", "_needs", "_reads", "_system_differs",
                 "_system_write")

    def __init__(self, module: SharingModule, cost: LineCost) -> None:
        actual, desired = module.actual, module.desired
        system = desired.system
        defaults = [default_program(s) for s in (actual.system, system)]
        free = {"P": {p.P for p in defaults} | {system.S1},
                "V": {p.V for p in defaults} | {system.S4, system.S5}}
        differing = [(n, have, want)
                     for n, (have, want) in enumerate(zip(actual.programs, desired.programs), 1)
                     if have is not None and want is not None and have != want]
        needs = []
        for field in _WORD_FIELDS:
            left = free.get(field, {0})
            bits = _bits(n for n, have, want in differing if getattr(have, field) != getattr(want, field)
                         and getattr(want, field) not in left)
            if bits:
                needs.append((field, bits))
        # (field, the programs whose value there takes a word)
        self._needs: tuple[tuple[str, int], ...] = tuple(needs)
        self._managed = _bits(n for n, p in enumerate(desired.programs, 1) if p is not None)
        self._system_differs = actual.system != system
        # what differs from the read-back after a system step
        self._changed = self._predicted_changes(module) if self._system_differs else 0
        writes: list[codec.Message] = []
        if self._system_differs:
            writes = [codec.WriteSystem(system), *((codec.InitSystem(),) if system == DEFAULT_SYSTEM else ())]
        self._system_write = min((cost.message_time(desired.address, m) for m in writes), default=0.0)
        self._address, self._cost = actual.address, cost
        self._reads: dict[tuple[int, bool], float] = {}

    @staticmethod
    def _predicted_changes(module: SharingModule) -> int | None:
        """The programs whose prediction differs from the read-back where a system step goes: the
        managed ones that differ, the others as the desired system block clamps them (None: the
        module refuses it)."""
        actual, desired = module.actual, module.desired
        try:
            clamped = after(actual, [codec.WriteSystem(desired.system)])
        except codec.Rejected:
            return None
        return _bits(n for n, (have, want, then) in enumerate(zip(actual.programs, desired.programs,
                                                                  clamped.programs), 1)
                     if have is not None and (want if want is not None else then) != have)

    def seconds(self, chosen: _Chosen) -> float:
        """The floor behind the groups `chosen`."""
        own, verification = self.parts(chosen)
        return own + verification

    def parts(self, chosen: _Chosen) -> tuple[float, float]:
        """The floor behind the groups `chosen`: of the own steps' bus time, of the verification's."""
        cost = self._cost
        words, written = 0, chosen.programs
        for field, bits in self._needs:
            left = bits & ~chosen.fields.get(field, 0)
            words += left.bit_count()
            written |= left
        messages = -(-words // _WORDS_PER_MESSAGE)
        own = (words + messages) * 2 * cost.line.char_time + messages * cost.turnaround
        if self._system_differs and not chosen.system:
            own += self._system_write
        system = chosen.system or self._system_differs
        if system:
            if self._changed is None:
                return own, self._read(0, True)
            written |= self._changed
        if written & self._managed != self._managed:
            return own, self._read(0, True) if system else 0.0
        return own, self._read(written, system)

    def _read(self, programs: int, system: bool) -> float:
        """What reading back `programs` (and the system block) costs, as `verification_time` prices it."""
        key = (programs, system)
        if key not in self._reads:
            self._reads[key] = reading_time(self._address, _numbers(programs), system, self._cost)
        return self._reads[key]


def _bits(numbers: Iterable[int]) -> int:
    """A set of program numbers as bits, program 1 the lowest."""
    bits = 0
    for n in numbers:
        bits |= 1 << (n - 1)
    return bits


def _numbers(bits: int) -> list[int]:
    return [n for n in PROGRAM_NUMBERS if bits >> (n - 1) & 1]


def _attempt(broadcasts: tuple[Step, ...], modules: Sequence[SharingModule], cost: LineCost,
             memo: SharingMemo,
             bound: float = inf, floors: Sequence[float] = ()) -> _Attempt | None:
    """(broadcasts, each module's own steps, the line's bus time — broadcasts, own steps and every
    verifying read-back); None where a module cannot take the broadcasts. Each kind of module is
    priced once (`memo`); where the bus time reaches `bound` — or would, with what the modules not
    priced yet cost at least (`floors`, one per module, if given) — the rest is not priced: the
    bus time is then infinite."""
    messages = tuple(step.message for step in broadcasts)
    total = sum(cost.broadcast_time(message) for message in messages)
    left = list(accumulate(reversed(floors), initial=0.0))[::-1] if floors else [0.0] * (len(modules) + 1)
    if total + left[0] > bound + _FLOOR_MARGIN:
        return _Attempt(broadcasts, (), inf)
    owns = []
    for index, module in enumerate(modules, start=1):
        key = (messages, module.kind)
        if key not in memo.owns:
            memo.owns[key] = _priced(broadcasts, module, cost)
        own = memo.owns[key]
        if own is None:
            return None
        owns.append(own)
        total += own.seconds
        if total >= bound or total + left[index] > bound + _FLOOR_MARGIN:
            return _Attempt(broadcasts, (), inf)
    return _Attempt(broadcasts, tuple(owns), total)


@dataclass(frozen=True, slots=True)
class _Own:
    """What reaches a module behind a set of broadcasts, proved on the device model with them."""

    steps: tuple[Step, ...]  # its own steps, after the broadcasts
    bus_time: float  # its own steps'
    seconds: float  # its own steps' and the verifying read-back of everything that reaches it
    # its programs those of the desired image where they are equal: the memo holds many
    predicted: ModuleImage


def _priced(broadcasts: tuple[Step, ...], module: SharingModule, cost: LineCost) -> _Own | None:
    """A module's own steps after the broadcasts, proved once — the broadcasts and they, from its
    read-back — and their bus time with the verifying read-back of everything that reaches it;
    None when the module cannot take the broadcasts."""
    actual = module.actual
    if not broadcasts:
        plan = module.plan
        steps, bus_time, predicted = plan.steps, plan.bus_time, plan.predicted
    else:
        try:
            before = after(actual, [s.message for s in broadcasts])
            own, bus_time, _ = cheapest_messages(before, module.desired, cost)
        except (codec.Rejected, UnreachableImage):
            return None
        messages = [*(s.message for s in broadcasts), *own]
        try:
            predicted = run_steps(actual, module.desired, messages)
        except StepProblem as found:
            if 0 < found.index <= len(broadcasts):
                return None  # a broadcast this module cannot take
            raise PlanVerificationError(f"module {actual.address}: {found}; steps: "
                                        f"{[m.hex() for m in messages]}") from None
        steps = tuple(Step(m, summarise(m, actual.system), m.RELEASES_AXES) for m in own)
        programs = tuple(want if want == have else have
                         for have, want in zip(predicted.programs, module.desired.programs))
        predicted = replace(predicted, programs=programs)
    return _Own(steps, bus_time, bus_time + verification_time(actual, predicted, (*broadcasts, *steps), cost),
                predicted)
