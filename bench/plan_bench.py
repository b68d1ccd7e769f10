"""The planner on realistic plant changes: plan bus time against the naive download and a lower bound.

    python bench/plan_bench.py [--framing crc16] [--framing open-driver] [--modules 30]

For each scenario and framing (9600 baud 8E1, turnaround 10 ms, ZVZ 20 ms) it prints the
plan's estimated bus time, the naive download's (20h if the system differs, one 21h per
changed program), a lower bound on *any* plan, the plan's message count and the planning
CPU time. Then it plans whole plants — N modules × 64 programs, fully managed, each with
one of the scenarios' changes ("mixed"), or each commissioned or changed a lot ("heavy") —
from images saved as JSON, and prints the total CPU time (acceptance: under 1 s for 30
modules).

The lower bound. A message of n bytes costs `exchange + byte × n` (exact for crc16 and
open-driver: no stuffing), and every message has a 2-byte ID word, so a plan of E
exchanges carrying B bytes beyond the ID words costs `E × (exchange + 2 byte) + B × byte`.
- The system step: when the system parameters differ, only 10h or 20h changes them;
  10h only gives the factory defaults. So the bound counts the 10h (factory) or the 20h.
- B: after its last initialisation (or the system step, if it is never initialised) a
  program still differs from its desired value in a set of fields the device model
  predicts (`Problem.masks`, for each of: not initialised, initialised before or after
  the system step), and every one of them must be written by a message carrying bytes
  for that program alone: a 21h (14 bytes), a 32h/33h pair (4 bytes for P and V), a
  40h..45h item (4 bytes per field), a 46h item (2 bytes) for a jump address no link or
  unlink range can give (other jump addresses may come free from a range).
  So B ≥ Σ over programs of the least such count over the ways it can be initialised.
- E: at least one exchange when any managed program differs after the system step;
  at least B / 62 (no message carries more than 62 bytes beyond its ID word); and at
  least the size of a maximum matching between programs and the field classes {P and V},
  Vr, T, F1, F2, over the fields a program differs in however it is initialised: two such
  writes of different programs and different classes need two messages (a 21h writes one
  program, a 40h..45h one field, a 32h/33h only P and V, an init only defaults).
Inits and ranges are counted only through E, so the bound is loose where they do the work
and tight where items do (a teach-in revert is priced exactly).
"""

from __future__ import annotations

import argparse
import json
import random
import tempfile
import time
from dataclasses import replace
from math import ceil
from pathlib import Path

from prc3cfg import codec
from prc3cfg.bustime import LineCost
from prc3cfg.image import DEFAULT_SYSTEM, PROGRAM_COUNT, ModuleImage, Program, default_program
from prc3cfg.line import LineSettings
from prc3cfg.planner import plan_module
from prc3cfg.planner.pricing import ADDRESS_ITEM_SIZE, FIELD_ITEM_SIZE, PARTS_ITEM_SIZE, PROGRAM_SIZE
from prc3cfg.planner.problem import A_BIT, FIELD_BIT, KEEP, PLAIN_FIELDS, PV_BITS, Problem

SYSTEM = replace(DEFAULT_SYSTEM, S1=2500, S2=120, S4=500, S5=20)
USED = 40  # programs a recipe uses; the rest are at their defaults (plant files with `reset`)
ID_WORD = 2


def recipe_program(rnd: random.Random, number: int, system=SYSTEM) -> Program:
    """A program as a coating recipe has it: position, speed, a dwell, a function output, chains of four."""
    return Program(
        P=rnd.randrange(300, system.S1, 5), V=rnd.randrange(max(system.S5, 50), system.S4, 10),
        Vr=0, T=rnd.choice([0, 0, 5, 10, 20]), F1=rnd.choice([0, 1010, 1050]), F2=rnd.choice([0, 0, 1050]),
        A=number + 1 if number % 4 else 0,
    )  # fmt: skip


def plant(rnd: random.Random, address: int = 1) -> ModuleImage:
    programs = [recipe_program(rnd, n) if n <= USED else default_program(SYSTEM) for n in range(1, PROGRAM_COUNT + 1)]
    return ModuleImage(address, SYSTEM, tuple(programs))


def changed(image: ModuleImage, changes: dict[int, Program | None], **system: int) -> ModuleImage:
    programs = list(image.programs)
    for number, program in changes.items():
        programs[number - 1] = program
    return replace(image, system=replace(image.system, **system), programs=tuple(programs))


# -- scenarios: (read-back, plant file) ---------------------------------------------------------


def recipe_tweak(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    actual = plant(rnd, address)
    p = actual.programs
    changes = {n: replace(p[n - 1], V=p[n - 1].V + 10) for n in rnd.sample(range(1, USED + 1), 3)}
    changes |= {n: replace(p[n - 1], T=p[n - 1].T + 5) for n in rnd.sample(range(1, USED + 1), 2)}
    return actual, changed(actual, changes)


def teach_in_revert(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    desired = plant(rnd, address)
    p = desired.programs
    taught = {
        n: replace(p[n - 1], P=p[n - 1].P + rnd.choice([-15, -5, 5, 15])) for n in rnd.sample(range(1, USED + 1), 12)
    }
    return changed(desired, taught), desired


def commissioning(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    return ModuleImage.factory(address), plant(rnd, address)


def lower_s1(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    actual = plant(rnd, address)
    s1 = 1200
    clamped = {n: replace(p, P=min(p.P, s1)) for n, p in enumerate(actual.programs, start=1)}
    high = [n for n, p in enumerate(actual.programs, start=1) if p.P > s1]
    clamped |= {n: replace(clamped[n], P=rnd.randrange(800, s1, 5)) for n in high[:3]}
    return actual, changed(actual, clamped, S1=s1)


def rechaining(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    actual = plant(rnd, address)
    p = actual.programs
    chains = {n: n + 1 if n < 8 else 1 for n in range(1, 9)}  # a loop 1 → … → 8 → 1
    chains |= {n: n + 1 if n < 16 else 0 for n in range(9, 17)}
    chains |= {n: n + 1 if n < USED else 0 for n in range(17, USED + 1)}
    return actual, changed(actual, {n: replace(p[n - 1], A=a) for n, a in chains.items()})


def cleanup(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    desired = plant(rnd, address)
    old = {n: recipe_program(rnd, n) for n in range(USED + 1, PROGRAM_COUNT + 1)}  # an old recipe's leftovers
    return changed(desired, old), desired


def factory_reset(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    return plant(rnd, address), ModuleImage.factory(address)


def large_mixed(rnd: random.Random, address: int = 1) -> tuple[ModuleImage, ModuleImage]:
    """Narrower speeds, a new recipe on 20 programs, dwell and outputs, a rechain, a cleanup, kept programs."""
    actual = plant(rnd, address)
    actual = changed(actual, {n: recipe_program(rnd, n) for n in range(50, PROGRAM_COUNT + 1)})
    system = replace(SYSTEM, S4=400, S5=40)
    programs = [replace(p, V=max(min(p.V, system.S4), system.S5)) for p in actual.programs]
    for n in rnd.sample(range(1, USED + 1), 20):
        programs[n - 1] = replace(programs[n - 1], P=rnd.randrange(300, system.S1, 5), V=rnd.randrange(50, 400, 10))
    for n in rnd.sample(range(1, USED + 1), 10):
        programs[n - 1] = replace(programs[n - 1], T=rnd.choice([0, 15, 30]), F1=rnd.choice([0, 1020]))
    for n in range(21, 31):
        programs[n - 1] = replace(programs[n - 1], A=n + 1 if n < 30 else 0)
    for n in range(50, PROGRAM_COUNT + 1):
        programs[n - 1] = default_program(system)
    for n in (45, 46, 47):  # kept by hand on the floor: unmanaged, not read
        programs[n - 1] = None
    actual = changed(actual, {45: None, 46: None, 47: None})
    return actual, replace(actual, system=system, programs=tuple(programs))


SCENARIOS = {
    "recipe tweak": recipe_tweak,
    "teach-in revert": teach_in_revert,
    "commissioning": commissioning,
    "lower S1, clamping": lower_s1,
    "rechaining": rechaining,
    "cleanup (reset)": cleanup,
    "factory reset": factory_reset,
    "large mixed change": large_mixed,
}


# -- the bound --------------------------------------------------------------------------------


def lower_bound(actual: ModuleImage, desired: ModuleImage, cost: LineCost) -> float:
    """A lower bound on the bus time of any plan (see the module docstring)."""
    problem = Problem.build(actual, desired, cost)
    plain = [FIELD_BIT[name] for name in PLAIN_FIELDS]

    def payload(i: int, mask: int) -> int:
        fields = (PARTS_ITEM_SIZE if mask & PV_BITS else 0) + FIELD_ITEM_SIZE * sum(1 for bit in plain if mask & bit)
        jump = desired.programs[i].A
        if mask & A_BIT and not (jump == 0 or (jump == i + 2 and problem.managed[jump - 1])):
            fields += ADDRESS_ITEM_SIZE  # no link or unlink range gives this jump
        return min(PROGRAM_SIZE - ID_WORD, fields)

    managed = [i for i in range(PROGRAM_COUNT) if problem.managed[i]]
    carried = sum(min(payload(i, problem.masks[kind][i]) for kind in problem.kinds) for i in managed)
    differs = any(problem.masks[KEEP][i] for i in managed)
    exchanges = max(int(differs), ceil(carried / (codec.MAX_MESSAGE_BYTES - ID_WORD)), separate_writes(problem))
    prices = problem.prices
    return problem.system_cost + exchanges * prices.message(ID_WORD) + carried * prices.byte


def separate_writes(problem: Problem) -> int:
    """How many writes no two of which one message can make (a maximum matching, see the docstring)."""
    classes = [PV_BITS] + [FIELD_BIT[name] for name in PLAIN_FIELDS]
    must = {}
    for i in range(PROGRAM_COUNT):
        if problem.managed[i]:
            mask = PV_BITS | sum(classes)
            for kind in problem.kinds:
                mask &= problem.masks[kind][i]
            must[i] = mask
    owner: dict[int, int] = {}  # program → the class it is matched with

    def augment(c: int, seen: set[int]) -> bool:
        for i, mask in must.items():
            if mask & classes[c] and i not in seen:
                seen.add(i)
                if i not in owner or augment(owner[i], seen):
                    owner[i] = c
                    return True
        return False

    return sum(augment(c, set()) for c in range(len(classes)))


# -- running ------------------------------------------------------------------------------------


def line_cost(framing: str) -> LineCost:
    return LineCost.of(framing, LineSettings(), 0.010, 0.020)


def scenarios_table(framings: list[str]) -> None:
    print(f"{'scenario':<20} {'framing':<12} {'plan ms':>9} {'naive ms':>9} {'bound ms':>9} "
          f"{'plan/bound':>10} {'msgs':>5} {'cpu ms':>7}")  # fmt: skip
    for framing in framings:
        cost = line_cost(framing)
        for name, make in SCENARIOS.items():
            actual, desired = make(random.Random(name))
            start = time.process_time()
            plan = plan_module(actual, desired, cost)
            cpu = time.process_time() - start
            bound = lower_bound(actual, desired, cost)
            ratio = plan.bus_time / bound if bound else 1.0
            print(f"{name:<20} {framing:<12} {plan.bus_time * 1e3:9.1f} {plan.naive_bus_time * 1e3:9.1f} "
                  f"{bound * 1e3:9.1f} {ratio:10.2f} {len(plan.steps):5d} {cpu * 1e3:7.1f}")  # fmt: skip


def plant_run(framing: str, modules: int, scenarios: list[str], label: str) -> None:
    """Plan a whole plant from saved images, as `prc3cfg plan --actual` does."""
    rnd = random.Random(f"plant-{label}-{modules}")
    makers = [SCENARIOS[name] for name in scenarios]
    cases = [makers[m % len(makers)](rnd, address=m % 30 + 1) for m in range(modules)]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "images.json"
        path.write_text(json.dumps([[a.to_json(), d.to_json()] for a, d in cases]))
        saved = [(ModuleImage.from_json(a), ModuleImage.from_json(d)) for a, d in json.loads(path.read_text())]
    cost = line_cost(framing)
    start = time.process_time()
    plans = [plan_module(actual, desired, cost) for actual, desired in saved]
    cpu = time.process_time() - start
    print(f"{label} plant, {modules} modules × {PROGRAM_COUNT} programs, {framing}: planning CPU {cpu * 1e3:.0f} ms, "
          f"bus time {sum(p.bus_time for p in plans):.2f} s (naive {sum(p.naive_bus_time for p in plans):.2f} s), "
          f"{sum(len(p.steps) for p in plans)} messages")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--framing", action="append", choices=["crc16", "open-driver", "stx"])
    parser.add_argument("--modules", type=int, default=30)
    args = parser.parse_args()
    framings = args.framing or ["crc16", "open-driver"]
    scenarios_table(framings)
    print()
    for framing in framings:
        plant_run(framing, args.modules, list(SCENARIOS), "mixed")
        plant_run(framing, args.modules, ["commissioning", "large mixed change"], "heavy")


if __name__ == "__main__":
    main()
