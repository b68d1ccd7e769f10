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
them and dropping what does not pay, beside adding them one by one; the cheaper wins. Pure.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from math import inf
from typing import NamedTuple

from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.image import DEFAULT_SYSTEM, PROGRAM_FIELDS, PROGRAM_NUMBERS, ModuleImage, SystemParameters
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
from prc3cfg.core.verification import verification_time

#: Items per message of the per-field messages (40h..45h; 46h carries 31).
FIELD_ITEMS = codec.MAX_FIELD_ITEMS


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


def share(modules: Sequence[SharingModule], cost: LineCost, memo: SharingMemo | None = None, proof_time: float = 0.0) -> Shared:
    """The cheapest broadcasts found for a line whose every module is in `modules`: groups added
    one by one while they pay, or all of them with those dropped that do not — the cheaper.
    `proof_time` is what any broadcast costs besides: proving that nobody else is on the line
    (every address outside `modules` probed, and silent), so broadcasts must save more than it.

    `memo` (shared by the lines of a plant) plans, proves and prices each kind of module once per
    set of broadcasts: modules alike but for their address cost the same (the address counts only
    on stx, where it can change a frame's stuffing), so a line of modules alike costs one module's
    search. A set of broadcasts that cannot beat the best found is dropped at the first module
    that makes it dearer."""
    memo = SharingMemo() if memo is None else memo
    groups = _candidates(modules)
    modules = [replace(m, kind=memo.kind(m, cost)) for m in modules]
    nothing = _attempt((), modules, cost, memo)
    assert nothing is not None  # without broadcasts, every module's own plan stands
    added = nothing
    for group in groups:  # add while it pays
        trial = _attempt(added[0] + group, modules, cost, memo, bound=added[2] - 1e-9)
        if trial is not None and trial[2] < added[2] - 1e-9:
            added = trial
    kept = list(groups)
    dropped = _attempt(tuple(step for group in kept for step in group), modules, cost, memo) or nothing
    for group in groups:  # from all of them, drop while that pays
        rest = [g for g in kept if g is not group]
        # a bound only where a set the modules cannot take (`nothing` in its place) could not win either
        bound = dropped[2] - 1e-9 if nothing[2] >= dropped[2] - 1e-9 else inf
        trial = _attempt(tuple(step for g in rest for step in g), modules, cost, memo, bound) or nothing
        if trial[2] < dropped[2] - 1e-9:
            kept, dropped = rest, trial
    broadcasts, owns, _ = min((nothing, added, dropped), key=lambda priced: priced[2] + (proof_time if priced[0] else 0.0))
    received: dict[SystemParameters, tuple[Step, ...]] = {}  # the broadcasts, summarised as each module sees them
    plans = tuple(_plan(module, own, received, broadcasts) for module, own in zip(modules, owns)) if broadcasts else tuple(m.plan for m in modules)
    bus_time = sum(cost.broadcast_time(step.message) for step in broadcasts) + sum(p.bus_time for p in plans)
    return Shared(broadcasts, plans, bus_time)


def _plan(module: SharingModule, own: _Own, received: dict[SystemParameters, tuple[Step, ...]], broadcasts: tuple[Step, ...]) -> ModulePlan:
    """A module's plan behind the broadcasts: the steps that reach it, its own bus time."""
    actual = module.actual
    if actual.system not in received:
        received[actual.system] = tuple(Step(s.message, summarise(s.message, actual.system), s.message.RELEASES_AXES) for s in broadcasts)
    steps = (*received[actual.system], *own.steps)
    predicted = own.predicted if own.predicted.address == actual.address else replace(own.predicted, address=actual.address)
    return ModulePlan(module.desired.address, steps, own.bus_time, module.plan.naive_bus_time,
                      any(step.releases_axes for step in steps), predicted)  # fmt: skip


def _candidates(modules: Sequence[SharingModule]) -> list[tuple[Step, ...]]:
    """Groups of broadcast steps: the system block, then per field the items every module shares."""
    first = modules[0]
    groups: list[tuple[Step, ...]] = []
    wanted = first.desired.system
    if all(m.desired.system == wanted for m in modules) and sum(m.actual.system != wanted for m in modules) >= 2:
        message = codec.InitSystem() if wanted == DEFAULT_SYSTEM else codec.WriteSystem(wanted)
        groups.append((Step(message, summarise(message, first.actual.system), True),))
    for field in PROGRAM_FIELDS:
        items = []
        for number in PROGRAM_NUMBERS:
            desired = [p for m in modules if (p := m.desired.program(number)) is not None]
            values = {getattr(p, field) for p in desired}
            if len(values) != 1 or len(desired) != len(modules):
                continue
            (value,) = values
            differing = sum(m.actual.program(number) is None or getattr(m.actual.program(number), field) != value for m in modules)
            if differing >= 2:
                items.append((number, value))
        kind = codec.WriteAddresses if field == "A" else codec.FIELD_MESSAGES[field]
        size = codec.MAX_ADDRESS_ITEMS if field == "A" else FIELD_ITEMS
        messages = [kind(tuple(items[i : i + size])) for i in range(0, len(items), size)]
        if messages:
            groups.append(tuple(Step(m, summarise(m, first.actual.system), False) for m in messages))
    return groups


def _attempt(broadcasts: tuple[Step, ...], modules: Sequence[SharingModule], cost: LineCost, memo: SharingMemo,
             bound: float = inf) -> _Attempt | None:  # fmt: skip
    """(broadcasts, each module's own steps, the line's bus time — broadcasts, own steps and every
    verifying read-back); None where a module cannot take the broadcasts. Each kind of module is
    priced once (`memo`); where the bus time reaches `bound` the rest is not priced: the bus time is
    then infinite."""
    messages = tuple(step.message for step in broadcasts)
    total = sum(cost.broadcast_time(message) for message in messages)
    owns = []
    for module in modules:
        key = (messages, module.kind)
        if key not in memo.owns:
            memo.owns[key] = _priced(broadcasts, module, cost)
        own = memo.owns[key]
        if own is None:
            return None
        owns.append(own)
        total += own.seconds
        if total >= bound:
            return _Attempt(broadcasts, (), inf)
    return _Attempt(broadcasts, tuple(owns), total)


@dataclass(frozen=True, slots=True)
class _Own:
    """What reaches a module behind a set of broadcasts, proved on the device model with them."""

    steps: tuple[Step, ...]  # its own steps, after the broadcasts
    bus_time: float  # its own steps'
    seconds: float  # its own steps' and the verifying read-back of everything that reaches it
    predicted: ModuleImage  # its programs those of the desired image where they are equal: the memo holds many


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
            raise PlanVerificationError(f"module {actual.address}: {found}; steps: {[m.hex() for m in messages]}") from None
        steps = tuple(Step(m, summarise(m, actual.system), m.RELEASES_AXES) for m in own)
        programs = tuple(want if want == have else have for have, want in zip(predicted.programs, module.desired.programs))
        predicted = replace(predicted, programs=programs)
    return _Own(steps, bus_time, bus_time + verification_time(actual, predicted, (*broadcasts, *steps), cost), predicted)
