"""Rolling evidence (issue 41, item 3): every targeted plan also reads in full the module of each line whose
record is the oldest (`what_to_read.rolling`), so a program another tool changed on a module whose system
block did not change is found within as many plans as its line has modules — not only once the record
outgrows `record_max_age`; and every plan names the oldest value it took from the record. On the real
emulator and client."""

from __future__ import annotations

import json
import random
from dataclasses import replace

import pytest
from emulated import emulated_plant, roll_order, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from prc3cfg import api
from prc3cfg.api._plan import record
from prc3cfg.core import what_to_read
from prc3cfg.core.image import ModuleImage
from prc3cfg.shell.testing import EmulatedPlant


def applied(plant: EmulatedPlant, capsys: pytest.CaptureFixture) -> None:
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0


def changed_by_another_tool(plant: EmulatedPlant, bus: str, address: int, number: int) -> None:
    """A program the plant file declares, changed as a teach-in on the floor would: the system block stays."""
    emulator = plant.emulators[bus]
    image = emulator.module(address).image
    emulator.update(address, image=image.with_programs({number: replace(image.known(number), T=image.known(number).T + 1)}))


def plan_document(plant: EmulatedPlant, capsys: pytest.CaptureFixture) -> dict:
    result = run_cli(capsys, "plan", plant.path, "--json")
    assert result.code == 0, result.err
    return json.loads(result.out)


def module_in(document: dict, name: str) -> dict:
    return next(m for bus in document["buses"] for m in bus["modules"] if m["name"] == name)


# -- which module rolls --------------------------------------------------------------------------


def known_at(since: str) -> what_to_read.Known:
    return what_to_read.Known(ModuleImage.factory(1).with_programs({n: None for n in range(3, 65)}), since, "apply of /p/a.yaml by ana@pc")


def target(bus: str, address: int, programs: tuple[int, ...] = (), managed: tuple[int, ...] = (1, 2, 3)) -> what_to_read.Target:
    return what_to_read.Target(bus, address, f"m{address}", programs, None, known_at("2026-11-28T01:00:00+00:00").image, managed)


def test_the_oldest_record_of_each_line_rolls_table():
    """(targets, record) → the modules rolled: per line the oldest record, ties by address; a module read in
    full already (not on record, or every program it holds and the plant file manages read) never rolls."""
    t1, t2, t3 = "2026-11-28T01:00:00+00:00", "2026-11-28T02:00:00+00:00", "2026-11-28T03:00:00+00:00"
    cases = [  # (targets, {key: since}) → rolled keys
        (([target("a", 1), target("a", 2), target("a", 3)], {("a", 1): t2, ("a", 2): t1, ("a", 3): t3}), {("a", 2)}),
        (([target("a", 1), target("a", 2)], {("a", 1): t1, ("a", 2): t1}), {("a", 1)}),  # a tie: the lower address
        (([target("a", 1), target("b", 2), target("b", 3)], {("a", 1): t3, ("b", 2): t2, ("b", 3): t1}), {("a", 1), ("b", 3)}),
        (([target("a", 1, (1, 2, 3)), target("a", 2)], {("a", 1): t1, ("a", 2): t2}), {("a", 2)}),  # 1 is read in full anyway
        (([replace(target("a", 1), known=None), target("a", 2)], {("a", 2): t3}), {("a", 2)}),  # 1 is not on record
        (([target("a", 1, (1, 2, 3))], {("a", 1): t1}), set()),  # nothing left to roll
    ]
    for (targets, sinces), rolled in cases:
        known = {key: known_at(since) for key, since in sinces.items()}
        said = what_to_read.rolling(targets, known)
        assert set(said) == rolled, (targets, sinces)
        for key in rolled:
            assert said[key] == f"rolling evidence: the oldest record of its line, since {what_to_read.to_the_minute(sinces[key])}"
    # a rolled module reads every program the plant file manages and the record holds, with the record to agree with
    widened = what_to_read.rolled(target("a", 1, (2,), (2, 5)), known_at(t1))
    assert widened.programs == (1, 2, 5) and widened.known == known_at(t1).image


# -- what rolling finds ---------------------------------------------------------------------------


def test_a_program_another_tool_changed_is_found_within_as_many_plans_as_its_line_has_modules(plant, capsys, tmp_path):
    """The issue's limit: after an apply, another tool changes a program the plant file declares on a module
    whose system block stays, and the plant file changes something else (another line's module): main said
    "No changes" for it until the record expired. Rolling finds it within 3 plans (booth-b has 3 modules) —
    the module whose record is the newest, so the last to roll — and the apply writes it back."""
    applied(plant, capsys)
    name = roll_order(plant.path, "booth-b")[-1]
    address = next(m.address for _, m in api.load(plant.path).modules() if m.name == name)
    changed_by_another_tool(plant, "booth-b", address, 1)
    text = plant.path.read_text()
    plant.path.write_text(text.replace("1: {position: 1.750}", "1: {position: 1.700}", 1))  # booth-a-top's program 1
    found = None
    for n in range(1, 4):
        document = plan_document(plant, capsys)
        if module_in(document, name)["steps"]:
            found = n
            break
    assert found is not None, "not found within the 3 plans the line's 3 modules bound it to"
    assert found == 3  # the newest record rolls last: the bound is reached, and not exceeded
    said = document["read"]["not_as_verified"]
    assert f"booth-b/{name} (program 1 is not as on record)" in said, said  # the rolled read is evidence: the line opens
    assert all(m["read"]["programs_not_read"] == [] for m in document["buses"][1]["modules"])
    done = run_cli(capsys, "apply", plant.path, "--auto-approve")
    assert done.code == 0, done.err
    assert plant.matches_plant()


def test_a_plan_file_with_a_rolled_module_is_proved_by_reading_the_same_programs(plant, capsys, tmp_path):
    """`apply --plan` reads again exactly what its plan read: the rolled module in full, the rest as the plan did."""
    applied(plant, capsys)
    name = roll_order(plant.path, "booth-a")[0]
    text = plant.path.read_text()
    plant.path.write_text(text.replace("1: {position: 1.750}", "1: {position: 1.700}", 1))
    saved = tmp_path / "plan.json"
    planned = run_cli(capsys, "plan", plant.path, "--out", saved)
    assert planned.code == 0, planned.err
    assert "rolling evidence: the oldest record of its line, since " in planned.out
    document = json.loads(saved.read_text())
    wanted = {m.name: m for _, m in api.load(plant.path).modules()}
    read = module_in(document, name)["read"]  # every program managed, and every one the record holds
    assert set(read["programs"]) >= set(wanted[name].managed_programs()) and read["programs_not_read"] == []
    done = run_cli(capsys, "apply", plant.path, "--plan", saved, "--auto-approve")
    assert done.code == 0, done.err
    assert plant.matches_plant()


def test_full_read_and_actual_roll_nothing(plant, capsys, tmp_path):
    applied(plant, capsys)
    full = run_cli(capsys, "plan", plant.path, "--full-read")
    assert full.code == 0 and "rolling evidence" not in full.out


# -- the oldest evidence relied on, in every medium -------------------------------------------------


def oldest_words(plant: EmulatedPlant, whose: bool = True) -> str:
    """The oldest value the next plan takes from the record, in its words: of the modules whose programs it
    takes (not the module each line rolls, read now), the one with the oldest record."""
    plant_ = api.load(plant.path)
    known = record(plant_, plant_.buses)
    names = {(b.name, m.address): m.name for b, m in plant_.modules()}
    rolled = {roll_order(plant.path, bus)[0] for bus in ("booth-a", "booth-b")}
    bus, address = min((key for key in known if names[key] not in rolled), key=lambda key: (known[key].since, key))
    name = names[(bus, address)]
    by = f" as {known[(bus, address)].by} read or verified them" if whose else ""
    return f"oldest value taken from the record: {bus}/{name}'s programs,{by} since {what_to_read.to_the_minute(known[(bus, address)].since)}"


def test_every_medium_names_the_oldest_value_taken_from_the_record(plant, capsys, tmp_path):
    """Neither the rolled modules (read now) nor any module read in full is the oldest evidence: of the modules
    whose programs were taken from the record, the one with the oldest record — named with since when and by whom."""
    applied(plant, capsys)
    saved = tmp_path / "plan.json"
    words = oldest_words(plant)
    human = run_cli(capsys, "plan", plant.path, "--out", saved)
    assert human.code == 0, human.err
    headline = next(line for line in human.out.splitlines() if line.startswith("No changes"))
    assert words in headline, headline
    module = words.split(": ")[1].split("'s ")[0]
    assert json.loads(saved.read_text())["evidence"]["oldest"]["module"] == module
    shown = run_cli(capsys, "show", saved)
    assert shown.code == 0 and words in shown.out
    words = oldest_words(plant, whose=False)  # markdown escapes the path and user of `by`: the rest as said
    markdown = run_cli(capsys, "plan", plant.path, "--markdown")
    assert markdown.code == 0 and words.split(",")[0] in markdown.out and words.split(",")[1] in markdown.out, markdown.out
    words = oldest_words(plant)
    document = json.loads(run_cli(capsys, "plan", plant.path, "--json").out)
    assert document["evidence"]["oldest"]["module"] == words.split(": ")[1].split("'s ")[0]
    # a plan that changes something names it in its notes: the headline is the change's then
    plant.path.write_text(plant.path.read_text().replace("1: {position: 1.750}", "1: {position: 1.700}", 1))
    words = oldest_words(plant, whose=False)
    changed = run_cli(capsys, "plan", plant.path)
    assert changed.code == 0 and words in next(line for line in changed.out.splitlines() if line.startswith("Read now:"))


# -- soak: the bound --------------------------------------------------------------------------------

#: The modules the plant file declares on each line, with the programs it declares of each.
DECLARED = {"booth-a": {1: (1, 2, 3), 2: (1, 2, 3), 5: (1, 2, 3, 10, 11)}, "booth-b": {1: (1, 2, 3), 3: (1, 2, 3, 4), 4: (1, 2)}}


@pytest.mark.soak
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1))
def test_any_program_another_tool_changes_is_found_within_the_bound(tmp_path_factory, seed):
    """Seeded: after an apply and 0–4 plans (the roll anywhere in its turn), another tool changes one program
    the plant file declares on one module (system block unchanged); a plan finds it within as many plans as
    its line has modules, and one apply after that leaves every module as the plant file says."""
    rnd = random.Random(seed)
    with emulated_plant(tmp_path_factory.mktemp("scenario")) as plant:
        api.told(api.apply(plant.plant, gates=api.Gates(allow_axis_release=True)))
        for _ in range(rnd.randint(0, 4)):
            api.plan(api.load(plant.path))
        bus = rnd.choice(sorted(DECLARED))
        address = rnd.choice(sorted(DECLARED[bus]))
        changed_by_another_tool(plant, bus, address, rnd.choice(DECLARED[bus][address]))
        for _ in range(len(DECLARED[bus])):
            planned = api.plan(api.load(plant.path))
            if any(m.steps for m in planned.modules if (m.bus, m.address) == (bus, address)):
                break
        else:
            pytest.fail(f"seed {seed}: {bus}/{address} not found within {len(DECLARED[bus])} plans")
        api.told(api.apply(api.load(plant.path), gates=api.Gates(allow_axis_release=True)))
        assert plant.matches_plant(), seed
