"""What to read (`prc3cfg.core.what_to_read`), as tables of cases: given the line's record, the
change and the evidence, which programs each command reads — a plan, a plan file, a restore or a full
read, a read that widens on what it finds, a verification. The same decisions over the emulator are
`test_targeted_read.py`, `test_link.py` and `test_cli_apply.py`'s verification tests."""

from __future__ import annotations

from dataclasses import replace
from datetime import UTC, datetime, timedelta

import pytest

from prc3cfg.core import codec, what_to_read
from prc3cfg.core.image import DEFAULT_SYSTEM, PROGRAM_NUMBERS, ModuleImage, Wanted
from prc3cfg.core.plan_file import PlannedModule
from prc3cfg.core.planner import Step
from prc3cfg.core.what_to_read import UNSET, Known, Target

NOW = datetime(2026, 11, 26, 12, 0, tzinfo=UTC)
MAX_AGE = 3_600.0
ALL = frozenset(PROGRAM_NUMBERS)

FACTORY = ModuleImage.factory(1)  # what the module holds: defaults throughout
#: The plant file manages programs 1..3 and wants program 2 other than the module holds it.
DESIRED = FACTORY.with_programs({n: None for n in range(4, 65)}).with_programs({2: replace(FACTORY.known(2),
                                                                                           T=7)})
MANAGED = (1, 2, 3)
# clamps positions (docs/protocol.md "What a module does")
LOWER_S1 = replace(DEFAULT_SYSTEM, S1=DEFAULT_SYSTEM.S1 - 100)
OTHER_S6 = replace(DEFAULT_SYSTEM, S6=DEFAULT_SYSTEM.S6 + 1)  # clamps nothing
M1, M2 = ("line", 1), ("line", 2)


def record(image: ModuleImage, hours: float = 0.5) -> Known:
    return Known(image, (NOW - timedelta(hours=hours)).isoformat(), "apply of a.yaml by ana@pc")


def wanted(address: int = 1) -> Wanted:
    return Wanted("line", address, f"m{address}", replace(DESIRED, address=address))


def target(address: int, programs: tuple[int, ...], known: ModuleImage | None) -> Target:
    return Target("line", address, f"m{address}", programs, DESIRED.system, None if known is None
                  else replace(known, address=address), MANAGED)


# -- a plan ----------------------------------------------------------------------------------------

OVERRULED = "bo@pc's record (newer) is not this user's"
# (the record, modules another user's newer entry overruled, modules in E12) → (targets, read in full because)
PLAN_CASES = {
    "no record: read in full": ({}, {}, frozenset(), None),
    "a record of another module only: read in full": ({M2: record(FACTORY)}, {}, frozenset(), None),
    "the record shows the plant file's values: the system block only": (
        {M1: record(DESIRED)}, {}, frozenset(), ([target(1, (), DESIRED)], {})),
    "the record shows program 2 other than wanted: program 2": (
        {M1: record(FACTORY)}, {}, frozenset(), ([target(1, (2,), FACTORY)], {})),
    "a program the record does not know: that program": (
        {M1: record(FACTORY.with_programs({3: None}))}, {}, frozenset(),
        ([target(1, (2, 3), FACTORY.with_programs({3: None}))], {})),
    "a record older than record_max_age: every managed program": (
        {M1: record(DESIRED, hours=2)}, {}, frozenset(),
        ([target(1, MANAGED, None)],
         {M1: f"its record ({record(DESIRED, hours=2).since}) is older than record_max_age (3600 s)"})),
    "E12 since: every managed program, whatever the record": (
        {M1: record(DESIRED)}, {}, frozenset({M1}), ([target(1, MANAGED, None)], {M1: UNSET})),
    "overruled by another user's newer entry: every managed program, and whose claim": (
        {}, {M1: OVERRULED}, frozenset(), ([target(1, MANAGED, None)], {M1: OVERRULED})),
    "each module by its own record": (
        {M1: record(DESIRED)}, {M2: OVERRULED}, frozenset(),
        ([target(1, (), DESIRED), target(2, MANAGED, None)], {M2: OVERRULED})),
}


@pytest.mark.parametrize(("known", "overruled", "unset", "expected"), PLAN_CASES.values(), ids=PLAN_CASES)
def test_what_a_plan_reads(known, overruled, unset, expected):
    modules = [wanted(1), wanted(2)] if M2 in overruled else [wanted(1)]
    known = {key: replace(k, image=replace(k.image, address=key[1])) for key, k in known.items()}
    assert what_to_read.for_plan(modules, known, overruled, unset, {"line": MAX_AGE}, NOW) == expected


# -- a plan file, a restore, a full read -----------------------------------------------------------


def entry(programs_read: tuple[int, ...]) -> PlannedModule:
    return PlannedModule("line", 1, "m1", "", (), 0, programs_read)


PLAN_FILE_CASES = {  # (the record now, what the plan read) → (programs read again, evidence kept, stale)
    "the record as the plan saw it: the plan's reads": (record(DESIRED), (), ((), DESIRED, False)),
    "program 2 read by the plan: read again": (record(FACTORY), (2,), ((2,), FACTORY, False)),
    "program 2 changed on record since, the plan took it as known: stale": (record(FACTORY), (), None),
    "the record gone since (an apply forgot it): stale": (None, (2,), None),
    "the record outgrew record_max_age: stale": (record(FACTORY, hours=2), (2,), None),
    "a plan that read every managed program needs no record": (None, MANAGED, (MANAGED, None, False)),
}


@pytest.mark.parametrize(("known", "programs_read", "expected"), PLAN_FILE_CASES.values(),
                         ids=PLAN_FILE_CASES)
def test_what_a_plan_file_reads_again(known, programs_read, expected):
    targets, stale = what_to_read.for_plan_file([entry(programs_read)], {M1: DESIRED}, {}
                                                if known is None else {M1: known},
                                                {"line": MAX_AGE}, NOW)
    if expected is None:
        assert (targets, stale) == ([], entry(programs_read))
    else:
        programs, evidence, _ = expected
        assert stale is None
        # no clamping: the plan's steps are proved
        assert targets == [Target("line", 1, "m1", programs, None, evidence, MANAGED)]


def test_a_full_read_and_a_restore_read_every_program_their_image_holds_and_what_it_can_clamp():
    snapshot = replace(FACTORY, address=2, system=LOWER_S1)
    modules = [wanted(1), Wanted("line", 2, "m2", snapshot)]
    every = tuple(PROGRAM_NUMBERS)
    assert what_to_read.in_full(modules) == [
        Target("line", 1, "m1", MANAGED, DESIRED.system, managed=MANAGED),
        Target("line", 2, "m2", every, LOWER_S1, managed=every)]


# -- a read widens on what it finds ----------------------------------------------------------------

# (the 50h's answer, the target's programs, the plan's system, the record's image) → programs to read
AFTER_SYSTEM_CASES = {
    "no plan system, no record: the target's": (DEFAULT_SYSTEM, (2,), None, None, {2}),
    "a plan system that clamps nothing here: the target's": (DEFAULT_SYSTEM, (2,), OTHER_S6, None, {2}),
    "a plan system that can clamp here: every program": (DEFAULT_SYSTEM, (2,), LOWER_S1, None, ALL),
    "the record's system block: the target's": (DEFAULT_SYSTEM, (2,), None, FACTORY, {2}),
    "another system block than the record's: every managed program too": (OTHER_S6, (2,), None, FACTORY,
                                                                          {1, 2, 3}),
    "both: every program": (OTHER_S6, (2,), LOWER_S1, FACTORY, ALL),
}


@pytest.mark.parametrize(("system", "programs", "clamped_by", "known", "expected"),
                         AFTER_SYSTEM_CASES.values(), ids=AFTER_SYSTEM_CASES)
def test_what_a_read_reads_after_the_system_block(system, programs, clamped_by, known, expected):
    assert what_to_read.after_system(system, programs, clamped_by, known, MANAGED) == expected


# a read of the system block and program 2
READ_2 = FACTORY.with_programs({n: None for n in PROGRAM_NUMBERS if n != 2})
OTHER_2 = READ_2.with_programs({2: replace(FACTORY.known(2), T=9)})
AFTER_PROGRAMS_CASES = {  # (what was read, the record's image) → programs still to read
    "no record: nothing more": (OTHER_2, None, set()),
    "as on record: nothing more": (READ_2, FACTORY, set()),
    "a program other than on record: every managed program not read yet": (OTHER_2, FACTORY, {1, 3}),
    "a program the record does not know: no evidence, "
    "nothing more": (OTHER_2, FACTORY.with_programs({2: None}), set()),
    "another system block (every managed program already read): nothing more": (
        replace(FACTORY, system=OTHER_S6), FACTORY, set()),
}


@pytest.mark.parametrize(("read", "known", "expected"), AFTER_PROGRAMS_CASES.values(),
                         ids=AFTER_PROGRAMS_CASES)
def test_what_a_read_reads_after_its_programs(read, known, expected):
    assert what_to_read.after_programs(read, known, MANAGED) == expected


def test_the_modules_read_in_full_say_why_and_the_evidence_comes_second():
    known = FACTORY.with_programs({n: None for n in range(4, 65)})
    targets = [target(1, (2,), known), target(2, (2,), known), target(3, (), None), target(4, (2,), known)]
    images = {M1: replace(OTHER_2, address=1), M2: replace(READ_2, address=2),
              ("line", 3): replace(READ_2, address=3)}
    why = {("line", 3): "not on the line's record", ("line", 4): "not on the line's record"}
    assert what_to_read.read_in_full([wanted(a) for a in (1, 2, 3, 4)], targets, images, why) == (
        "line/m1 (program 2 is not as on record)",  # contradicted by its read-back
        # read as on record, on a line m1 opened
        "line/m2 (line/m1 on its line: program 2 is not as on record)",
        "line/m3 (not on the line's record)",
        "line/m4 (not on the line's record)",  # why, though it was not read (the read stopped)
    )


# -- a verification --------------------------------------------------------------------------------

INIT_2 = Step(codec.InitProgram(2), "program 2 to its defaults", False)
LOWER = Step(codec.WriteSystem(LOWER_S1), "S1 lower", True)
# what the device model predicts
CLAMPED = FACTORY.with_programs({3: replace(FACTORY.known(3), P=FACTORY.known(3).P - 1)})
FIRST = FACTORY.with_programs({n: None for n in range(5, 65)})  # the first read-back held programs 1..4
# (the steps sent, Verify.FULL, a release on the line without error detection) → (the system block, programs)
VERIFY_CASES = {
    "nothing sent: nothing": ((), False, False, (False, set())),
    "a program step: its programs": ((INIT_2,), False, False, (False, {2})),
    "a system step: the system block and what the module's own clamping changed": ((LOWER, INIT_2), False,
                                                                                   False, (True, {2, 3})),
    "nothing sent on a line where a release went out unprotected: the system block": ((), False, True,
                                                                                      (True, set())),
    "Verify.FULL: the system block and every program the first read-back held": ((INIT_2,), True, False,
                                                                                 (True, {1, 2, 3, 4})),
}


@pytest.mark.parametrize(("sent", "full", "watch", "expected"), VERIFY_CASES.values(), ids=VERIFY_CASES)
def test_what_a_verification_reads(sent, full, watch, expected):
    assert what_to_read.verification_reads(FIRST, FIRST, CLAMPED, sent, full=full,
                                           watch_system=watch) == expected
