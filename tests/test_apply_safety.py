"""`prc3cfg apply` where it can hurt: lost acknowledgements, tampered plan files, clamping of
programs the plant does not manage, damaged replies, foreign values, records that must survive.

Every test crosses the real link client and a real emulator; where a specific reply must be
lost or damaged, a `LossyProxy` sits between them.
"""

from __future__ import annotations

import json
import os
import random
import re
import signal
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
from emulated import emulated_plant, run_cli, travel_list
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from lossy import Loss, lose_replies_to

from prc3cfg.core import codec
from prc3cfg.core.image import ModuleImage, Program, SystemParameters, default_program
from prc3cfg.shell.records import Snapshot


def journal_events(directory: Path) -> list[dict]:
    folder = directory / ".prc3cfg" / "journal"
    return [json.loads(line) for path in sorted(folder.glob("*.jsonl"))
            for line in path.read_text().splitlines()]


def writes(directory: Path) -> list[str]:
    """Every write request any apply under `directory` put on a line (hex)."""
    return [e["request"] for e in journal_events(directory) if e["event"] == "exchange"
            and e["request"][:2] not in ("50", "51", "52")]


# -- 1. a 10h/20h that may have reached a module counts as a release ---------------------------


def test_a_20h_whose_every_acknowledgement_is_lost_still_counts_as_a_release(tmp_path, capsys):
    """The module executes each 20h; the master never hears so. It must be on the reference-travel list."""
    with emulated_plant(tmp_path, lossy={"booth-a": lose_replies_to(0x20, address=1)}) as plant:
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert result.code == 0, result.err  # the read-back shows the module as the plant file says
        assert not plant.emulators["booth-a"].module(1).referenced  # the module did release its axes
        assert "booth-a/booth-a-left" in travel_list(result.out)
        results = {(e["bus"], e["address"]): e for e in journal_events(tmp_path) if e["event"] == "result"}
        # the read-back shows the new system parameters
        assert results[("booth-a", 1)]["released_axes"] == "yes"


def test_a_20h_acknowledged_after_a_lost_reply_counts_once(tmp_path, capsys):
    with emulated_plant(tmp_path, lossy={"booth-b": lose_replies_to(0x20, address=3, times=1)}) as plant:
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert result.code == 0, result.err
        assert travel_list(result.out).count("booth-b/booth-b-right") == 1
        assert plant.matches_plant()


def test_a_module_silent_after_its_20h_is_listed_as_possibly_released(tmp_path, capsys):
    """From its 20h on, every reply of module 3 is lost: the 20h may have been executed, no read-back can
    tell."""
    silent = False

    def rule(frame, _):
        nonlocal silent
        silent |= frame.address == 3 and frame.message[:1] == b"\x20"
        return {Loss.REPLY} if silent and frame.address == 3 else set()

    with emulated_plant(tmp_path, lossy={"booth-b": rule}) as plant:
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert result.code == 1
        assert not plant.emulators["booth-b"].module(3).referenced
        assert ("booth-b/booth-b-right (possibly: its 10h/20h went out "
                "unacknowledged)") in travel_list(result.out)
        assert "✗ bus booth-b, module 3 (booth-b-right)" in result.err
        assert "not read back: what the module holds is not known" in result.err
        assert "restore with: prc3cfg restore" in result.problems[-1]
        results = {(e["bus"], e["address"]): e for e in journal_events(tmp_path) if e["event"] == "result"}
        assert results[("booth-b", 3)]["released_axes"] == "possibly"


def test_a_refused_20h_is_not_a_release(plant, capsys):
    plant.emulators["booth-b"].update(3, fault="E21")
    result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
    assert result.code == 1
    assert plant.emulators["booth-b"].module(3).referenced
    assert "booth-b-right" not in travel_list(result.out)


# -- 2. a plan file is proved before anything is written ---------------------------------------


@pytest.fixture
def plan_file(plant, capsys, tmp_path):
    path = tmp_path / "plan.json"
    assert run_cli(capsys, "plan", plant.path, "--out", path).code == 0
    return path


def edit(path: Path, change) -> None:
    document = json.loads(path.read_text())
    change(document)
    path.write_text(json.dumps(document))


def module_entry(document: dict, bus: str, address: int) -> dict:
    return next(m for b in document["buses"] if b["name"] == bus for m in b["modules"]
                if m["address"] == address)


def step(message: codec.Message) -> dict:
    return {"message": message.hex(), "summary": "looks harmless", "releases_axes": message.RELEASES_AXES}


def insert(index: int, *messages: codec.Message):
    def change(document):
        steps = module_entry(document, "booth-a", 1)["steps"]
        steps[index:index] = [step(m) for m in messages]

    return change


def set_step(index: int, **fields):
    def change(document):
        module_entry(document, "booth-a", 1)["steps"][index].update(fields)

    return change


def drop_step(index: int):
    def change(document):
        entry = module_entry(document, "booth-a", 5)
        del entry["steps"][index]
        entry["releases_axes"] = any(s["releases_axes"] for s in entry["steps"])

    return change


def swap_steps(document):
    steps = module_entry(document, "booth-a", 5)["steps"]
    steps[4], steps[5] = steps[5], steps[4]


def change_position(document):
    steps = module_entry(document, "booth-a", 1)["steps"]
    program = codec.decode_message(bytes.fromhex(steps[1]["message"]))
    steps[1]["message"] = codec.WriteProgram(program.pn,
                                             replace(program.program, P=program.program.P - 1)).hex()


def list_twice(document):
    document["buses"][0]["modules"].append(dict(document["buses"][0]["modules"][0]))


def hide_the_release(document):
    entry = module_entry(document, "booth-a", 1)
    entry["releases_axes"] = False
    entry["steps"][0]["releases_axes"] = False


TAMPERING = {
    "init all programs inserted": (
        insert(1, codec.InitAllPrograms()),
        "step 2 (1100) writes programs 4..64, which the plant file does not manage",
    ),
    "an unmanaged program's dwell": (
        insert(4, codec.WriteDwellTimes(((7, 50),))),
        "step 5 (430107000032) writes program 7, which the plant file does not manage",
    ),
    "20,000 steps appended": (
        insert(4, *[codec.ReadSystem()] * 20_000),
        "bus booth-a, module 1: 20004 steps, more than any plan of one module needs (128)",
    ),
    "a read as a step": (insert(4, codec.ReadSystem()), "step 5 (5000) is a read (50h), not a write"),
    "a second axis release": (insert(4, codec.InitSystem()), "step 5 (1000) releases the axes a second time"),
    "the release hidden": (hide_the_release, "step 1 (20000898"),
    "a releases_axes flag flipped": (
        set_step(0, releases_axes=False),
        "says releases_axes: false, but 20h releases the axes",
    ),
    "a position changed": (
        change_position,
        (
            "step 2 is 21010833015e00000005000000000200, where the plan made from this "
            "read-back has 21010834015e"
        ),
    ),
    "the system step dropped": (
        drop_step(0),
        "step 1 (2103044c00fa001e000003fc00320a00) would be refused by the module with code 32: P > S1",
    ),
    "two steps swapped": (
        swap_steps,
        "step 5 is 4603010202010a0b, where the plan made from this read-back has 43020100000502000005",
    ),
    "a module listed twice": (list_twice, "bus booth-a, module 1 is listed twice"),
    "an address as text": (
        lambda d: module_entry(d, "booth-a", 2).update(address="2"),
        'damaged plan file: buses[0].modules[1].address is the text "2", where a whole number belongs',
    ),
    "an address 2.7": (
        lambda d: module_entry(d, "booth-a", 2).update(address=2.7),
        "buses[0].modules[1].address is 2.7, where a whole number",
    ),
    "another prc3cfg version": (lambda d: d.update(prc3cfg_version="0.0.9"), "made by prc3cfg 0.0.9"),
    "a summary reworded": (
        lambda d: module_entry(d, "booth-a", 2)["steps"][0].update(summary="write nothing"),
        "buses[0].modules[1].review_sha256 (bus booth-a, module 2) is not the digest of the review text",
    ),
    "the axis warning removed": (
        lambda d: module_entry(d, "booth-a", 2)["changes"].update(warning=None),
        "buses[0].modules[1].review_sha256 (bus booth-a, module 2) is not the digest",
    ),
    "a field's value in the review": (
        lambda d: module_entry(d, "booth-a", 2)["changes"]["fields"][0].update(after=1),
        "buses[0].modules[1].review_sha256 (bus booth-a, module 2) is not the digest",
    ),
    "notes that are no text": (
        lambda d: d.update(left_alone=[{"step": 1}]),
        "damaged plan file: left_alone[0] is an object, where text belongs",
    ),
}


@pytest.mark.parametrize("case", TAMPERING, ids=list(TAMPERING))
def test_a_tampered_plan_file_is_refused_before_the_first_write(plant, plan_file, capsys, tmp_path, case):
    change, expected = TAMPERING[case]
    edit(plan_file, change)
    before = plant.images()
    result = run_cli(capsys, "apply", plant.path, "--plan", plan_file, "--auto-approve",
                     "--allow-axis-release")
    assert result.code == 1
    (line,) = result.problems
    assert line.startswith(f"error: {plan_file}: ") and expected in line
    assert plant.images() == before
    assert writes(tmp_path) == []
    assert all(s.referenced for e in plant.emulators.values() for s in e.modules().values())


@settings(max_examples=25, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_any_edit_of_a_step_is_refused(plant, plan_file, capsys, tmp_path, data):
    """Whatever a hex digit of whatever step becomes, what reaches the modules changed: refused."""
    document = json.loads(plan_file.read_text())
    steps = [s for b in document["buses"] for m in b["modules"] for s in m["steps"]]
    target = data.draw(st.sampled_from(steps))
    position = data.draw(st.integers(0, len(target["message"]) - 1))
    digit = data.draw(st.sampled_from([d for d in "0123456789abcdef" if d != target["message"][position]]))
    original = target["message"]
    target["message"] = original[:position] + digit + original[position + 1 :]
    edited = tmp_path / "edited.json"
    edited.write_text(json.dumps(document))
    before = plant.images()
    result = run_cli(capsys, "apply", plant.path, "--plan", edited, "--auto-approve", "--allow-axis-release")
    assert result.code == 1 and len(result.problems) == 1, result.err
    assert plant.images() == before and writes(tmp_path) == []


def test_an_untouched_plan_file_is_applied_from_any_directory(plant, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert run_cli(capsys, "plan", "plant.yaml", "--out", "plan.json").code == 0
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    result = run_cli(capsys, "apply", "--plan", tmp_path / "plan.json", "--auto-approve",
                     "--allow-axis-release")
    assert result.code == 0, result.err
    assert "proved against the modules as read back now" in result.out
    assert plant.matches_plant()
    (snapshot,) = (tmp_path / ".prc3cfg" / "snapshots").iterdir()
    restored = run_cli(capsys, "restore", snapshot, "--auto-approve", "--allow-axis-release")
    assert restored.code == 0, restored.err


# -- 4. the module's own clamping of programs the plant does not manage ------------------------

CLAMPING_PLANT = """\
plant: clamping
buses:
  - name: line
    port: socket://127.0.0.1:1
    modules:
      - address: 1
        name: left
        system: {upper_reversing_point: 2.200, max_speed: 0.500}
        programs:
          1: {position: 2.100, speed: 0.350}
"""


def test_clamping_of_kept_programs_is_shown_snapshotted_and_restored(tmp_path, capsys):
    source = tmp_path / "source.yaml"
    source.write_text(CLAMPING_PLANT)
    with emulated_plant(tmp_path, source=source) as plant:
        emulator = plant.emulators["line"]
        system = SystemParameters(S1=2500, S2=50, S3=754, S4=600, S5=10, S6=1500, S7=1000, S8=0, S10=583,
                                  S11=1100, S12=10)
        kept = {7: Program(P=2400, V=600, T=30), 8: Program(P=1000, V=300)}
        image = ModuleImage(1, system, (default_program(system),) * 64).with_programs(kept)
        emulator.update(1, image=image)

        shown = run_cli(capsys, "plan", plant.path, "--json")
        changes = json.loads(shown.out)["buses"][0]["modules"][0]["changes"]
        assert [(c["program"], c["field"], c["before"], c["after"]) for c in changes["clamped"]] == [
            (7, "P", 2400, 2200), (7, "V", 600, 500)]
        human = run_cli(capsys, "plan", plant.path)
        assert ("~ program 7 (not managed, kept): position 2.400 m → 2.200 m, speed 0.600 m/s → 0.500 m/s — "
                "clamped by the module" in human.out)
        assert "program 8" not in human.out

        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
        assert emulator.module(1).image.program(7) == Program(P=2200, V=500, T=30)
        (snapshot_path,) = (tmp_path / ".prc3cfg" / "snapshots").iterdir()
        assert Snapshot.load(snapshot_path).images[("line", 1)].program(7) == kept[7]

        restored = run_cli(capsys, "restore", snapshot_path, "--auto-approve", "--allow-axis-release")
        assert restored.code == 0, restored.err
        assert emulator.module(1).image.program(7) == kept[7]
        assert emulator.module(1).image.system == system


# -- 6. lines without a checksum ---------------------------------------------------------------


def test_a_refusal_heard_once_on_open_driver_is_asked_again_not_believed(tmp_path, capsys):
    """A reply damaged into "code 32" on a line without a checksum: the module did accept the write."""
    rule = lose_replies_to(0x21, address=2, times=1, loss=Loss.REFUSAL)
    with emulated_plant(tmp_path, framing="open-driver", lossy={"booth-a": rule}) as plant:
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert result.code == 0, result.err
        assert plant.matches_plant()
        assert "refused" not in result.err


def test_a_line_that_never_goes_quiet_ends_in_one_line(tmp_path, capsys):
    rule = lose_replies_to(0x50, address=1, loss=Loss.FLOOD)
    with emulated_plant(tmp_path, framing="open-driver", lossy={"booth-a": rule}, timeout=0.1) as plant:
        result = run_cli(capsys, "read", plant.path, "--retries", "1")
        assert result.code == 1
        (line,) = result.problems
        # the bus's 0.1 s on top of the line's own 0.083 s: a 50h's frames and two ZVZ gaps, the turnaround
        assert line.startswith("error: bus booth-a, module 1: no reply within 0.183 s to 50h after "
                               "2 attempts")


# -- 7. values a module should not hold ------------------------------------------------------


def test_values_out_of_range_on_a_module_are_shown_raw_and_fixed(plant, capsys):
    emulator = plant.emulators["booth-a"]
    image = emulator.module(1).image
    emulator.update(1, image=replace(image, system=replace(image.system, S8=5)).with_programs(
        {1: Program(P=9000, V=700, F1=2500, F2=-3, A=200)}))
    shown = run_cli(capsys, "read", plant.path)
    assert shown.code == 0, shown.err
    assert "position 9000 (raw, outside 0..9999)" not in shown.out  # 9000 is a position, just above S1
    assert "F1 2500 (raw, outside 0..1999)" in shown.out and "F2 -3 (raw, outside 0..1999)" in shown.out
    assert "next 200" in shown.out
    planned = run_cli(capsys, "plan", plant.path)
    assert planned.code == 0 and "alarm 5 (raw, outside 0..1)" in planned.out
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    assert plant.matches_plant()


# -- 8. records survive being killed ---------------------------------------------------------


@pytest.mark.parametrize("kills", [4, pytest.param(12, marks=pytest.mark.soak)])
def test_snapshots_are_whole_whenever_an_apply_is_killed(tmp_path, kills):
    """Real applies SIGKILLed at seeded points of their frame trace — late in the reads, as the last
    reply comes (the snapshot is written then), among the writes: every snapshot left behind is whole."""
    chooser = random.Random(8)
    env = {**os.environ, "PRC3CFG_LOCK_DIR": str(tmp_path / "locks")}
    fifo = tmp_path / "trace.fifo"
    os.mkfifo(fifo)
    with emulated_plant(tmp_path) as plant:
        planned = subprocess.run([sys.executable, "-m", "prc3cfg", "plan", plant.path, "--trace",
                                  tmp_path / "plan.trace"], env=env)
        assert planned.returncode == 0
        # an apply's trace, up to its snapshot
        reads = len((tmp_path / "plan.trace").read_text().splitlines())
        command = [sys.executable, "-m", "prc3cfg", "apply", plant.path, "--auto-approve",
                   "--allow-axis-release", "--trace", fifo]
        for _ in range(kills):
            point = chooser.randrange(reads - 8, reads + 40)
            process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
            with fifo.open() as trace:
                for seen, _line in enumerate(trace, start=1):
                    if seen == point:
                        process.send_signal(signal.SIGKILL)
                        break
                trace.read()  # to the end: the process has ended
            process.wait()
    snapshots = list((tmp_path / ".prc3cfg" / "snapshots").glob("*"))
    assert snapshots, "no apply got as far as its snapshot"
    for path in snapshots:
        # the one name a kill may leave beside a snapshot (shell.files: a file saved again)
        if path.suffix != ".json":
            beside = re.fullmatch(r"\.(.+\.json)\.[0-9a-f]{8}\.tmp", path.name)
            assert beside and (path.parent / beside[1]).is_file(), f"a temporary file was left: {path.name}"
        Snapshot.load(path)  # raises on a truncated file
