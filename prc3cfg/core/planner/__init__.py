"""The planner: per module, the cheapest message sequence that turns the read-back into the desired image.

`plan_module(actual, desired, cost)` derives the module's problem (`problem`), searches
for cheap layouts (`optimise`), builds their messages (`layout`), prices them exactly
with the line's `LineCost`, keeps the cheapest, and proves it on the device model from the
read-back (`check.run_steps`, the same proof a plan file passes before `apply --plan`
sends it): every step accepted, the desired image on the system and every managed
program, no unmanaged program written. A plan that fails this is a planner bug
(`PlanVerificationError`), never returned.

Owns: the module plan. Does not own the diff shown to people, rendering, the plan file
(`prc3cfg.core.plantplan`) or sending anything. Pure: no I/O.
"""

from __future__ import annotations

from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.image import ModuleImage
from prc3cfg.core.planner.check import StepProblem, run_steps
from prc3cfg.core.planner.layout import Layout
from prc3cfg.core.planner.optimise import search, whole_programs
from prc3cfg.core.planner.plan import ModulePlan, PlanVerificationError, Step, UnreachableImage, summarise
from prc3cfg.core.planner.problem import Problem

#: Layouts within this fraction of the best estimate are priced exactly (stx stuffing adds bytes).
STUFFING_MARGIN = 0.03
EXACTLY_PRICED = 4


def plan_module(actual: ModuleImage, desired: ModuleImage, cost: LineCost) -> ModulePlan:
    """The cheapest plan found from `actual` (the read-back) to `desired` (the plant file's image).

    `None` programs in `desired` are unmanaged and never touched; they may be `None` in
    `actual` too (not read). Raises `UnreachableImage` when no plan can reach `desired`.
    """
    problem = Problem.build(actual, desired, cost)
    layouts = search(problem)
    # The estimates are exact but for stx stuffing: price exactly only the layouts that could win.
    close = [layout for layout in layouts if layout.estimate <= layouts[0].estimate * (1 + STUFFING_MARGIN)]
    best, best_time = _cheapest(problem, cost, close[:EXACTLY_PRICED])
    if best_time > naive_bus_time(actual, desired, cost):
        best, best_time = _cheapest(problem, cost, [whole_programs(problem)])
    try:
        return plan_from_steps(actual, desired, best, cost)
    except StepProblem as found:
        raise PlanVerificationError(f"module {desired.address}: {found}; steps: {[m.hex() for m in best]}") from None


def plan_from_steps(actual: ModuleImage, desired: ModuleImage, messages: list[codec.Message], cost: LineCost) -> ModulePlan:
    """A plan of given steps (the planner's, or a plan file's), proved on the device model.

    Raises `StepProblem` naming the first step that breaks a rule of `check.run_steps`.
    """
    predicted = run_steps(actual, desired, messages)
    steps = tuple(Step(message, summarise(message, actual.system), message.RELEASES_AXES) for message in messages)
    return ModulePlan(
        address=desired.address,
        steps=steps,
        bus_time=sum(cost.message_time(desired.address, m) for m in messages),
        naive_bus_time=naive_bus_time(actual, desired, cost),
        releases_axes=any(step.releases_axes for step in steps),
        predicted=predicted,
    )


def _cheapest(problem: Problem, cost: LineCost, layouts: list[Layout]) -> tuple[list[codec.Message], float]:
    """The messages of the layout that is cheapest on the line, and their bus time."""
    priced = []
    for layout in layouts:
        messages = layout.messages(problem)
        priced.append((sum(cost.message_time(problem.address, m) for m in messages), messages))
    time, messages = min(priced, key=lambda pair: pair[0])
    return messages, time


def naive_bus_time(actual: ModuleImage, desired: ModuleImage, cost: LineCost) -> float:
    """The naive download: a 20h if the system parameters differ, one 21h per changed managed program."""
    messages: list[codec.Message] = []
    if actual.system != desired.system:
        messages.append(codec.WriteSystem(desired.system))
    for number, (have, want) in enumerate(zip(actual.programs, desired.programs), start=1):
        if want is not None and have != want:
            messages.append(codec.WriteProgram(number, want))
    return sum(cost.message_time(desired.address, m) for m in messages)


__all__ = [
    "ModulePlan", "PlanVerificationError", "Step", "StepProblem", "UnreachableImage", "plan_from_steps", "plan_module", "run_steps",
    "summarise",
]  # fmt: skip
