"""`prc3cfg status` (issue 44, item 2): the health table as cases (`prc3cfg.core.status`), and `status --json`
from the records of real applies on the emulator, checked against `schemas/status.schema.json`; the revision
counter and last verified from hand-kept journals (`Journal`, as the engine writes them), seeded in the soak
tier against a plain recomputation; `status serve` without asyncua says how to install it, in a real process.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import pytest
from emulated import emulated_plant, run_cli
from test_cli_json import valid

from prc3cfg import api
from prc3cfg.core.status import Health, LastVerified, ModuleFacts, drifted, health, worst
from prc3cfg.shell.locks import line_lock
from prc3cfg.shell.records import Journal
from prc3cfg.shell.sessions import bus_line_keys
from prc3cfg.shell.status import gather, identities

ROOT = Path(__file__).resolve().parents[1]
NORMAL = ModuleFacts("a", 1, "m", 3, None, last_failed=False, apply_running=False, travel_pending=False,
                     drift_seen=False,
                     evidence_age=10.0, evidence_bound=3600.0)

#: (what differs from a healthy module, the health it gives): every row of `RULES`, and what wins when two
#: hold.
CASES = [
    ({}, Health.NORMAL),
    ({"apply_running": True}, Health.CHECK_FUNCTION),
    ({"last_failed": True}, Health.FAILURE),
    ({"travel_pending": True}, Health.MAINTENANCE_REQUIRED),
    ({"drift_seen": True}, Health.MAINTENANCE_REQUIRED),
    ({"evidence_age": 3600.5}, Health.MAINTENANCE_REQUIRED),
    ({"evidence_age": 3600.0}, Health.NORMAL),  # at the bound: still within it
    ({"evidence_age": None}, Health.MAINTENANCE_REQUIRED),  # no record at all
    ({"apply_running": True, "last_failed": True, "drift_seen": True}, Health.CHECK_FUNCTION),
    ({"last_failed": True, "travel_pending": True}, Health.FAILURE),
]


@pytest.mark.parametrize(("changed", "expected"), CASES)
def test_health_is_the_first_row_of_the_table_that_holds(changed, expected):
    value, why = health(replace(NORMAL, **changed))
    assert value is expected
    assert (why == "") == (expected is Health.NORMAL)


def test_a_lines_health_is_its_most_pressing_modules():
    assert worst([Health.NORMAL, Health.MAINTENANCE_REQUIRED, Health.FAILURE]) is Health.FAILURE
    assert worst([Health.FAILURE, Health.CHECK_FUNCTION]) is Health.CHECK_FUNCTION
    assert worst([]) is Health.NORMAL
    assert [int(h) for h in Health] == [0, 1, 2, 3, 4]  # DI's DeviceHealthEnumeration


def test_drift_is_a_difference_where_both_say_something():
    plant = api.load(ROOT / "plants" / "demo-line.yaml")
    desired = plant.modules()[0][1].desired_image()
    assert not drifted(desired, desired)
    managed = next(n for n, p in enumerate(desired.programs, 1) if p is not None)
    assert not drifted(desired, desired.with_programs({managed: None}))  # not read: no drift
    other = plant.modules()[1][1].desired_image()
    assert drifted(desired, other) == (desired.system != other.system or desired.programs != other.programs)


def test_status_json_follows_the_records_of_an_apply(tmp_path, capsys):
    with emulated_plant(tmp_path) as plant:
        before = run_cli(capsys, "status", plant.path, "--json")
        assert before.code == 0, before.err
        document = valid("status", json.loads(before.out))
        modules = [m for line in document["lines"] for m in line["modules"]]
        assert len(modules) == len(plant.plant.modules())
        assert {m["health"] for m in modules} == {"MAINTENANCE_REQUIRED"} and {m["revision_counter"]
                                                                               for m in modules} == {0}

        applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert applied.code == 0, applied.err
        after = valid("status", json.loads(run_cli(capsys, "status", plant.path, "--json").out))
        modules = [m for line in after["lines"] for m in line["modules"]]
        assert {m["health"] for m in modules} == {"NORMAL"}, [m["why"] for m in modules]
        assert {m["revision_counter"] for m in modules} == {1}
        last = modules[0]["last_verified"]
        assert (last["plant_sha256"] == plant.plant.sha256
                and last["by"].startswith(os.environ.get("USER", "")) and last["time"])

        bus = plant.plant.buses[0]
        with line_lock(bus_line_keys(plant.plant, bus), "test: an apply holds the line"):
            held = valid("status", json.loads(run_cli(capsys, "status", plant.path, "--json").out))
        assert held["lines"][0]["health"] == "CHECK_FUNCTION" and held["lines"][1]["health"] == "NORMAL"

        words = run_cli(capsys, "status", plant.path)
        assert (words.code == 0 and f"bus {bus.name}: NORMAL" in words.out
                and "revision 1, verified" in words.out)


def test_status_of_a_file_that_is_no_plant_is_one_line(tmp_path, capsys):
    broken = tmp_path / "plant.yaml"
    broken.write_text("buses: [\n", encoding="utf-8")
    result = run_cli(capsys, "status", broken, "--json")
    assert result.code == 1 and result.out == ""
    assert len(result.problems) == 1 and str(broken) in result.problems[0] and "Traceback" not in result.err


def test_serve_without_asyncua_says_how_to_install_it(tmp_path):
    """A real process in which asyncua cannot be imported, as where the extra is not installed."""
    program = ("import sys; sys.modules['asyncua'] = None; from prc3cfg.cli import main; "
               f"main(['status', 'serve', {str(ROOT / 'plants' / 'demo-line.yaml')!r}, '--listen', "
               "'opc.tcp://127.0.0.1:4840', "
               f"'--trust', {str(tmp_path)!r}])")
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, check=False,
                          env=os.environ | {"PYTHONPATH": str(ROOT)})
    assert done.returncode == 1 and done.stdout == ""
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("error: prc3cfg status serve needs the OPC UA library asyncua (the extra opcua), "
                           "which the Python running prc3cfg does not have — install it there: "), line
    assert line.endswith(" -m pip install asyncua"), line


def _journal(plant_path: Path, command: str, results: list[tuple[str, int, bool, bool]], user: str,
             commit: str | None) -> Path:
    """A run's journal as the engine keeps it: a header, and a `result` per module (verified, written or
    not)."""
    while True:  # a fresh name: two journals made within one microsecond would share one
        journal = Journal(plant_path,
                          {"command": command, "user": user, "host": "bench",
                           "plant": {"path": str(plant_path), "sha256": "ab" * 32,
                                     "git": {"commit": commit}}})
        if not journal.path.exists():
            break
    for bus, address, verified, written in results:
        journal.record("result", bus=bus, address=address, verified=verified, failure=None if verified
                       else "no answer",
                       released_axes="no", written=["3a"] if written else [], interrupted=False)
    journal.close()
    return journal.path


def _history(
    seed: int, plant_path: Path, modules: list[tuple[str, int]], runs: int
) -> dict[tuple[str, int], tuple[int, bool, str | None]]:
    """Random runs written as journals; what a plain reading of them gives per module: verified changes,
    whether the newest change failed, and who made the newest verified one."""
    chance = random.Random(seed)
    expected = {key: (0, False, None) for key in modules}
    for n in range(runs):
        command = chance.choice(["apply", "apply", "restore", "adopt"])
        user = f"user{chance.randrange(3)}"
        touched = chance.sample(modules, chance.randrange(1, len(modules) + 1))
        results = [(bus, address, chance.random() < 0.8, chance.random() < 0.7) for bus, address in touched]
        _journal(plant_path, command, results, user, f"{n:040x}")
        if command == "adopt":
            continue
        for bus, address, verified, written in results:
            count, _, by = expected[(bus, address)]
            if written:
                expected[(bus, address)] = (count + verified, not verified, f"{user}@bench" if verified
                                            else by)
    return expected


def _check_history(seed: int, root: Path, runs: int) -> None:
    plant = api.load(ROOT / "plants" / "demo-line.yaml")
    plant_path = root / f"seed{seed}" / "plant.yaml"
    plant_path.parent.mkdir(parents=True)
    plant_path.write_bytes(plant.path.read_bytes())
    plant = api.load(plant_path)
    expected = _history(seed, plant_path, [(bus.name, module.address) for bus, module in plant.modules()],
                        runs)
    facts, _ = gather(plant, identities(plant), now=datetime.now(UTC))
    for f in facts:
        count, failed, by = expected[(f.bus, f.address)]
        assert (f.revision, f.last_failed, f.last_verified.by if f.last_verified else None) == (count, failed,
                                                                                                by), (seed, f)
        # nothing else holds here: no apply runs, no travel; no record: maintenance
        assert (health(f)[0] is Health.FAILURE) == failed
        assert health(f)[0] in (Health.FAILURE, Health.MAINTENANCE_REQUIRED)
        if f.last_verified is not None:
            assert (isinstance(f.last_verified, LastVerified) and f.last_verified.commit is not None
                    and len(f.last_verified.commit) == 40)


def test_a_few_record_histories_give_what_a_plain_reading_gives(tmp_path):
    for seed in range(3):
        _check_history(seed, tmp_path, runs=6)


@pytest.mark.soak
def test_many_record_histories_give_what_a_plain_reading_gives(tmp_path):
    for seed in range(40):
        _check_history(seed, tmp_path, runs=25)

