"""Helpers for the planner tests: lines to plan for, the acceptance check of a plan, and the bench's lower
bound.

`check_plan` is the invariant of issue 5, checked from outside the planner: the steps,
run on the device model from the read-back (programs that were not read filled with
whatever the test chooses), are accepted one by one, give the desired system and managed
programs, and leave every unmanaged program as the module's own clamping leaves it.
"""

from __future__ import annotations

import importlib
import math
import random
import sys
from dataclasses import replace
from pathlib import Path

from prc3cfg.core import codec, device
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.image import ModuleImage, Program, default_program
from prc3cfg.core.line import LineSettings
from prc3cfg.core.planner import ModulePlan

FRAMINGS = ("crc16", "open-driver", "stx")

#: bench/plan_bench.py, whose lower bound the tests hold below the plans.
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
plan_bench = importlib.import_module("plan_bench")


def bench_case(scenario: str) -> tuple[ModuleImage, ModuleImage]:
    """bench/plan_bench.py's fixed case `scenario` (of the plant runs or of the exact comparison): its
    read-back and plant file, made from a generator seeded with its name, as the bench's exact table makes
    its first."""
    return (plan_bench.SCENARIOS | plan_bench.MORE_SCENARIOS)[scenario](random.Random(scenario))


def line(framing: str = "crc16", turnaround: float = 0.010, zvz: float = 0.020) -> LineCost:
    return LineCost.of(framing, LineSettings(), turnaround, zvz)


def with_programs(image: ModuleImage, changes: dict[int, Program | None]) -> ModuleImage:
    """`image` with programs (by number) replaced."""
    programs = list(image.programs)
    for number, program in changes.items():
        programs[number - 1] = program
    return replace(image, programs=tuple(programs))


def check_plan(
    plan: ModulePlan,
    actual: ModuleImage,
    desired: ModuleImage,
    cost: LineCost,
    unread: dict[int, Program] | None = None,
) -> None:
    """Assert the acceptance invariant and the plan's bookkeeping."""
    filler = default_program(actual.system)
    unread = unread or {}
    start_programs = tuple(
        p if p is not None else unread.get(n, filler) for n, p in enumerate(actual.programs, start=1)
    )
    state = device.ModuleState(replace(actual, programs=start_programs))
    clamped = state
    managed = {n for n, p in enumerate(desired.programs, start=1) if p is not None}
    for step in plan.steps:
        message = step.message
        assert step.releases_axes == message.RELEASES_AXES
        assert not set(message.touched_programs()) - managed, f"{step.summary} touches unmanaged programs"
        assert codec.decode_message(message.encode()) == message
        state = device.execute(state, message)  # raises Rejected when the module would refuse it
        if message.RELEASES_AXES:
            clamped = device.execute(clamped, message)
    assert state.image.system == desired.system
    for number, (got, want) in enumerate(zip(state.image.programs, desired.programs), start=1):
        if want is not None:
            assert got == want, f"program {number}: {got} != {want}"
        else:
            assert got == clamped.image.programs[number - 1], f"unmanaged program {number} was changed"
    assert plan.predicted.system == desired.system
    for number, (predicted, have, want) in enumerate(zip(plan.predicted.programs, actual.programs,
                                                         desired.programs), 1):
        if want is not None:
            assert predicted == want
        elif have is not None:  # read, not managed: shown as the module's clamping leaves it
            assert predicted == clamped.image.programs[number - 1]
        else:
            assert predicted is None
    assert plan.bus_time == math.fsum(cost.message_time(desired.address, s.message) for s in plan.steps)
    assert plan.bus_time <= plan.naive_bus_time + 1e-12
    system_steps = [s for s in plan.steps if s.message.RELEASES_AXES]
    assert len(system_steps) == (actual.system != desired.system)
    assert plan.releases_axes == bool(system_steps)
    differs = actual.system != desired.system or any(
        want is not None and have != want for have, want in zip(actual.programs, desired.programs)
    )
    assert bool(plan.steps) == differs
