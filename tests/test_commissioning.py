"""Commissioning (issue 41, item 4): a module whose 50h reads the factory system parameters, where the plant
file wants others, is planned from the factory programs for the programs the plant file manages — not read
before writing — and every one of them is read back after the writes (`what_to_read.factory_fresh`); nothing
the plant file leaves unmanaged is changed without having been read. On the real emulator and client: what
another tool changed on a factory-fresh module ends as the plant file says where it manages it, and byte for
byte as it was where it does not."""

from __future__ import annotations

import json
import random
from dataclasses import replace
from pathlib import Path

import pytest
from emulated import emulated_plant, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from prc3cfg import api
from prc3cfg.core import codec, render, what_to_read
from prc3cfg.core.image import DEFAULT_SYSTEM, PROGRAM_NUMBERS, ModuleImage, Program
from prc3cfg.core.plan_file import evidence
from prc3cfg.core.plant_plan import PlantPlan

MODULE = """\
      - address: {address}
        name: m{address}
        unmanaged_programs: {unmanaged}
        system: {{upper_reversing_point: 2.000{clamping}}}
        programs:
          1: {{position: 1.500, speed: 0.300, dwell: 0.5}}
          2: {{position: 0.300, speed: 0.300, relative_speed: 0.020}}
          7: {{position: 0.150, speed: 0.050}}
        chains: [[1, 2]]
"""
PLANT = """\
plant: commissioning
buses:
  - name: line
    port: emulator://line
    framing: crc16
    modules:
{modules}"""
MANAGED = (1, 2, 7)
#: What another tool writes: a program any of the plant's system parameters leave as it is (no clamping).
OTHER = Program(P=300, V=300, T=20)


def plant_file(directory: Path, unmanaged: dict[int, str], clamping: bool = True) -> Path:
    """Modules 1.. with `unmanaged_programs` as given; `clamping`: the plant's system parameters can clamp
    programs (a lower max_speed than the factory's), else they only raise the upper reversing point."""
    system = ", max_speed: 0.500" if clamping else ""
    modules = "".join(MODULE.format(address=a, unmanaged=u, clamping=system) for a, u in unmanaged.items())
    path = directory / "source.yaml"
    path.write_text(PLANT.format(modules=modules))
    return path


def read_before_writing(journal: Path) -> dict[int, set[int]]:
    """By module address: the programs the apply read before its first write."""
    read: dict[int, set[int]] = {}
    for record in map(json.loads, journal.read_text().splitlines()):
        if record["event"] != "exchange":
            continue
        message = codec.decode_message(bytes.fromhex(record["request"]))
        if not message.IS_READ:
            break
        read.setdefault(record["address"], set()).update(message.programs
                                                         if isinstance(message, codec.ReadProgram) else
                                                         range(message.first, message.last + 1)
                                                         if isinstance(message, codec.ReadPrograms) else ())
    return read


def test_the_factory_programs_the_plant_file_will_write_are_planned_not_read():
    """The rule, pure: a factory-fresh 50h where the plant file wants other system parameters reads no managed
    program; the unmanaged ones only where the plant's system parameters can clamp them; a record that says
    otherwise, or a plant file that wants the factory's system parameters, reads as before."""
    plant_system = replace(DEFAULT_SYSTEM, S1=2000, S4=500)  # a lower max_speed than the factory's: can clamp
    quiet = replace(DEFAULT_SYSTEM, S1=2000)  # a higher upper reversing point: clamps nothing
    unmanaged = set(PROGRAM_NUMBERS) - set(MANAGED)
    factory = ModuleImage.factory(1)
    cases = [  # (50h, plant system, record) → programs read
        (DEFAULT_SYSTEM, plant_system, None, unmanaged),
        (DEFAULT_SYSTEM, quiet, None, set()),
        # nothing says fresh: the plant wants the factory's
        (DEFAULT_SYSTEM, DEFAULT_SYSTEM, None, set(MANAGED)),
        (plant_system, quiet, None, set(MANAGED)),  # not factory-fresh: as before
        # the record says otherwise: read in full
        (DEFAULT_SYSTEM, quiet, replace(factory, system=quiet), set(MANAGED)),
    ]
    for system, wanted, known, read in cases:
        assert what_to_read.after_system(system, MANAGED, wanted, known, MANAGED,
                                         fresh=True) == read, (system, wanted)
        # not an apply: every managed one
        assert what_to_read.after_system(system, MANAGED, wanted, known, MANAGED) >= set(MANAGED)


@pytest.mark.parametrize("clamping", [True, False])
def test_a_factory_fresh_line_is_commissioned_unread_where_it_writes_and_keeps_what_it_does_not_manage(
    tmp_path, capsys, clamping
):
    """Three factory-fresh modules (system block as the factory left it): m1 untouched; on m2 another tool
    changed programs the plant file does not manage (keep); on m3 it changed managed ones — program 7, which
    the plant file wants as the factory's (no write planned for it), and a field of program 2 the plan's
    writes may not cover. The apply reads no managed program before writing, ends verified with every managed
    program as the plant file says (m3 through the repair round, said in the account), m2's unmanaged programs
    byte for byte as the other tool left them, and says which programs it did not read."""
    source = plant_file(tmp_path, {1: "keep", 2: "keep", 3: "keep"}, clamping)
    with emulated_plant(tmp_path, source=source) as plant:
        emulator = plant.emulators["line"]
        m2 = emulator.module(2).image
        emulator.update(2, image=m2.with_programs({20: OTHER, 33: replace(OTHER, T=30)}))
        m3 = emulator.module(3).image
        emulator.update(3, image=m3.with_programs({7: OTHER, 2: replace(m3.known(2), Vr=7)}))
        kept = {n: emulator.module(2).image.program(n) for n in PROGRAM_NUMBERS if n not in MANAGED}

        done = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert done.code == 0, done.out + done.err
        assert plant.matches_plant()
        assert {n: emulator.module(2).image.program(n) for n in kept} == kept  # byte for byte
        assert "repair round" in done.out.split("✓ bus line, module 3 (m3): ")[1].splitlines()[0]
        assert "planned as the factory's, not read before writing" in done.out
        assert "every module matches" not in done.out
        (journal,) = (plant.path.parent / ".prc3cfg" / "journal").iterdir()
        for address, programs in read_before_writing(journal).items():
            assert not programs & set(MANAGED), (address, programs)
            assert programs == (set(PROGRAM_NUMBERS) - set(MANAGED) if clamping else set()), address
        # the snapshot undoes the commissioning: the factory's where it planned from them, what it read
        # elsewhere
        (snapshot,) = (plant.path.parent / ".prc3cfg" / "snapshots").iterdir()
        api.told(api.restore(snapshot, gates=api.Gates(allow_axis_release=True)))
        assert emulator.module(1).image == ModuleImage.factory(1)
        assert {n: emulator.module(2).image.program(n) for n in kept} == kept


@pytest.mark.parametrize("approved", [False, True], ids=["by line", "whole plan approved"])
def test_a_reset_plant_file_reads_only_the_system_blocks_and_verifies_every_program(tmp_path, approved):
    """`unmanaged_programs: reset`: every program managed — the apply reads one 50h per module before
    writing; another tool's programs on a factory-fresh module end at the factory's defaults, found by the
    verification that reads every program planned from the factory image. The plan a person approves says
    what it did not read."""
    source = plant_file(tmp_path, {1: "reset", 2: "reset"})
    shown: list[PlantPlan] = []
    gates = (api.Gates(allow_axis_release=True, approve=lambda the_plan: not shown.append(the_plan))
             if approved else \
        api.Gates(allow_axis_release=True))
    with emulated_plant(tmp_path, source=source) as plant:
        emulator = plant.emulators["line"]
        emulator.update(2, image=emulator.module(2).image.with_programs({40: OTHER, 64: OTHER}))
        result = api.apply(plant.plant, gates=gates)
        api.told(result)
        assert result.verified and plant.matches_plant()
        assert len(shown) == approved
        for the_plan in [result.plan, *shown]:
            assert evidence(the_plan)["from_factory"] == {"modules": 2, "programs": 128}
            assert not evidence(the_plan)["complete"] and evidence(the_plan)["read_now"]["programs"] == 0
        assert read_before_writing(result.journal) == {1: set(), 2: set()}
        assert emulator.module(2).image.programs == ModuleImage.factory(2).with_programs(
            {n: p for n, p in enumerate(plant.plant.buses[0].modules[1].desired_image().programs, 1)
             if p is not None}).programs


@pytest.mark.soak
@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1))
def test_whatever_another_tool_wrote_on_factory_fresh_modules_commissioning_ends_at_the_plant_file(
    tmp_path_factory, seed
):
    """Seeded: on factory-fresh modules (keep or reset, a system change that clamps or not) another tool
    changed some programs, managed or not, leaving the system block; the apply ends with every managed
    program as the plant file says, every unmanaged one byte for byte as it was, and no headline that
    claims what was not read."""
    rnd = random.Random(seed)
    directory = tmp_path_factory.mktemp("commissioning")
    modules = {a: rnd.choice(["keep", "reset"]) for a in range(1, rnd.randint(2, 4) + 1)}
    source = plant_file(directory, modules, clamping=rnd.random() < 0.5)
    with emulated_plant(directory, source=source) as plant:
        emulator = plant.emulators["line"]
        for address in modules:
            image = emulator.module(address).image
            changed = rnd.sample(PROGRAM_NUMBERS, rnd.randint(0, 4))
            emulator.update(address, image=image.with_programs({n: replace(OTHER, T=rnd.randint(0, 90))
                                                                for n in changed}))
        before = {a: emulator.module(a).image for a in modules}
        # a plan first: the line's record then holds what it read, the other tool's programs too
        if rnd.random() < 0.3:
            api.plan(plant.plant)
        result = api.apply(plant.plant, gates=api.Gates(allow_axis_release=True))
        api.told(result)
        assert result.verified and plant.matches_plant(), seed
        assert not claims_what_was_not_read(result.plan), seed
        shown = render.human(result.plan)
        assert render.EVERY_MODULE not in shown, seed
        assert ("Not read before writing" in shown) == any(change.assumed
                                                           for change in result.plan.modules), seed
        for _, module in plant.plant.modules():
            desired, held = module.desired_image(), emulator.module(module.address).image
            for number, (want, have, was) in enumerate(zip(desired.programs, held.programs,
                                                           before[module.address].programs), 1):
                assert have == (was if want is None else want), (seed, module.address, number)


def claims_what_was_not_read(the_plan: PlantPlan) -> bool:
    """Whether the plan's evidence says every value it covers was read, where it planned programs from the
    factory image."""
    return any(change.assumed for change in the_plan.modules) and evidence(the_plan)["complete"]
