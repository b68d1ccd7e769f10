"""The planner: per module, the cheapest message sequence that turns the read-back into the desired image.

`plan_module(actual, desired, cost)` derives the module's problem (`problem`), searches
for cheap layouts (`optimise`), builds their messages (`layout`), prices them exactly
with the line's `LineCost`, keeps the cheapest, and runs it on the device model
(`prc3cfg.device`) from the read-back: every step must be accepted and the result must be
the desired image on the system and every managed program, touching no unmanaged program.
A plan that fails this is a planner bug (`PlanVerificationError`), never returned.

Owns: the module plan. Does not own the diff shown to people, rendering, the plan file
(`prc3cfg.plantplan`) or sending anything. Pure: no I/O.
"""

from __future__ import annotations

from dataclasses import replace

from prc3cfg import codec, device
from prc3cfg.bustime import LineCost
from prc3cfg.image import ModuleImage
from prc3cfg.planner.optimise import search
from prc3cfg.planner.plan import ModulePlan, PlanVerificationError, Step, UnreachableImage, summarise
from prc3cfg.planner.problem import Problem


def plan_module(actual: ModuleImage, desired: ModuleImage, cost: LineCost) -> ModulePlan:
    """The cheapest plan found from `actual` (the read-back) to `desired` (the plant file's image).

    `None` programs in `desired` are unmanaged and never touched; they may be `None` in
    `actual` too (not read). Raises `UnreachableImage` when no plan can reach `desired`.
    """
    problem = Problem.build(actual, desired, cost)
    best: list[codec.Message] | None = None
    best_time = 0.0
    for layout in search(problem):
        messages = layout.messages(problem)
        time = sum(cost.message_time(problem.address, m) for m in messages)
        if best is None or time < best_time:
            best, best_time = messages, time
    assert best is not None
    predicted = _verify(problem, best)
    steps = []
    system = actual.system
    for message in best:
        steps.append(Step(message, summarise(message, system), message.RELEASES_AXES))
        if isinstance(message, codec.WriteSystem):
            system = message.system
    return ModulePlan(
        address=problem.address,
        steps=tuple(steps),
        bus_time=best_time,
        naive_bus_time=naive_bus_time(actual, desired, cost),
        releases_axes=any(step.releases_axes for step in steps),
        predicted=predicted,
    )


def naive_bus_time(actual: ModuleImage, desired: ModuleImage, cost: LineCost) -> float:
    """The naive download: a 20h if the system parameters differ, one 21h per changed managed program."""
    messages: list[codec.Message] = []
    if actual.system != desired.system:
        messages.append(codec.WriteSystem(desired.system))
    for number, (have, want) in enumerate(zip(actual.programs, desired.programs), start=1):
        if want is not None and have != want:
            messages.append(codec.WriteProgram(number, want))
    return sum(cost.message_time(desired.address, m) for m in messages)


def _verify(problem: Problem, messages: list[codec.Message]) -> ModuleImage:
    """Run the plan on the device model; the predicted image (managed programs only) or a bug report."""
    state = problem.start
    for index, message in enumerate(messages, start=1):
        trespass = [n for n in message.touched_programs() if not problem.managed[n - 1]]
        if trespass:
            raise PlanVerificationError(f"module {problem.address}: step {index} ({message.hex()}) "
                                        f"touches unmanaged programs {trespass}")  # fmt: skip
        try:
            state = device.execute(state, message)
        except codec.Rejected as rejected:
            raise PlanVerificationError(f"module {problem.address}: step {index} ({message.hex()}) "
                                        f"would be rejected with code {rejected.code}: {rejected}") from None  # fmt: skip
    image = state.image
    predicted = replace(
        image, programs=tuple(p if managed else None for p, managed in zip(image.programs, problem.managed))
    )
    wrong = [n for n, (p, want) in enumerate(zip(predicted.programs, problem.desired.programs), 1) if p != want]
    if predicted.system != problem.desired.system or wrong:
        raise PlanVerificationError(
            f"module {problem.address}: the plan gives system {predicted.system} and programs {wrong} "
            f"differing from the desired image; steps: {[m.hex() for m in messages]}"
        )
    return predicted


__all__ = ["ModulePlan", "PlanVerificationError", "Step", "UnreachableImage", "plan_module"]
