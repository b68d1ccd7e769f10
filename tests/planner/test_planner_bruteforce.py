"""Cross-check against brute force on tiny modules: no plan of up to three messages is cheaper.

Only programs 1..3 are managed; the others are unmanaged and not read. The candidate
messages are every message that touches only programs 1..3 and writes desired values
(and the system step, the inits, the link/unlink ranges). A cheapest-first search over
the module states the device model gives for them finds the cheapest plan of at most
three messages; the planner's plan must cost no more, and the lower bound of
bench/plan_bench.py (`Relaxation`, run without the plan as its incumbent) no more than it.
"""

from __future__ import annotations

import heapq
import itertools
import random
from dataclasses import replace

import pytest
from planner_helpers import FRAMINGS, check_plan, line, plan_bench

from prc3cfg.core import codec, device
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.image import (
    DEFAULT_SYSTEM,
    PROGRAM_COUNT,
    PROGRAM_FIELDS,
    ModuleImage,
    Program,
    default_program,
)
from prc3cfg.core.planner import plan_module

MANAGED = (1, 2, 3)
DEPTH = 3


def candidates(desired: ModuleImage, system_differs: bool) -> list[codec.Message]:
    want = {n: desired.programs[n - 1] for n in MANAGED}
    out: list[codec.Message] = []
    if system_differs:
        out += [codec.InitSystem(), codec.WriteSystem(desired.system)]
    out += [codec.InitProgram(n) for n in MANAGED]
    out += [codec.WriteProgram(n, want[n]) for n in MANAGED]
    out += [codec.WritePartProgram(n, want[n].P, want[n].V) for n in MANAGED]
    for first, last in itertools.combinations_with_replacement(MANAGED, 2):
        numbers = range(first, last + 1)
        out += [codec.InitPrograms(first, last), codec.UnlinkPrograms(first, last)]
        if first < last:
            out.append(codec.LinkPrograms(first, last))
        out.append(codec.WritePartPrograms(first, tuple((want[n].P, want[n].V) for n in numbers)))
    for size in (1, 2, 3):
        for subset in itertools.combinations(MANAGED, size):
            for name, cls in codec.FIELD_MESSAGES.items():
                out.append(cls(tuple((n, getattr(want[n], name)) for n in subset)))
            out.append(codec.WriteAddresses(tuple((n, want[n].A) for n in subset)))
    return out


def cheapest_short_plan(actual: ModuleImage, desired: ModuleImage, cost: LineCost,
                        bound: float) -> float | None:
    """The bus time of the cheapest plan of at most DEPTH candidates costing less than `bound`."""
    filler = default_program(actual.system)
    start = device.ModuleState(replace(actual, programs=tuple(filler if p is None else p
                                                              for p in actual.programs)))
    goal = (desired.system, tuple(desired.programs[n - 1] for n in MANAGED))
    priced = [(cost.message_time(desired.address, m), m)
              for m in candidates(desired, actual.system != desired.system)]
    queue: list[tuple[float, int, int, device.ModuleState]] = [(0.0, 0, 0, start)]
    seen: set = set()
    tie = itertools.count()
    while queue:
        time, _, depth, state = heapq.heappop(queue)
        key = (state.image.system, tuple(state.image.programs[n - 1] for n in MANAGED))
        if time >= bound:
            continue
        if key == goal:
            return time
        if key in seen or depth == DEPTH:
            continue
        seen.add(key)
        for price, message in priced:
            if time + price >= bound:
                continue
            try:
                after = device.execute(state, message)
            except codec.Rejected:
                continue
            heapq.heappush(queue, (time + price, next(tie), depth + 1, after))
    return None


def tiny_case(seed: int) -> tuple[ModuleImage, ModuleImage]:
    rnd = random.Random(seed)
    system = rnd.choice([DEFAULT_SYSTEM, replace(DEFAULT_SYSTEM, S1=1200, S2=200, S4=400, S5=30)])

    def program(n: int) -> Program:
        return rnd.choice([
            default_program(system),
            Program(rnd.randint(0, system.S1), rnd.randint(system.S5, system.S4), 0, rnd.choice([0, 20]),
                    rnd.choice([0, 1010]), 0, rnd.choice([0, n + 1])),
        ])

    unmanaged = (None,) * (PROGRAM_COUNT - len(MANAGED))
    programs = [program(n) for n in MANAGED]
    actual = ModuleImage(rnd.randint(1, 30), system, (*programs, *unmanaged))
    new_system = system
    if rnd.random() < 0.3:
        new_system = rnd.choice([DEFAULT_SYSTEM, replace(system, S1=rnd.randint(100, system.S1)),
                                 replace(system, S2=rnd.randint(50, 500))])
    wanted = list(programs)
    for _ in range(rnd.randint(0, 3)):
        n = rnd.choice(MANAGED)
        choice = rnd.randrange(4)
        if choice == 0:
            name = rnd.choice(PROGRAM_FIELDS)
            limit = {"P": new_system.S1, "V": new_system.S4, "A": 4}.get(name, 600)
            low = new_system.S5 if name == "V" else 0
            wanted[n - 1] = wanted[n - 1].with_field(name, rnd.randint(low, limit))
        elif choice == 1:
            wanted[n - 1] = default_program(rnd.choice([system, new_system]))
        elif choice == 2:
            wanted = [p.with_field("A", m + 1 if m < 3 else 0) for m, p in enumerate(wanted, start=1)]
        else:
            wanted[n - 1] = program(n)
    wanted = [replace(p, P=min(p.P, new_system.S1), V=min(max(p.V, new_system.S5), new_system.S4))
              for p in wanted]
    return actual, ModuleImage(actual.address, new_system, (*wanted, *unmanaged))


@pytest.mark.parametrize("framing", FRAMINGS)
@pytest.mark.parametrize("seed", [*range(10),
                                  *(pytest.param(seed, marks=pytest.mark.soak) for seed in range(10, 60))])
def test_no_short_plan_is_cheaper(framing: str, seed: int) -> None:
    actual, desired = tiny_case(seed)
    cost = line(framing, turnaround=random.Random(seed).choice([0.0, 0.010]))
    plan = plan_module(actual, desired, cost)
    check_plan(plan, actual, desired, cost)
    cheaper = cheapest_short_plan(actual, desired, cost, bound=plan.bus_time - 1e-9)
    assert cheaper is None, (f"a plan of {cheaper * 1000:.2f} ms beats the planner's "
                             f"{plan.bus_time * 1000:.2f} ms")
    bound, _ = plan_bench.Relaxation(actual, desired, cost).bound()
    assert bound <= plan.bus_time + 1e-9, (f"the bound {bound * 1000:.2f} ms is above a plan of "
                                           f"{plan.bus_time * 1000:.2f} ms")
