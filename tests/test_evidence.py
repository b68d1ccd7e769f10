"""What a plan's word rests on (issue 41): a headline names its evidence in every medium — what was read
now, what was taken from the line's record and since when — and says "every module matches" only when
every value it covers was read in that run; and one module that reads other than the line's record says
opens the whole line: every module of it is read in full in that run, and the plan says why. On the real
emulator and client."""

from __future__ import annotations

import json
import random
from dataclasses import replace
from pathlib import Path

import pytest
from emulated import emulated_plant, read_next, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from prc3cfg import api
from prc3cfg.core import what_to_read
from prc3cfg.core.image import PROGRAM_COUNT, ModuleImage
from prc3cfg.shell.testing import EmulatedPlant

EVERY_MODULE = "No changes: every module matches the plant file."


def applied(plant: EmulatedPlant, capsys: pytest.CaptureFixture) -> None:
    """The plant applied in full: the lines' records know every module."""
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0


def managed_count(plant: EmulatedPlant) -> int:
    return sum(len(m.managed_programs()) for _, m in api.load(plant.path).modules())


def taken(plant: EmulatedPlant) -> tuple[int, int]:
    """The modules, and the managed programs, the next plan of the unchanged plant takes from the record: all
    but those rolling evidence reads."""
    read = read_next(plant.path)
    left = [set(m.managed_programs()) - set(read[m.name]) for _, m in api.load(plant.path).modules()]
    return sum(1 for programs in left if programs), sum(map(len, left))


# -- 1. headlines name their evidence ------------------------------------------------------------


def test_no_changes_names_its_evidence_in_every_medium_until_everything_is_read(plant, capsys, tmp_path):
    applied(plant, capsys)
    programs, expected = managed_count(plant), [taken(plant)]
    human = run_cli(capsys, "plan", plant.path, "--detailed-exitcode", "--out", tmp_path / "plan.json")
    assert human.code == 0, human.err  # scripts rely on it: no changes is 0, however much was read
    headline = next(line for line in human.out.splitlines() if line.startswith("No changes"))
    assert EVERY_MODULE not in human.out
    # and the rolled modules' programs
    assert headline.startswith("No changes to what was read now (the system blocks of 6 modules and ")
    assert (f" programs) or to what prc3cfg last read or verified ({expected[0][1]} programs of "
            f"{expected[0][0]} modules; "
            "oldest value taken from the record: " in headline
            and f"'s programs, as apply of {plant.path} by ") in headline
    assert headline.endswith(" UTC).")
    markdown = run_cli(capsys, "plan", plant.path, "--markdown")
    assert (markdown.code == 0 and EVERY_MODULE not in markdown.out
            and "No changes to what was read now" in markdown.out)
    expected.append(taken(plant))
    for document, (modules, from_record) in ((json.loads(run_cli(capsys, "plan", plant.path, "--json").out),
                                              expected[1]),
                                          (json.loads((tmp_path / "plan.json").read_text()), expected[0])):
        evidence = document["evidence"]
        assert evidence["complete"] is False
        # 8 windows of 4 a line, rolled
        assert evidence["read_now"]["system_blocks"] == 6 and evidence["read_now"]["programs"] == 64
        assert evidence["from_record"] == {"modules": modules, "programs": from_record}
        # the apply's, or a plan's that rolled the module
        assert f" of {plant.path} by " in evidence["oldest"]["by"]
        assert evidence["oldest"]["since"].endswith("+00:00")
    shown = run_cli(capsys, "show", tmp_path / "plan.json")
    assert (shown.code == 0 and "No changes to what was read now" in shown.out
            and EVERY_MODULE not in shown.out)
    # apply's own words claim no more than its plan
    again = run_cli(capsys, "apply", plant.path, "--auto-approve")
    assert (again.code == 0 and "every module matches" not in again.out
            and "Nothing to do: nothing was written" in again.out)
    # read in full: the headline may say every module now, and the JSON says so too
    full = run_cli(capsys, "plan", plant.path, "--full-read", "--detailed-exitcode")
    assert full.code == 0 and EVERY_MODULE in full.out
    document = json.loads(run_cli(capsys, "plan", plant.path, "--full-read", "--json").out)
    assert document["evidence"] == {"complete": True, "read_now": {"system_blocks": 6, "programs": programs},
                                    "from_record": {"modules": 0, "programs": 0}, "oldest": None}


def test_a_plan_files_evidence_is_proved_by_the_apply_and_one_without_is_shown_as_saying_nothing_and_refused(
    plant, capsys, tmp_path
):
    applied(plant, capsys)
    saved = tmp_path / "plan.json"
    assert run_cli(capsys, "plan", plant.path, "--out", saved).code == 0
    document = json.loads(saved.read_text())
    document["evidence"]["complete"] = True  # a file that claims every value was read
    saved.write_text(json.dumps(document))
    refused = run_cli(capsys, "apply", plant.path, "--plan", saved, "--auto-approve")
    assert (refused.code == 1
            and "evidence.complete is not what prc3cfg wrote for this plan" in refused.err), refused.err
    del document["evidence"]  # a plan file from before plans named their evidence
    saved.write_text(json.dumps(document))
    shown = run_cli(capsys, "show", saved)
    assert (shown.code == 0 and "No changes (the plan file does not say what was read" in shown.out
            and EVERY_MODULE not in shown.out)
    refused = run_cli(capsys, "apply", plant.path, "--plan", saved, "--auto-approve")
    assert (refused.code == 1
            and 'it does not say what its plan rests on (no "evidence")' in refused.err), refused.err


def test_the_recipes_replan_reads_in_full():
    """The job that plans main's plant file against the modules now takes nothing from the record."""
    recipe = (Path(__file__).resolve().parents[1] / "docs" / "ci.md").read_text()
    job = recipe[recipe.index("  replan:"):recipe.index("  apply:", recipe.index("  replan:"))]
    plan = next(line for line in job.splitlines() if "/bin/prc3cfg\" plan" in line)
    assert "--full-read" in plan


# -- 2. a contradiction opens the line -------------------------------------------------------------


def test_the_line_opens_on_a_module_that_contradicts_its_record_table():
    """(what each module of a line read, against its record) → why the line is read in full (None: it is
    not)."""
    held = ModuleImage.factory(1).with_programs({1: replace(ModuleImage.factory(1).known(1), P=2000)})
    cut = held.with_programs({n: None for n in range(2, PROGRAM_COUNT + 1)})
    other = cut.with_programs({1: replace(held.known(1), P=2100)})
    moved = replace(cut, system=replace(cut.system, S6=cut.system.S6 + 1))
    def target(known: ModuleImage | None, address: int = 1) -> what_to_read.Target:
        return what_to_read.Target("line", address, f"m{address}", (1,), None, known, (1, 2, 3))
    cases = [  # (target, read) → why
        ((target(held), cut), None),  # as on record
        ((target(None), other), None),  # not on the record: read in full already, nothing to contradict
        ((target(held), other), "line/m1: program 1 is not as on record"),
        ((target(held), moved), "line/m1: its system parameters are not those on record"),
    ]
    for (t, image), why in cases:
        assert what_to_read.opens_line(t, image) == why
    # a module read before the line opened: the managed programs it did not read yet; read in full: none
    assert what_to_read.still_to_read(target(held), cut) == frozenset({2, 3})
    assert what_to_read.still_to_read(target(held), held) == frozenset()
    assert what_to_read.opened(target(held)) == replace(target(held), programs=(1, 2, 3), known=None)


def swap(plant: EmulatedPlant, bus: str, a: int, b: int) -> None:
    """Two controllers of a line swapped: each holds the other's programs, with the same system block."""
    emulator = plant.emulators[bus]
    first, second = emulator.module(a).image, emulator.module(b).image
    assert first.system == second.system and first.programs != second.programs
    emulator.update(a, image=replace(first, programs=second.programs))
    emulator.update(b, image=replace(second, programs=first.programs))


def edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


@pytest.mark.parametrize("change", [
    # booth-a-left's program 1: the first module read contradicts its record
    ("position: 2.1\n", "position: 2.05\n"),
    # booth-a-right's: the second — the first, read already, is read again
    ("position: 2.0\n", "position: 1.95\n"),
])
def test_two_swapped_controllers_open_their_line_and_both_are_written_back(plant, capsys, tmp_path, change):
    """The issue's case on a 3-module line: the change reads program 1 of one swapped module, which is not
    as on record — every module of the line is read in full, and the apply writes both back."""
    applied(plant, capsys)
    swap(plant, "booth-a", 1, 2)
    edit(plant.path, *change)
    rolled = read_next(plant.path)  # what rolling evidence reads of the other line
    planned = run_cli(capsys, "plan", plant.path, "--out", tmp_path / "plan.json")
    assert planned.code == 0, planned.err
    modules = {m["name"]: m for bus in json.loads((tmp_path / "plan.json").read_text())["buses"]
               for m in bus["modules"]}
    wanted = {m.name: m for _, m in api.load(plant.path).modules()}
    # the whole line, read in full (a rolled one: all its record held)
    for name in ("booth-a-left", "booth-a-right", "booth-a-top"):
        assert set(modules[name]["read"]["programs"]) >= set(wanted[name].managed_programs()), name
        assert modules[name]["read"]["programs_not_read"] == [], name
    # the other line: as its record says, and rolling
    for name in ("booth-b-left", "booth-b-right", "booth-b-pretreat"):
        assert modules[name]["read"]["programs"] == list(rolled[name]), name
    assert ("booth-a/booth-a-left (program 1 is not as on record), booth-a/booth-a-right (program 1 is not "
            "as on record), booth-a/booth-a-top (booth-a/booth-a-left on its line: program 1 is not as on "
            "record)" in planned.out)
    done = run_cli(capsys, "apply", plant.path, "--plan", tmp_path / "plan.json", "--auto-approve")
    assert done.code == 0, done.err
    assert plant.matches_plant()  # both swapped modules written back: the module 2 stayed wrong


#: The plant file's change of program 1 of each module of booth-a.
PROGRAM_1 = {1: ("position: 2.1\n", "position: 2.05\n"), 2: ("position: 2.0\n", "position: 1.95\n"),
             5: ("position: 1.75\n", "position: 1.7\n")}


@pytest.mark.soak
@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1))
def test_whatever_another_hand_changed_on_a_line_an_apply_that_reads_one_of_it_ends_at_the_plant_file(
    tmp_path_factory, seed
):
    """Seeded: after an apply, another tool changes programs of modules of a line (a swap, a program
    rewritten, a module put back to factory programs), and the plant file changes program 1 of one module
    whose program 1 the other tool changed; the apply that follows ends with every module of the line as the
    plant file says — whichever module, first or last, contradicts its record."""
    rnd = random.Random(seed)
    directory = tmp_path_factory.mktemp("scenario")
    with emulated_plant(directory) as plant:
        api.told(api.apply(plant.plant, gates=api.Gates(allow_axis_release=True)))
        emulator = plant.emulators["booth-a"]
        addresses = sorted(emulator.modules())
        before = {a: s.image for a, s in emulator.modules().items()}
        for _ in range(rnd.randint(1, 3)):
            kind, address = rnd.choice(["swap", "rewrite", "factory"]), rnd.choice(addresses)
            image = emulator.module(address).image
            if kind == "swap":
                other = rnd.choice([a for a in addresses if a != address])
                there = emulator.module(other).image
                emulator.update(address, image=replace(image, programs=there.programs))
                emulator.update(other, image=replace(there, programs=image.programs))
            elif kind == "rewrite":
                number = rnd.choice([1, 2, 3])
                emulator.update(address, image=image.with_programs({number: replace(image.known(number),
                                                                                    T=image.known(number).T
                                                                                    + 1)}))
            else:
                emulator.update(address, image=replace(image, programs=ModuleImage.factory(address).programs))
        changed = [a for a in addresses if emulator.module(a).image.program(1) != before[a].program(1)]
        # the change below must read something another hand changed: else it is the stated limit
        if not changed:
            address = rnd.choice(addresses)
            image = emulator.module(address).image
            emulator.update(address, image=image.with_programs({1: replace(image.known(1),
                                                                           T=image.known(1).T + 1)}))
            changed = [address]
        edit(plant.path, *PROGRAM_1[rnd.choice(changed)])
        result = api.apply(api.load(plant.path), gates=api.Gates(allow_axis_release=True))
        api.told(result)
        assert result.verified
        assert plant.matches_plant(), seed
