"""The plan cache of `prc3cfg.core.plant_planner`: modules alike but for their address are planned once."""

from __future__ import annotations

from dataclasses import replace

from prc3cfg.core.bustime import LineCost
from prc3cfg.core.image import ModuleImage
from prc3cfg.core.line import LineSettings
from prc3cfg.core.plant_planner import PlanCache


def wanting_a_new_position(address: int) -> tuple[ModuleImage, ModuleImage]:
    actual = ModuleImage.factory(address)
    program = actual.programs[0]
    assert program is not None
    return actual, replace(actual, programs=(replace(program, P=program.P + 100), *actual.programs[1:]))


def test_modules_alike_but_for_their_address_share_one_plan():
    cache = PlanCache()
    cost = LineCost.of("crc16", LineSettings(), 0.010, 0.020)
    first = cache.plan(*wanting_a_new_position(1), cost)
    second = cache.plan(*wanting_a_new_position(2), cost)
    assert first.steps and second.steps is first.steps  # planned once, reused
    assert (second.address, second.predicted.address) == (2, 2)


def test_a_module_that_reported_e12_is_planned_apart():
    cache = PlanCache()
    cost = LineCost.of("crc16", LineSettings(), 0.010, 0.020)
    plain = cache.plan(*wanting_a_new_position(1), cost)
    unset = cache.plan(*wanting_a_new_position(2), cost, system_unset=True)
    assert unset.steps is not plain.steps


def test_a_cached_plan_holds_the_desired_image_s_programs_not_copies_of_them():
    """The cache keeps a plan of every module of the plant (32 × 30 modules holding programs of
    their own: 960 predictions of 64 programs): each predicted program that is the desired one is
    the desired image's own object, not another copy of it."""
    actual, desired = wanting_a_new_position(1)
    plan = PlanCache().plan(actual, desired, LineCost.of("crc16", LineSettings(), 0.010, 0.020))
    assert plan.predicted.programs == desired.programs
    assert all(p is w for p, w in zip(plan.predicted.programs, desired.programs, strict=True))
