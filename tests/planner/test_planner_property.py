"""The acceptance property of issue 5: the plan, run on the device model from the read-back, gives the desired
images.

Scenarios are built like real plant changes: a read-back image, then a handful of
mutations of it for the plant file (a recipe tweak, a teach-in, new system parameters
that clamp programs, programs reset to defaults before or after the system step, chains
relinked, unmanaged programs, a factory reset, nothing at all), on every framing.
"""

from __future__ import annotations

import random
from dataclasses import replace
from math import fsum

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from planner_helpers import FRAMINGS, check_plan, line

from prc3cfg.core.image import (
    DEFAULT_SYSTEM,
    PROGRAM_COUNT,
    PROGRAM_FIELDS,
    ModuleImage,
    Program,
    SystemParameters,
    default_program,
)
from prc3cfg.core.planner import plan_module
from prc3cfg.core.planner.init_search import search
from prc3cfg.core.planner.problem import PlanningProblem
from prc3cfg.core.planner.write_phase import WritePhase


def random_system(rnd: random.Random) -> SystemParameters:
    s4 = rnd.choice([600, 500, rnd.randint(1, 600)])
    return SystemParameters(
        S1=rnd.choice([400, 2000, 9999, rnd.randint(100, 9999)]), S2=rnd.choice([50, rnd.randint(50, 500)]),
        S3=rnd.randint(1, 9999), S4=s4, S5=rnd.choice([min(10, s4), rnd.randint(1, s4)]),
        S6=rnd.randint(1000, 1500), S7=rnd.randint(800, 1500), S8=rnd.randint(0, 1),
        S10=rnd.randint(1, 9999), S11=rnd.randint(1, 1500), S12=rnd.randint(5, 50),
    )


def random_program(rnd: random.Random, system: SystemParameters, number: int) -> Program:
    return Program(
        P=rnd.randint(0, system.S1),
        V=rnd.randint(system.S5, system.S4),
        Vr=rnd.choice([0, 0, rnd.randint(-600, 600)]),
        T=rnd.choice([0, rnd.randint(0, 600)]),
        F1=rnd.choice([0, 1010, rnd.randint(0, 1999)]),
        F2=rnd.choice([0, 0, rnd.randint(0, 1999)]),
        A=rnd.choice([0, min(number + 1, PROGRAM_COUNT), rnd.randint(0, PROGRAM_COUNT)]),
    )


def valid_under(program: Program, system: SystemParameters) -> Program:
    """The program with P and V brought into what `system` accepts."""
    return replace(program, P=min(program.P, system.S1), V=max(min(program.V, system.S4), system.S5))


def read_back(rnd: random.Random) -> ModuleImage:
    system = rnd.choice([DEFAULT_SYSTEM, random_system(rnd)])
    used = rnd.randint(0, PROGRAM_COUNT)
    default = default_program(system)
    programs = [random_program(rnd, system, n) if n <= used else default for n in range(1, PROGRAM_COUNT + 1)]
    return ModuleImage(rnd.randint(1, 30), system, tuple(programs))


def span(rnd: random.Random) -> range:
    first = rnd.randint(1, PROGRAM_COUNT)
    return range(first, min(PROGRAM_COUNT, first + rnd.choice([0, 2, 5, 14, 30, 63])) + 1)


def new_system(rnd: random.Random, old: SystemParameters) -> SystemParameters:
    choice = rnd.randrange(5)
    if choice == 0:
        return DEFAULT_SYSTEM
    if choice == 1:  # lower S1: clamping moves positions
        return replace(old, S1=rnd.randint(100, old.S1))
    if choice == 2:  # narrow the speeds: clamping moves speeds
        s4 = rnd.randint(1, old.S4)
        return replace(old, S4=s4, S5=rnd.randint(min(old.S5, s4), s4))
    if choice == 3:  # a new reference point: a new default position
        return replace(old, S2=rnd.randint(50, 500))
    return random_system(rnd)


def plant_file(rnd: random.Random, actual: ModuleImage, mutations: list[int]) -> ModuleImage:
    system = actual.system
    programs = list(actual.programs)
    for mutation in mutations:
        if mutation == 0:  # recipe tweak: one field of a few programs
            name = rnd.choice(PROGRAM_FIELDS)
            for n in rnd.sample(range(1, 65), rnd.randint(1, 5)):
                value = getattr(random_program(rnd, system, n), name)
                programs[n - 1] = programs[n - 1].with_field(name, value)
        elif mutation == 1:  # teach-in revert: positions of many programs
            for n in rnd.sample(range(1, 65), rnd.randint(1, 20)):
                programs[n - 1] = replace(programs[n - 1], P=rnd.randint(0, system.S1))
        elif mutation == 2:
            system = new_system(rnd, system)
        elif mutation == 3:  # cleanup: programs back to the defaults of the new or the old system
            source = rnd.choice([system, actual.system])
            for n in span(rnd):
                programs[n - 1] = default_program(source)
        elif mutation == 4:  # rechaining
            numbers = span(rnd)
            for n in numbers:
                linked = rnd.random() < 0.8 and n != numbers[-1]
                programs[n - 1] = programs[n - 1].with_field("A", n + 1 if linked else 0)
        elif mutation == 5:  # whole programs rewritten
            for n in span(rnd):
                programs[n - 1] = random_program(rnd, system, n)
        elif mutation == 6:  # factory reset
            system = DEFAULT_SYSTEM
            programs = [default_program(system)] * PROGRAM_COUNT
    return replace(actual, system=system, programs=tuple(valid_under(p, system) for p in programs))


@st.composite
def scenarios(draw: st.DrawFn) -> tuple[ModuleImage, ModuleImage, dict[int, Program], str, float]:
    rnd = draw(st.randoms(use_true_random=False))
    actual = read_back(rnd)
    mutations = draw(st.lists(st.integers(0, 6), max_size=4))
    desired = plant_file(rnd, actual, mutations)
    unread: dict[int, Program] = {}
    if draw(st.booleans()):  # unmanaged programs, some of them not read at all
        unmanaged = set(span(rnd)) | set(rnd.sample(range(1, 65), rnd.randint(0, 6)))
        read_too = draw(st.booleans())
        actual_programs, desired_programs = list(actual.programs), list(desired.programs)
        for n in unmanaged:
            desired_programs[n - 1] = None
            if not read_too:
                actual_programs[n - 1] = None
                unread[n] = Program(*(rnd.randint(0, 9999), rnd.randint(1, 600), 0, 0, 0, 0,
                                      rnd.randint(0, 64)))
        actual = replace(actual, programs=tuple(actual_programs))
        desired = replace(desired, programs=tuple(desired_programs))
    framing = draw(st.sampled_from(FRAMINGS))
    turnaround = draw(st.sampled_from([0.0, 0.005, 0.010, 0.050]))
    return actual, desired, unread, framing, turnaround


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenarios())
def test_plan_reaches_the_desired_image(scenario) -> None:
    actual, desired, unread, framing, turnaround = scenario
    cost = line(framing, turnaround)
    plan = plan_module(actual, desired, cost)
    check_plan(plan, actual, desired, cost, unread)


@pytest.mark.soak
@settings(suppress_health_check=[HealthCheck.too_slow])  # the soak profile's 2,000 examples
@given(scenarios())
def test_plan_reaches_the_desired_image_in_many_more_scenarios(scenario) -> None:
    test_plan_reaches_the_desired_image.hypothesis.inner_test(scenario)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenarios())
def test_where_no_byte_is_stuffed_every_candidates_estimate_is_its_bus_time(scenario) -> None:
    """`plan_module` prices only the cheapest candidate where the framing stuffs no byte: it takes
    the search's estimates for the bus time of their messages."""
    actual, desired, _, framing, turnaround = scenario
    cost = line(framing, turnaround)
    assume(not cost.framing.stuffs)
    problem = PlanningProblem.build(actual, desired, cost)
    for layout in search(problem):
        priced = fsum(cost.message_time(problem.address, message) for message in layout.messages(problem))
        assert layout.estimate == pytest.approx(priced, abs=1e-9)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenarios())
def test_no_candidates_write_phase_costs_less_than_the_bounds_the_search_prunes_by(scenario) -> None:
    """The search drops an init choice, a set of 21h or a jump-address alternative whose lower bound
    (`WritePhase.floor`, `WritePhase.at_least`, headers counted whole) is not below the best plan: each
    bound is below every write phase it is the bound of — here, each candidate's, with the 21h it took."""
    actual, desired, _, framing, turnaround = scenario
    problem = PlanningProblem.build(actual, desired, line(framing, turnaround))
    for layout in search(problem):
        phase, writes = WritePhase(problem, layout.kinds), layout.writes
        assert phase.floor <= writes.estimate + 1e-9
        assert phase.at_least(writes.whole, len(writes.ranges)) <= writes.estimate + 1e-9


@pytest.mark.soak
@settings(suppress_health_check=[HealthCheck.too_slow])  # the soak profile's 2,000 examples
@given(scenarios())
def test_no_candidates_write_phase_costs_less_than_the_bounds_in_many_more_scenarios(scenario) -> None:
    test_no_candidates_write_phase_costs_less_than_the_bounds_the_search_prunes_by.hypothesis.inner_test(scenario)
