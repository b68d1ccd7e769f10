"""The lower bound of bench/plan_bench.py (`Relaxation`) is a true lower bound.

It must never be above the bus time of a plan that reaches the plant file: not above the
planner's plan on modules with a window of managed programs (and, in
test_planner_bruteforce, not above any plan of up to three messages on tiny modules); and it
is no empty claim where the answer is plain (a teach-in revert is one 40h: bound and plan
agree). The bound runs here without the plan as its incumbent, so nothing it is compared
with steers it.
"""

from __future__ import annotations

import random
from dataclasses import replace

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from planner_helpers import FRAMINGS, line, plan_bench, with_programs
from test_planner_cases import PLANT, recipe
from test_planner_property import plant_file, read_back

from prc3cfg.core.image import PROGRAM_COUNT
from prc3cfg.core.planner import plan_module

EPSILON = 1e-9


@st.composite
def windows(draw: st.DrawFn) -> tuple:
    """A module whose plant file manages a window of up to 12 programs (the others not read)."""
    rnd = draw(st.randoms(use_true_random=False))
    actual = read_back(rnd)
    desired = plant_file(rnd, actual, draw(st.lists(st.integers(0, 6), max_size=4)))
    first = rnd.randint(1, PROGRAM_COUNT)
    window = range(first, min(PROGRAM_COUNT, first + rnd.randint(0, 11)) + 1)
    outside = {n: None for n in range(1, PROGRAM_COUNT + 1) if n not in window}
    framing = draw(st.sampled_from(FRAMINGS))
    cost = line(framing, draw(st.sampled_from([0.0, 0.010, 0.050])),
                zvz=draw(st.sampled_from([0.020, 0.100])))
    return with_programs(actual, outside), with_programs(desired, outside), cost


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(windows())
def test_the_bound_is_not_above_the_plan(case: tuple) -> None:
    actual, desired, cost = case
    plan = plan_module(actual, desired, cost)
    bound, _ = plan_bench.Relaxation(actual, desired, cost).bound()
    assert bound <= plan.bus_time + EPSILON


@pytest.mark.parametrize("framing", FRAMINGS)
def test_a_teach_in_revert_is_bounded_by_its_one_40h(framing: str) -> None:
    taught = with_programs(PLANT, {n: replace(recipe(n), P=recipe(n).P + 7) for n in (2, 5, 9, 14, 20, 33)})
    cost = line(framing)
    plan = plan_module(taught, PLANT, cost)
    bound, optimum = plan_bench.Relaxation(taught, PLANT, cost).bound()
    assert optimum and bound == pytest.approx(plan.bus_time)


@pytest.mark.soak  # the bound of a full rewrite takes about two minutes of CPU
def test_a_full_rewrite_is_planned_at_the_optimum_of_the_relaxation() -> None:
    """64 programs rewritten (the bench's scenario): the plan is R's optimum. Three channels overflow
    together there (43h..45h), so only the bound with two of them counted exactly reaches it."""
    actual, desired = plan_bench.full_rewrite(random.Random("full rewrite"))
    cost = plan_bench.line_cost("crc16")
    plan = plan_module(actual, desired, cost)
    bound, optimum = plan_bench.Relaxation(actual, desired, cost).bound(plan.bus_time)
    assert optimum and bound == pytest.approx(plan.bus_time)
