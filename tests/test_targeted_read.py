"""A targeted read-back (`prc3cfg.core.what_to_read`): plan and apply read only what the change from a
base touches — and end where a full read would, on the real emulator; what was not read is never
written, and Teach In on the floor is found where it was read, and left (and said) where it was not."""

from __future__ import annotations

import json
import random
import sys
from dataclasses import replace
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from emulated import emulated_plant, read_next, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from prc3cfg import api
from prc3cfg.api._plan import RECORD
from prc3cfg.core import what_to_read
from prc3cfg.core.device import can_clamp
from prc3cfg.core.image import PROGRAM_COUNT, ModuleImage
from prc3cfg.core.planner import plan_module
from prc3cfg.plant.importer import module_entry, plant_yaml
from prc3cfg.shell.testing import emulate

sys.path.insert(0, str(Path(__file__).resolve().parent / "planner"))
from planner_helpers import line
from test_planner_property import plant_file, read_back

# -- the core: what a change touches, and a plan that never writes what it did not read ------------


@st.composite
def changes(draw: st.DrawFn) -> tuple[ModuleImage, ModuleImage]:
    """A module as it holds the base, and the plant file's change of it (the planner property tests'
    scenarios)."""
    rnd = random.Random(draw(st.integers(0, 2**32)))
    actual = replace(read_back(rnd), address=1)
    return actual, plant_file(rnd, actual, draw(st.lists(st.integers(0, 6), max_size=4)))


NOW = datetime(2026, 11, 26, 12, 0, tzinfo=UTC)


def known(image: ModuleImage, hours: float = 1) -> what_to_read.Known:
    return what_to_read.Known(image, (NOW - timedelta(hours=hours)).isoformat(), "apply of a.yaml by ana@pc")


def test_what_to_read_from_the_lines_record_is_a_table():
    rnd = random.Random(3)
    held = replace(read_back(rnd), address=1)
    managed = tuple(n for n, p in enumerate(held.programs, 1) if p is not None)
    changed = held.with_programs({5: replace(held.known(5), P=held.known(5).P // 2 + 1),
                                  9: replace(held.known(9), T=7)})
    other_system = replace(held, system=replace(held.system, S6=1001 if held.system.S6 != 1001 else 1002))
    # (the record, the plant file) → (programs read besides the 50h, evidence kept, read in full because)
    cases = [
        (None, held, managed, False, "not on the line's record"),
        (known(held), held, (), True, None),  # untouched: its system block only
        (known(held), changed, (5, 9), True, None),
        (known(held), other_system, (), True, None),  # a system change: the read-back adds what it can clamp
        (known(held.with_programs({9: None})), held, (9,), True, None),  # a program the record does not know
        (known(held, hours=9), held, managed, False, "older than record_max_age (28800 s)"),
    ]
    for record, desired, programs, evidence, why in cases:
        decided = what_to_read.to_read(record, desired, NOW, 28_800)
        assert decided.programs == programs
        assert (decided.known is not None) == evidence
        assert (decided.why is None) if why is None else why in decided.why


def test_a_read_back_that_contradicts_the_record_drops_it_whole():
    rnd = random.Random(4)
    held = replace(read_back(rnd), address=1)
    # what a targeted read read: programs 1..9
    cut = held.with_programs({n: None for n in range(10, PROGRAM_COUNT + 1)})
    assert what_to_read.contradiction(held, cut) is None
    other_program = cut.with_programs({3: replace(held.known(3), T=held.known(3).T + 1)})
    assert what_to_read.contradiction(held, other_program) == "program 3 is not as on record"
    other_system = replace(cut, system=replace(cut.system, S7=cut.system.S7 + 1))
    assert what_to_read.contradiction(held, other_system) == "its system parameters are not those on record"
    record = known(held)
    kept = what_to_read.merged(record, cut, NOW.isoformat(), "plan of b.yaml by bo@pc")
    # the rest still rests on the old record
    assert kept.image == held and kept.since == record.since and kept.by == record.by
    whole = what_to_read.merged(record, held, NOW.isoformat(), "plan of b.yaml by bo@pc")
    assert whole.since == NOW.isoformat() and whole.by == "plan of b.yaml by bo@pc"  # every value read now
    dropped = what_to_read.merged(record, other_program, NOW.isoformat(), "read")
    assert dropped.image == other_program  # nothing of the contradicted record is kept
    written = what_to_read.verified(record, other_program, NOW.isoformat(), "apply of a.yaml by ana@pc")
    # what prc3cfg wrote is no contradiction
    assert written.image == held.with_programs({3: other_program.known(3)})
    assert written.since == record.since  # programs 10.. still rest on the record


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(changes(), st.sets(st.integers(1, PROGRAM_COUNT), max_size=20))
def test_a_plan_from_a_partial_read_writes_initialises_and_rewrites_no_program_it_did_not_read(change, read):
    actual, desired = change
    if can_clamp(actual.system, desired.system):
        # the read-back reads every program then (what_to_read.after_system)
        read = set(range(1, PROGRAM_COUNT + 1))
    cut = actual.with_programs({n: None for n in range(1, PROGRAM_COUNT + 1) if n not in read})
    plan = plan_module(cut, what_to_read.within_read(desired, cut), line())
    for step in plan.steps:  # an 11h/13h/14h across an unread program included
        assert set(step.message.touched_programs()) <= read, f"{step.summary} touches a program not read"
    for number in read:  # what was read reaches the plant file's value
        assert plan.predicted.program(number) == desired.program(number)


# -- across the emulator: a targeted apply ends where a full one does ------------------------------

BUS = {"name": "line", "framing": "crc16", "parity": "even", "timeout": 0.1}


def write_plant(path: Path, port: str, images: list[ModuleImage]) -> Path:
    path.write_text(plant_yaml("targeted",
                               [(BUS | {"port": port},
                                 [module_entry(image, f"m{image.address}") for image in images])]))
    return path


def test_equivalence_across_the_emulator(tmp_path):
    """One scenario of each kind, fast; `test_a_targeted_apply_ends_where_a_full_one_does` draws many."""
    for seed in range(3):
        rnd = random.Random(seed)
        actual = replace(read_back(rnd), address=1)
        targeted_equals_full(tmp_path / str(seed), actual,
                             plant_file(rnd, actual, [seed % 7, (seed * 3) % 7]))


@pytest.mark.soak
@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(changes())
def test_a_targeted_apply_ends_where_a_full_one_does(tmp_path_factory, change):
    targeted_equals_full(tmp_path_factory.mktemp("scenario"), *change)


def targeted_equals_full(directory: Path, actual: ModuleImage, desired: ModuleImage) -> None:
    """Modules holding the scenario's `actual` (module 1) and an untouched one (module 2), each read
    once so that the line's record knows them: the plant file applied targeted from that record,
    and again with a full read from the same start, end alike."""
    directory.mkdir(parents=True, exist_ok=True)
    other = replace(read_back(random.Random(actual.system.S3)), address=2)
    write_plant(directory / "source.yaml", "socket://127.0.0.1:1", [desired, other])
    ended = {}
    (directory / "run").mkdir()
    with emulate(directory / "source.yaml", directory / "run", timeout=0.1) as emulated:
        port = emulated.plant.buses[0].port
        plant = api.load(write_plant(emulated.path, port, [desired, other]))
        emulator = emulated.emulators["line"]
        for full in (False, True):
            emulator.update(1, image=actual)
            emulator.update(2, image=other)
            api.read(plant)  # the line's record: what the modules hold
            if not full:
                planned = api.plan(plant)
                reading = planned.reading
                # every module's system block is read
                assert reading is not None and reading.modules_not_read == ()
                managed = tuple(n for n, p in enumerate(other.programs, 1) if p is not None)
                rolled = {n for m in planned.modules if m.address == 2
                          for n, p in enumerate(m.actual.programs, 1) if p is not None}
                assert len(rolled) <= what_to_read.ROLLED_WINDOWS * 4  # rolling evidence, within its budget
                # the untouched module: its 50h
                assert reading.programs_not_read[("line", 2)] == tuple(n for n in managed if n not in rolled)
            result = api.apply(plant, gates=api.Gates(allow_axis_release=True), full_read=full)
            api.told(result)
            ended[full] = {a: s.image for a, s in emulator.modules().items()}
    assert ended[False] == ended[True]
    assert ended[False][1].system == desired.system and ended[False][1].programs == desired.programs


# -- Teach In: found where the change reads, left (and said) where it does not ---------------------


@pytest.fixture
def applied(tmp_path, capsys):
    """The demo plant applied in full on emulators: the lines' records know every module."""
    with emulated_plant(tmp_path) as plant:
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
        # one a line (and one more a spelling of it)
        assert len(list((tmp_path / "state" / "lines").glob("*.json"))) >= 2
        yield plant


def edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


def test_a_value_taught_in_a_program_the_change_touches_is_found_and_shown_never_silently_overwritten(
    applied, capsys, tmp_path
):
    left = applied.emulators["booth-a"]
    left.teach_in(1, 1, 1777)  # booth-a-left, program 1, on the floor
    edit(applied.path, "position: 2.1", "position: 2.0")  # the change touches program 1
    shown = run_cli(capsys, "plan", applied.path, "--module", "booth-a-left", "--out", tmp_path / "p.json")
    assert shown.code == 0, shown.err
    assert "program 1: position 1.777 m → 2.000 m" in shown.out  # what the module holds, as read
    # taught again after the plan was made: the reviewed plan is stale, nothing is written
    left.teach_in(1, 1, 1666)
    refused = run_cli(capsys, "apply", applied.path, "--plan", tmp_path / "p.json", "--auto-approve",
                      "--module", "booth-a-left")
    assert refused.code == 1 and "stale plan" in refused.err
    assert left.module(1).image.known(1).P == 1666


def test_a_value_taught_in_a_program_the_change_does_not_touch_is_left_and_the_plan_says_it_was_not_read(
    applied, capsys, tmp_path
):
    booth = applied.emulators["booth-a"]
    # rolling evidence reads other modules' programs in this plan
    assert read_next(applied.path)["booth-a-top"] == ()
    booth.teach_in(5, 2, 180)  # program 2 of booth-a-top: the change below does not touch it
    edit(applied.path, "position: 2.1", "position: 2.0")  # booth-a-left's program 1
    planned = run_cli(capsys, "plan", applied.path, "--out", tmp_path / "p.json")
    assert ("taken as known from the line's record" in planned.out
            and "plan --refresh-only (or --full-read) reads everything" in planned.out)
    document = json.loads((tmp_path / "p.json").read_text())
    assert document["read"]["base"] == RECORD
    assert all(said.startswith(f"apply of {applied.path} by ") for said in document["read"]["taken"].values())
    top = next(m for bus in document["buses"] for m in bus["modules"] if m["name"] == "booth-a-top")
    assert top["read"]["programs"] == [] and 2 in top["read"]["programs_not_read"]
    applied_ = run_cli(capsys, "apply", applied.path, "--plan", tmp_path / "p.json", "--auto-approve")
    assert applied_.code == 0, applied_.err
    # left as taught
    assert booth.module(5).image.known(2).P == 180 and booth.module(1).image.known(1).P == 2000
    full = run_cli(capsys, "plan", applied.path, "--full-read", "--module", "booth-a-top")
    assert "program 2: position 0.180 m → 0.150 m" in full.out  # one option away


def test_a_plan_file_whose_read_programs_are_edited_is_refused(applied, capsys, tmp_path):
    edit(applied.path, "position: 2.1", "position: 2.0")
    assert run_cli(capsys, "plan", applied.path, "--out", tmp_path / "p.json").code == 0
    document = json.loads((tmp_path / "p.json").read_text())
    document["buses"][0]["modules"][0]["read"]["programs"] = [1, 2]
    (tmp_path / "p.json").write_text(json.dumps(document))
    refused = run_cli(capsys, "apply", applied.path, "--plan", tmp_path / "p.json", "--auto-approve")
    assert refused.code == 1 and ("stale plan" in refused.err
                                  or "changed after it was made" in refused.err), refused.err


def test_a_module_whose_system_block_is_not_the_bases_is_read_in_full(applied, capsys, tmp_path):
    """A module changed by another tool since the last verified apply (or a spare fitted and set up
    by hand): its one 50h shows a system block other than the base's, so nothing of it is taken as
    last verified — every managed program is read and brought to the plant file."""
    booth = applied.emulators["booth-a"]
    held = booth.module(1).image  # booth-a-left, as last verified
    program_2 = replace(held.known(2), T=held.known(2).T + 3)
    other = replace(held, system=replace(held.system, S6=held.system.S6 + 1)).with_programs({2: program_2})
    # an acceleration that clamps nothing, and program 2, which the change below does not touch
    booth.update(1, image=other)
    edit(applied.path, "position: 2.1", "position: 2.0")  # the change touches program 1 only
    planned = run_cli(capsys, "plan", applied.path, "--module", "booth-a-left", "--out", tmp_path / "p.json")
    assert planned.code == 0, planned.err
    left = next(m for bus in json.loads((tmp_path / "p.json").read_text())["buses"] for m in bus["modules"]
                if m["name"] == "booth-a-left")
    module = next(m for _, m in api.load(applied.path).modules() if m.name == "booth-a-left")
    # rolled: all it held
    assert (set(left["read"]["programs"]) >= set(module.managed_programs())
            and left["read"]["programs_not_read"] == [])
    assert "read in full: booth-a/booth-a-left (its system parameters are not those on record)" in planned.out
    assert run_cli(capsys, "apply", applied.path, "--module", "booth-a-left", "--auto-approve",
                   "--allow-axis-release").code == 0
    held, wanted = booth.module(1).image, module.desired_image()
    assert held.system == wanted.system and all(held.program(n) == wanted.program(n)
                                                for n in module.managed_programs())
