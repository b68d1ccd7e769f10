"""The planner: per module, the cheapest message sequence that turns the read-back into the desired image.

`plan_module(actual, desired, cost)` derives the module's problem (`problem`), searches
for cheap layouts (`init_search`), builds their messages (`layout`), prices them exactly
with the line's `LineCost`, keeps the cheapest (`cheapest_messages`), and proves it, once, on
the device model from the read-back (`check.run_steps`, the same proof a plan file passes
before `apply --plan` sends it): every step accepted, the desired image on the system and
every managed program, no unmanaged program written. A plan that fails this is a planner bug
(`PlanVerificationError`), never returned.

Owns: the module plan. Does not own the diff shown to people, rendering, the plan file
(`prc3cfg.core.plant_plan`) or sending anything. Pure: no I/O.
"""

from __future__ import annotations

from dataclasses import replace
from math import fsum

from prc3cfg.core import codec, device
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.image import ModuleImage, default_program
from prc3cfg.core.planner.check import StepProblem, run_steps
from prc3cfg.core.planner.init_search import search
from prc3cfg.core.planner.layout import Layout, init_message, runs_of
from prc3cfg.core.planner.module_plan import (
    Action,
    ModulePlan,
    PlanVerificationError,
    Step,
    UnreachableImage,
    summarise,
)
from prc3cfg.core.planner.problem import KEEP, PlanningProblem
from prc3cfg.core.planner.write_phase import whole_programs

#: What a 20h that writes the system parameters a module already holds is for.
E12_SUMMARY = ("write the system parameters it holds: it reported E12 (system parameters not set), which "
               "only this clears")
#: Layouts within this fraction of the best estimate are priced exactly (stx stuffing adds bytes).
STUFFING_MARGIN = 0.03
EXACTLY_PRICED = 4
#: Programs an init run's message may leave out at each end, where that is cheaper on the line (`_trimmed`).
TRIMS = 6


def plan_module(actual: ModuleImage, desired: ModuleImage, cost: LineCost, *,
                system_unset: bool = False) -> ModulePlan:
    """The cheapest plan found from `actual` (the read-back) to `desired` (the plant file's image).

    `None` programs in `desired` are unmanaged and never touched; they may be `None` in
    `actual` too (not read). Raises `UnreachableImage` when no plan can reach `desired`.
    `system_unset`: the module reported E12 ("system parameters not set", code 23): it refuses every
    write but 10h/20h, and only they clear it — so its system parameters are written first even
    where they read back as the plant file's (releasing its axes, like any 20h).
    """
    if system_unset:  # the 20h first: until it has gone, the module refuses every other write
        first = codec.WriteSystem(desired.system)
        rest = plan_module(after(actual, [first]), desired, cost)
        return plan_from_steps(actual, desired, [first, *(s.message for s in rest.steps)], cost,
                               system_unset=True)
    best, best_time, naive = cheapest_messages(actual, desired, cost)
    try:
        return plan_from_steps(actual, desired, best, cost, bus_time=best_time, naive=naive)
    except StepProblem as found:
        raise PlanVerificationError(f"module {desired.address}: {found}; steps: "
                                    f"{[m.hex() for m in best]}") from None


def cheapest_messages(actual: ModuleImage, desired: ModuleImage,
                      cost: LineCost) -> tuple[list[codec.Message], float, float]:
    """The cheapest messages found from `actual` to `desired`, not yet proved on the device model
    (`plan_module` proves them; the sharing proves them behind its broadcasts), their bus time and
    the naive download's. Raises `UnreachableImage`."""
    problem = PlanningProblem.build(actual, desired, cost)
    layouts = search(problem)
    # stx stuffing adds bytes the estimates leave out: price the layouts that could win
    if cost.framing.stuffs:
        close = [layout for layout in layouts
                 if layout.estimate <= layouts[0].estimate * (1 + STUFFING_MARGIN)]
        best, best_time = _cheapest(problem, cost, close[:EXACTLY_PRICED])
    else:  # the estimates are exact
        best, best_time = _cheapest(problem, cost, layouts[:1])
    naive = naive_bus_time(actual, desired, cost)
    if best_time > naive:
        best, best_time = _cheapest(problem, cost, [whole_programs(problem)])
    return best, best_time, naive


def after(actual: ModuleImage, messages: list[codec.Message]) -> ModuleImage:
    """The read-back as `messages` leave it, by the device model (programs not read stay unknown);
    `codec.Rejected` if the module would refuse one."""
    filler = default_program(actual.system)
    state = device.ModuleState(replace(actual, programs=tuple(filler if p is None else p
                                                              for p in actual.programs)))
    for message in messages:
        state = device.execute(state, message)
    return replace(state.image,
                   programs=tuple(None if a is None else p
                                  for a, p in zip(actual.programs, state.image.programs)))


def plan_from_steps(actual: ModuleImage, desired: ModuleImage, messages: list[codec.Message], cost: LineCost,
                    *,
                    system_unset: bool = False, bus_time: float | None = None,
                    naive: float | None = None) -> ModulePlan:
    """A plan of given steps (the planner's, or a plan file's), proved on the device model
    (`system_unset`: see `plan_module`); `bus_time` and `naive`: the steps' bus time and the naive
    download's, where the caller has priced them.

    Raises `StepProblem` naming the first step that breaks a rule of `check.run_steps`.
    """
    predicted = run_steps(actual, desired, messages, system_unset=system_unset)
    steps = tuple(Step(message, summarise(message, actual.system), message.RELEASES_AXES)
                  for message in messages)
    if system_unset and steps and actual.system == desired.system:
        steps = (replace(steps[0], summary=f"{E12_SUMMARY} (20h)"), *steps[1:])
    return ModulePlan(
        address=desired.address,
        steps=steps,
        bus_time=(fsum(cost.message_time(desired.address, m) for m in messages) if bus_time is None
                  else bus_time),
        naive_bus_time=naive_bus_time(actual, desired, cost) if naive is None else naive,
        releases_axes=any(step.releases_axes for step in steps),
        predicted=predicted,
    )


def _cheapest(problem: PlanningProblem, cost: LineCost,
              layouts: list[Layout]) -> tuple[list[codec.Message], float]:
    """The messages of the layout that is cheapest on the line, and their bus time."""
    priced = []
    for layout in layouts:
        messages = _trimmed(problem, cost, layout).messages(problem)
        priced.append((fsum(cost.message_time(problem.address, m) for m in messages), messages))
    time, messages = min(priced, key=lambda pair: pair[0])
    return messages, time


def _trimmed(problem: PlanningProblem, cost: LineCost, layout: Layout) -> Layout:
    """`layout` with each init run's message the cheapest on the line of those without some of the
    programs at its ends that hold the plant file's values initialised or not (the search grows runs
    over them on a tie: `init_dp.TIE`) — on stx a run's bounds and check byte may be stuffed, and a
    shorter run not. At most TRIMS programs an end are tried; the rest of the plan is the same either
    way (those programs take no write)."""
    kinds = list(layout.kinds)
    for kind in problem.kinds[1:]:
        for first, last in runs_of(layout.kinds, kind):
            def alike(i: int, kind: int = kind) -> bool:
                return problem.masks[KEEP][i] == 0 and problem.masks[kind][i] == 0

            starts, ends = [first], [last]
            while len(starts) <= TRIMS and starts[-1] < last and alike(starts[-1]):
                starts.append(starts[-1] + 1)
            while len(ends) <= TRIMS and ends[-1] > first and alike(ends[-1]):
                ends.append(ends[-1] - 1)
            if len(starts) == len(ends) == 1:
                continue
            a, b = min(((a, b) for a in starts for b in ends if a <= b),
                       key=lambda run: cost.message_time(problem.address, init_message(*run)))
            kinds[first:a] = [KEEP] * (a - first)
            kinds[b + 1 : last + 1] = [KEEP] * (last - b)
    return layout if kinds == list(layout.kinds) else replace(layout, kinds=tuple(kinds))


def naive_bus_time(actual: ModuleImage, desired: ModuleImage, cost: LineCost) -> float:
    """The naive download: a 20h if the system parameters differ, one 21h per changed managed program."""
    total = (cost.message_time(desired.address, codec.WriteSystem(desired.system))
             if actual.system != desired.system else 0)
    each = None  # a 21h's time, where the framing does not stuff: the same for every program
    for number, (have, want) in enumerate(zip(actual.programs, desired.programs), start=1):
        if want is not None and have != want:
            if each is None or cost.framing.stuffs:
                each = cost.message_time(desired.address, codec.WriteProgram(number, want))
            total += each
    return total


__all__ = [
    "Action", "ModulePlan", "PlanVerificationError", "Step", "StepProblem", "UnreachableImage", "after",
           "cheapest_messages",
    "plan_from_steps", "plan_module", "run_steps", "summarise",
]
