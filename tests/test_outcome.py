"""A module's outcome of an apply (`prc3cfg.core.outcome.ModuleOutcome`): a frozen value, built once when its
run ends, that the result, the account, the journal and the JSON events take as it is. Its `released` is
concluded once, by `axes.released` from the run's facts (each row of `test_axes.ROWS`, as a run would hold
it); its `failure` is said once, by its constructor. Without the emulator, but for the one apply that shows
what leaves it is the frozen value and `released` is concluded once a module."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import random
import subprocess
import sys
import typing
from dataclasses import replace
from typing import Any

import pytest
from emulated import emulated_plant
from hypothesis import given
from hypothesis import strategies as st
from lossy import Loss
from test_api import paired
from test_axes import FACTS, ROWS

import prc3cfg.api
from prc3cfg.core import axes, codec, events, render
from prc3cfg.core.apply_states import Course, State
from prc3cfg.core.axes import Release
from prc3cfg.core.image import DEFAULT_SYSTEM, ModuleImage
from prc3cfg.core.outcome import INTERRUPTED, ModuleOutcome, to_travel
from prc3cfg.core.planner import Step

BEFORE = ModuleImage.factory(1)
CHANGED = replace(BEFORE, system=replace(DEFAULT_SYSTEM, S6=DEFAULT_SYSTEM.S6 + 1))
RELEASE = Step(codec.WriteSystem(CHANGED.system), "S6 up", True)
INIT_2 = Step(codec.InitProgram(2), "program 2 to its defaults", False)


def outcome(holds: set[str] = frozenset(), state: State = State.FAILED, problem: str | None = "lost",
            stopped: str | None = None,
            ) -> ModuleOutcome:
    """A module's outcome whose run holds the facts named (`test_axes.FACTS`) and no other."""
    sent = (RELEASE, INIT_2) if {"sent", "acknowledged"} & holds else (INIT_2,)
    final = (CHANGED if "changed" in holds else BEFORE) if "read_back" in holds else None
    return ModuleOutcome("line", 1, "m1", BEFORE, CHANGED, (RELEASE, INIT_2), 0, sent, (RELEASE,)
                         if "acknowledged" in holds else (),
                   final, Course(state), exposed="exposed" in holds,
                         possibly_written="possibly_written" in holds,
                   problem=problem, stopped=stopped)


@pytest.mark.parametrize(("holds", "expected", "why"), ROWS, ids=[why for _, _, why in ROWS])
def test_an_outcome_s_release_is_concluded_from_its_run_s_facts(holds: set[str], expected: Release,
                                                                why: str) -> None:
    assert outcome(holds).released is expected, why


def test_an_outcome_is_frozen_and_holds_what_it_was_given() -> None:
    ended = outcome({"sent", "read_back", "changed"})
    for name, value in (("failure", None), ("released", Release.NO), ("final", None), ("sent", ())):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(ended, name, value)
    assert ended.unacknowledged == (RELEASE, INIT_2) and ended.unsent == () and not ended.unchanged


#: (the state the run ended in, its last problem, why the lines were stopped) → the outcome's failure
FAILURES = {
    "verified: no failure, whatever went wrong on the way": (State.VERIFIED, "step 1 of 2 (S6 up): no reply",
                                                             None, None),
    "failed: its last problem": (State.FAILED, "verification: no reply", None, "verification: no reply"),
    "a stop not by a signal says so where it says interrupted": (
        State.INTERRUPTED, f"{INTERRUPTED} before step 2 of 2 (program 2)", "a record could not be kept",
        "stopped (a record could not be kept) before step 2 of 2 (program 2)"),
    "a signal's stop says interrupted": (State.INTERRUPTED, f"{INTERRUPTED} before step 1 of 2", None,
                                         f"{INTERRUPTED} before step 1 of 2"),
    "a stop leaves other words as they are": (State.INTERRUPTED, "nothing was sent to it",
                                              "a record could not be kept", "nothing was sent to it"),
    "a stop leaves a failed module's words as they are": (State.FAILED, f"{INTERRUPTED} later",
                                                          "a record could "
                                                          "not be kept", f"{INTERRUPTED} later"),
}


@pytest.mark.parametrize(("state", "problem", "stopped", "expected"), FAILURES.values(), ids=FAILURES)
def test_an_outcome_s_failure_is_said_once_by_its_constructor(state: State, problem: str, stopped: str | None,
                                                              expected: str | None) -> None:
    assert outcome(state=state, problem=problem, stopped=stopped).failure == expected


def test_render_and_the_events_take_the_outcome_as_it_is() -> None:
    """No Protocol mirrors the outcome: the account, the travel list and the events are typed by it."""
    assert not hasattr(render, "Run")
    for function in (render.account, events.module):
        assert typing.get_type_hints(function)["run"] is ModuleOutcome
    ended = outcome({"sent"})
    assert render.account(ended) == "\n".join((
        "✗ bus line, module 1 (m1): lost",
        "    written: nothing acknowledged",
        "    sent, not acknowledged: S6 up; program 2 to its defaults",
        "    not read back: what the module holds is not known"))
    assert render.travel_list([ended]) == (f"{render.TRAVEL}\n    line/m1 (possibly: its 10h/20h went out "
                                           "unacknowledged)")
    assert events.module("apply", ended)["released"] == "possibly"


def test_an_apply_hands_out_frozen_outcomes_each_concluded_once(tmp_path, monkeypatch) -> None:
    """What leaves an apply is the frozen outcome, and `axes.released` runs once a module (the if-chain it
    replaced ran 24 times an apply)."""
    calls: list[Release] = []
    concluded = axes.released

    def counted(**facts: bool) -> Release:
        calls.append(said := concluded(**facts))
        return said

    monkeypatch.setattr(axes, "released", counted)
    with contextlib.ExitStack() as stack:
        _, links = paired(tmp_path, stack)
        plant = prc3cfg.api.load(tmp_path / "plant.yaml")
        result = prc3cfg.api.apply(plant, gates=prc3cfg.api.Gates(allow_axis_release=True), links=links)
    assert result.verified and result.runs and all(type(run) is ModuleOutcome for run in result.runs)
    assert calls == [run.released for run in result.runs]
    assert result.released == tuple(run for run in result.runs if run.released is not Release.NO) != ()


@pytest.mark.soak
@given(holds=st.sets(st.sampled_from(FACTS)),
       state=st.sampled_from([State.VERIFIED, State.FAILED, State.INTERRUPTED]),
       stopped=st.sampled_from([None, "a record could not be kept"]))
def test_every_outcome_says_the_same_of_its_axes_everywhere(holds: set[str], state: State,
                                                            stopped: str | None) -> None:
    """Over runs of every combination of facts and ends: the outcome's `released` is `axes.released`'s of its
    facts; the travel list, the result's `released`, the journal's and the JSON event's say the same; a
    verified outcome has no failure, and a failed one's account names it."""
    ended = outcome(holds, state, f"{INTERRUPTED} before step 1 of 2", stopped)
    facts = {fact: fact in holds for fact in FACTS} | {"sent": bool({"sent", "acknowledged"} & holds)}
    facts["changed"] = facts["changed"] and facts["read_back"]
    assert ended.released is axes.released(**facts)
    travels = ended.released is not Release.NO
    assert (to_travel([ended]) == [ended]) is travels and (render.travel_list([ended]) is not None) is travels
    module = events.module("apply", ended)
    assert (module is not None and module["released"] == ended.released.value
            and module["failure"] == ended.failure)
    if state is State.VERIFIED:
        assert ended.failure is None
    else:
        assert ended.failure is not None and ended.failure in (render.account(ended) or "")


@pytest.mark.soak
@pytest.mark.parametrize("seed", range(8))
def test_an_apply_whose_exchanges_are_lost_says_the_same_of_each_module_in_its_json_and_its_journal(
    tmp_path, seed: int
) -> None:
    """A real `prc3cfg apply --json` process over a commissioned demo line whose plant file now moves one
    module's upper reversing point (a 20h) and every module's stroke speed (program writes only): the requests
    or replies of three modules' exchanges lost at a seeded rate from their first write on. Each module's JSON
    event and its journal record carry the one outcome — the same release and failure — and the travel event
    names exactly the modules whose outcome is not `NO`."""
    chooser = random.Random(seed)
    rate = chooser.uniform(0.2, 0.6)
    writing: set[int] = set()  # the read-back before the plan is left whole: a line not read is not written
    armed = False

    def rule(frame: Any, _: int) -> set[Loss]:
        writing.update([frame.address] if armed and frame.message[:1] not in (b"\x50", b"\x51", b"\x52")
                       else [])
        lost = frame.address in writing and frame.address in (1, 3, 5) and chooser.random() < rate
        return {chooser.choice([Loss.REPLY, Loss.REQUEST])} if lost else set()

    def apply(*json: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "prc3cfg", "apply", str(plant.path), "--auto-approve",
                               "--allow-axis-release",
                               "--retries", "1", *json], capture_output=True, text=True,
                              timeout=120)

    with emulated_plant(tmp_path, lossy={"booth-a": rule, "booth-b": rule}) as plant:
        assert apply().returncode == 0
        plant.path.write_text(plant.path.read_text().replace("upper_reversing_point: 1.8\n",
                                                             "upper_reversing_point: 1.79\n")
                              .replace("speed: 0.35\n", "speed: 0.34\n"))
        armed = True
        done = apply("--json")
        names = {(bus.name, m.address): m.name for bus, m in plant.plant.modules()}
    assert "Traceback" not in done.stderr and done.returncode in (0, 1), done.stderr
    said = [json.loads(line) for line in done.stdout.splitlines()]
    modules = {(e["bus"], e["address"]): e for e in said if e["event"] == "module"}
    journal = [json.loads(line) for path in sorted((tmp_path / ".prc3cfg" / "journal").glob("*.jsonl"))[-1:]
               for line in path.read_text().splitlines()]
    results = {(e["bus"], e["address"]): e for e in journal if e["event"] == "result"}
    assert modules and modules.keys() <= results.keys()
    for key, module in modules.items():
        assert (module["released"], module["failure"]) == (results[key]["released_axes"],
                                                           results[key]["failure"]), key
        assert (module["result"] == "failed") is (not results[key]["verified"]), key
    travel = next((e for e in said if e["event"] == "travel"), {"modules": []})
    assert {(m["bus"], m["name"]) for m in travel["modules"]} == {(bus, names[bus, a])
                                                                  for (bus, a), r in results.items()
                                                                     if r["released_axes"] != "no"}
