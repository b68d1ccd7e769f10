"""Rolling evidence (issue 41, item 3): every targeted plan also reads, per line, the eight windows of four
programs whose values on record are the oldest (`what_to_read.rolling`), so a program another tool changed on
a module whose system block did not change is found within ⌈W / 8⌉ plans (W: the line's windows) — not only
once the record outgrows `record_max_age`; and every plan names the oldest value it took from the record.
On the real emulator and client."""

from __future__ import annotations

import json
import os
import random
from dataclasses import replace
from pathlib import Path

import pytest
from emulated import emulated_plant, read_next, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from prc3cfg import api
from prc3cfg.api._plan import as_it_stands, record
from prc3cfg.core import what_to_read
from prc3cfg.core.image import ModuleImage
from prc3cfg.shell.testing import EmulatedPlant


def applied(plant: EmulatedPlant, capsys: pytest.CaptureFixture) -> None:
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0


def changed_by_another_tool(plant: EmulatedPlant, bus: str, address: int, number: int) -> None:
    """A program the plant file declares, changed as a teach-in on the floor would: the system block stays."""
    emulator = plant.emulators[bus]
    image = emulator.module(address).image
    emulator.update(address, image=image.with_programs({number: replace(image.known(number),
                                                                        T=image.known(number).T + 1)}))


def plan_document(plant: EmulatedPlant, capsys: pytest.CaptureFixture) -> dict:
    result = run_cli(capsys, "plan", plant.path, "--json")
    assert result.code == 0, result.err
    return json.loads(result.out)


def module_in(document: dict, name: str) -> dict:
    return next(m for bus in document["buses"] for m in bus["modules"] if m["name"] == name)


# -- which programs roll ----------------------------------------------------------------------------

T1, T2, T3 = "2026-11-28T01:00:00+00:00", "2026-11-28T02:00:00+00:00", "2026-11-28T03:00:00+00:00"


def known_at(since: str, held: int = 64, read_at: dict[int, str] | None = None) -> what_to_read.Known:
    """A record holding programs 1..`held`, as of `since` (those in `read_at` later)."""
    image = ModuleImage.factory(1).with_programs({n: None for n in range(held + 1, 65)})
    return what_to_read.Known(image, since, "apply of /p/a.yaml by ana@pc", read_at or {})


def target(bus: str, address: int, programs: tuple[int, ...] = (),
           managed: tuple[int, ...] = (1, 2, 3)) -> what_to_read.Target:
    return what_to_read.Target(bus, address, f"m{address}", programs, None, known_at(T1).image, managed)


def test_the_oldest_windows_of_each_line_roll_table():
    """(targets, record) → the programs rolled: per line the 8 windows of four (1–4, 5–8, …) whose oldest
    value on record is the oldest, ties by address then window; what the plan reads anyway, and a module not
    on record (read in full anyway), never roll."""
    first_half, second_half = tuple(range(1, 33)), tuple(range(33, 65))
    cases = [  # (targets, {key: record}) → {key: programs rolled}
        (([target("a", 1), target("a", 2)], {("a", 1): known_at(T2), ("a", 2): known_at(T1)}),
         {("a", 2): first_half}),
        # a tie
        (([target("a", 1), target("a", 2)], {("a", 1): known_at(T1), ("a", 2): known_at(T1)}),
         {("a", 1): first_half}),
        # read since
        (([target("a", 1)], {("a", 1): known_at(T1, read_at=dict.fromkeys(first_half, T2))}),
         {("a", 1): second_half}),
        (([target("a", 1), target("b", 2)], {("a", 1): known_at(T3), ("b", 2): known_at(T1)}),
         {("a", 1): first_half, ("b", 2): first_half}),  # each line its own budget
        # what the change reads is not rolled
        (([target("a", 1, (1, 2, 3))], {("a", 1): known_at(T1, held=4)}), {("a", 1): (4,)}),
        (([target("a", 1, (1, 2, 3))], {("a", 1): known_at(T1, held=3)}), {}),  # nothing left to roll
        (([replace(target("a", 1), known=None), target("a", 2)],
          {("a", 1): known_at(T1), ("a", 2): known_at(T3)}),
         {("a", 2): first_half}),  # not on record (or too old): read in full anyway
        # managed, not on record
        (([target("a", 1, managed=(1, 2, 3, 40))], {("a", 1): known_at(T1, held=3)}),
         {("a", 1): (1, 2, 3, 40)}),
        (([target("a", 1), target("a", 2)], {("a", 1): known_at(T1, held=12), ("a", 2): known_at(T2)}),
         # 3 windows of one module, then 5 of the next
         {("a", 1): tuple(range(1, 13)), ("a", 2): tuple(range(1, 21))}),
    ]
    for (targets, records), rolled in cases:
        said = what_to_read.rolling(targets, records)
        assert {key: programs for key, (programs, _) in said.items()} == rolled, (targets, records)
    said = what_to_read.rolling([target("a", 1)], {("a", 1): known_at(T1)})
    assert (said[("a", 1)][1]
            == "rolling evidence: programs 1–32, the oldest on its line, since 2026-11-28 01:00 UTC")
    # the targets: the programs added, with the record to agree with; "read in full" said only of a module
    # read in full
    targets, why = what_to_read.with_rolling([target("a", 1, (2,))], {}, {("a", 1): known_at(T1, held=3)})
    roll = what_to_read.rolling([target("a", 1, (2,))], {("a", 1): known_at(T1, held=3)})
    assert (targets == [replace(target("a", 1, (2,)), programs=(1, 2, 3))]
            and why == {("a", 1): roll[("a", 1)][1]})
    targets, why = what_to_read.with_rolling([target("a", 1, (), (1, 2, 3, 40))], {},
                                             {("a", 1): known_at(T1, held=64)})
    assert targets[0].programs == first_half and why == {}  # program 40 is still to roll: not read in full


def test_the_record_keeps_when_each_program_was_read_and_its_since_advances_once_each_old_value_is_read():
    """`merged`: what a plan read is as of that plan (`read_at`); `since` is the oldest value kept — so the
    module's windows roll in turn, and its record is as new as its oldest value."""
    record = known_at(T1)
    half = record.image.with_programs({n: None for n in range(33, 65)})
    after = what_to_read.merged(record, half, T2, "plan of /p/a.yaml by bo@pc")
    assert after.since == T1 and after.read_at == dict.fromkeys(range(1, 33), T2) and after.by == record.by
    rest = record.image.with_programs({n: None for n in range(1, 33)})
    again = what_to_read.merged(after, rest, T3, "plan of /p/a.yaml by bo@pc")
    assert again.since == T2 and again.read_at == dict.fromkeys(range(33, 65), T3)
    whole = what_to_read.merged(again, record.image, T3, "plan of /p/a.yaml by bo@pc")
    assert whole == what_to_read.Known(record.image, T3, "plan of /p/a.yaml by bo@pc")


# -- what rolling finds ---------------------------------------------------------------------------


def windows(plant: EmulatedPlant, bus: str) -> int:
    """W of `bus`: its modules' windows of four programs that hold a program the plant file manages or the
    record holds — the bound on the plans that find a change is ⌈W / 8⌉."""
    plant_ = api.load(plant.path)
    known = record(as_it_stands(plant_, plant_.buses))
    count = 0
    for b, m in plant_.modules():
        if b.name == bus:
            held = set(m.managed_programs()) | set(what_to_read.programs_in(known[(bus, m.address)].image))
            count += sum(1 for first in range(1, 65, 4) if held & set(range(first, first + 4)))
    return count


def newest(plant: EmulatedPlant, bus: str) -> tuple[str, int]:
    """The name and address of `bus`'s module whose record is the newest (ties: the highest address): its
    programs roll last."""
    plant_ = api.load(plant.path)
    known = record(as_it_stands(plant_, plant_.buses))
    module = max((m for b, m in plant_.modules() if b.name == bus),
                 key=lambda m: (known[(bus, m.address)].since, m.address))
    return module.name, module.address


def moved(plant: EmulatedPlant) -> None:
    """booth-a-top's program 1 moved from 1.750 m to 1.700 m in the plant file, as `emulated_plant` wrote it
    (an edit to the demo's text, "1: {position: 1.750}", changed nothing there)."""
    text = plant.path.read_text()
    assert text.count("position: 1.75\n") == 1  # booth-a-top's program 1, the edit's one place
    plant.path.write_text(text.replace("position: 1.75\n", "position: 1.7\n"))


def test_a_program_another_tool_changed_is_found_within_the_bound(plant, capsys, tmp_path):
    """The issue's limit: after an apply, another tool changes a program the plant file declares on a module
    whose system block stays, and the plant file changes something else (another line's module): main said
    "No changes" for it until the record expired. Rolling finds it within ⌈W / 8⌉ plans (booth-b: 3 modules
    whose records hold all 64 programs, W = 48: 6 plans) — on the module whose record is the newest, whose
    programs roll last — and the apply writes it back."""
    applied(plant, capsys)
    bound = -(-windows(plant, "booth-b") // what_to_read.ROLLED_WINDOWS)
    assert bound == 6
    name, address = newest(plant, "booth-b")
    changed_by_another_tool(plant, "booth-b", address, 2)
    moved(plant)
    plans = 0
    while plans < bound:
        plans += 1
        document = plan_document(plant, capsys)
        if module_in(document, name)["steps"]:
            break
    assert module_in(document, name)["steps"], f"not found within the {bound} plans"
    assert plans == 5  # the other modules' 32 older windows rolled first (4 plans), then its own 1–32
    said = document["read"]["not_as_verified"]
    # the rolled read is evidence: the line opens
    assert f"booth-b/{name} (program 2 is not as on record)" in said, said
    assert all(m["read"]["programs_not_read"] == [] for m in document["buses"][1]["modules"])
    done = run_cli(capsys, "apply", plant.path, "--auto-approve")
    assert done.code == 0, done.err
    assert plant.matches_plant()


def test_a_plan_file_with_rolled_programs_is_proved_by_reading_the_same_programs(plant, capsys, tmp_path):
    """`apply --plan` reads again exactly what its plan read: the rolled programs too."""
    applied(plant, capsys)
    moved(plant)
    rolled = read_next(plant.path)
    saved = tmp_path / "plan.json"
    planned = run_cli(capsys, "plan", plant.path, "--out", saved)
    assert planned.code == 0, planned.err
    # a module read in full by it
    assert "(rolling evidence: programs 1–32, the oldest on its line, since " in planned.out
    document = json.loads(saved.read_text())
    assert sum(map(len, rolled.values())) > 1 + 2 * 8 * 4 - 4  # booth-a-top's program 1, and 8 windows a line
    for name, programs in rolled.items():
        assert module_in(document, name)["read"]["programs"] == list(programs), name
    done = run_cli(capsys, "apply", plant.path, "--plan", saved, "--auto-approve")
    assert done.code == 0, done.err
    assert plant.matches_plant()


def test_full_read_and_actual_roll_nothing(plant, capsys, tmp_path):
    """What reads everything, or nothing, has nothing to roll."""
    applied(plant, capsys)
    full = run_cli(capsys, "plan", plant.path, "--full-read")
    assert full.code == 0 and "rolling evidence" not in full.out
    saved = tmp_path / "images.json"
    read = run_cli(capsys, "read", plant.path, "--json")
    assert read.code == 0, read.err
    saved.write_text(read.out)
    actual = run_cli(capsys, "plan", plant.path, "--actual", saved)
    assert (actual.code == 0 and "rolling evidence" not in actual.out
            and "oldest value taken" not in actual.out)


# -- the oldest evidence relied on, in every medium -------------------------------------------------


def oldest_words(plant: EmulatedPlant, whose: bool = True) -> str:
    """The oldest value the next plan takes from the record, in its words: of the modules whose programs it
    takes (not those it reads, rolled ones included), the one with the oldest record."""
    plant_ = api.load(plant.path)
    known = record(as_it_stands(plant_, plant_.buses))
    names = {(b.name, m.address): m.name for b, m in plant_.modules()}
    read = read_next(plant.path)
    taken = {(b.name, m.address) for b, m in plant_.modules()
             if set(m.managed_programs()) - set(read[m.name])}
    bus, address = min(taken, key=lambda key: (known[key].since, key))
    name = names[(bus, address)]
    by = f" as {known[(bus, address)].by} read or verified them" if whose else ""
    return (f"oldest value taken from the record: {bus}/{name}'s programs,{by} since "
            f"{what_to_read.to_the_minute(known[(bus, address)].since)}")


def test_every_medium_names_the_oldest_value_taken_from_the_record(plant, capsys, tmp_path):
    """Neither the rolled modules (read now) nor any module read in full is the oldest evidence: of the
    modules whose programs were taken from the record, the one with the oldest record — named with since when
    and by whom, once: in the headline of a plan without changes, in the "Read now" line of one with."""
    applied(plant, capsys)
    saved = tmp_path / "plan.json"
    words = oldest_words(plant)
    human = run_cli(capsys, "plan", plant.path, "--out", saved)
    assert human.code == 0, human.err
    headline = next(line for line in human.out.splitlines() if line.startswith("No changes"))
    assert words in headline, headline
    assert human.out.count("oldest value taken from the record") == 1, human.out  # the headline's: said once
    module = words.split(": ")[1].split("'s ")[0]
    assert json.loads(saved.read_text())["evidence"]["oldest"]["module"] == module
    shown = run_cli(capsys, "show", saved)
    assert shown.code == 0 and words in shown.out
    words = oldest_words(plant, whose=False)  # markdown escapes the path and user of `by`: the rest as said
    markdown = run_cli(capsys, "plan", plant.path, "--markdown")
    assert (markdown.code == 0 and words.split(",")[0] in markdown.out
            and words.split(",")[1] in markdown.out), markdown.out
    assert markdown.out.count("oldest value taken from the record") == 1, markdown.out
    words = oldest_words(plant)
    document = json.loads(run_cli(capsys, "plan", plant.path, "--json").out)
    assert document["evidence"]["oldest"]["module"] == words.split(": ")[1].split("'s ")[0]
    # a plan that changes something names it in its notes: the headline is the change's then
    moved(plant)
    words = oldest_words(plant, whose=False)
    changed = run_cli(capsys, "plan", plant.path)
    assert changed.code == 0 and words in next(line for line in changed.out.splitlines()
                                               if line.startswith("Read now:"))
    assert ("Plan: 1 of 6 modules changes" in changed.out
            and changed.out.count("oldest value taken from the record") == 1), changed.out


# -- soak: the bound --------------------------------------------------------------------------------

#: The programs the plant file declares of each module of each line.
DECLARED = {"booth-a": {1: (1, 2, 3), 2: (1, 2, 3), 5: (1, 2, 3, 10, 11)},
            "booth-b": {1: (1, 2, 3), 3: (1, 2, 3, 4), 4: tuple(range(1, 65))}}


@pytest.mark.soak
@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1))
def test_any_program_another_tool_changes_is_found_within_the_bound(tmp_path_factory, seed):
    """Seeded: after an apply and 0–7 plans (the roll anywhere in its turn), another tool changes one program
    the plant file declares on one module (system block unchanged); a plan finds it within ⌈W / 8⌉ plans of
    its line, and one apply after that leaves every module as the plant file says."""
    rnd = random.Random(seed)
    with emulated_plant(tmp_path_factory.mktemp("scenario")) as plant:
        api.told(api.apply(plant.plant, gates=api.Gates(allow_axis_release=True)))
        for _ in range(rnd.randint(0, 7)):
            api.plan(api.load(plant.path))
        bus = rnd.choice(sorted(DECLARED))
        address = rnd.choice(sorted(DECLARED[bus]))
        bound = -(-windows(plant, bus) // what_to_read.ROLLED_WINDOWS)
        changed_by_another_tool(plant, bus, address, rnd.choice(DECLARED[bus][address]))
        for _ in range(bound):
            planned = api.plan(api.load(plant.path))
            if any(m.steps for m in planned.modules if (m.bus, m.address) == (bus, address)):
                break
        else:
            pytest.fail(f"seed {seed}: {bus}/{address} not found within {bound} plans")
        api.told(api.apply(api.load(plant.path), gates=api.Gates(allow_axis_release=True)))
        assert plant.matches_plant(), seed


def test_the_record_file_keeps_read_at_and_passes_over_what_is_none():
    """`read_at` goes into the line's record file and back; a program that is none, a time without its zone or
    not later than `since` (another tool's edit) is taken as old as `since` — rolled sooner, never later."""
    from prc3cfg.shell import line_record

    keys = ("socket://127.0.0.1:4001",)
    line_record.LineRecord(keys).update({3: known_at(T1, read_at=dict.fromkeys(range(1, 33), T2))})
    assert line_record.LineRecord(keys).known()[3] == known_at(T1, read_at=dict.fromkeys(range(1, 33), T2))
    (path,) = [p for p in (Path(os.environ["PRC3CFG_STATE_DIR"]) / "lines").glob("*.json")]
    document = json.loads(path.read_text())
    document["modules"]["3"]["read_at"] = {"1": T3, "2": "2026-11-28T09:00:00",
                                           "3": "2000-01-01T00:00:00+00:00", "70": T3, "x": T3, "4": 5}
    path.write_text(json.dumps(document))
    assert line_record.LineRecord(keys).known()[3].read_at == {1: T3}
