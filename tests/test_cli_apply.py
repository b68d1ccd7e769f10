"""`prc3cfg apply` and `restore` against real emulators: gates, stale plans, locks, faults, convergence."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import pytest
import yaml
from emulated import DEMO, emulated_plant, run_cli, travel_list

from prc3cfg.shell.emulator.server import FaultInjection
from prc3cfg.shell.locks import line_keys, line_lock


def test_apply_converges_and_replan_is_empty(plant, capsys):
    result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
    assert result.code == 0, result.err
    assert plant.matches_plant()
    assert "Apply complete: 6 modules written and verified." in result.out
    assert travel_list(result.out).startswith("⚠ Travel to reference point required before production on: "
                                              "booth-a/booth-a-left,")
    assert all(not s.referenced for e in plant.emulators.values() for s in e.modules().values())
    assert run_cli(capsys, "plan", plant.path, "--detailed-exitcode").code == 0


def test_one_module_is_one_module(plant, capsys):
    """Counts read right: "1 module", never "1 modules"."""
    result = run_cli(capsys, "apply", plant.path, "--module", "booth-a-top", "--auto-approve",
                     "--allow-axis-release")
    assert result.code == 0, result.err
    assert "Apply complete: 1 module written and verified." in result.out
    assert " 1 modules" not in result.out + result.err


def test_axis_release_is_refused_without_the_flag_and_nothing_is_written(plant, capsys):
    before = plant.images()
    result = run_cli(capsys, "apply", plant.path, "--auto-approve")
    assert result.code == 1
    assert "releases the axes of booth-a/booth-a-left" in result.err and "nothing was written" in result.err
    assert plant.images() == before
    assert all(s.referenced for e in plant.emulators.values() for s in e.modules().values())


def test_without_a_terminal_apply_needs_auto_approve(plant, capsys):
    result = run_cli(capsys, "apply", plant.path, "--allow-axis-release")
    assert result.code == 1 and "pass --auto-approve" in result.err
    assert not plant.matches_plant()


def test_a_plan_file_is_applied_as_reviewed(plant, capsys, tmp_path):
    assert run_cli(capsys, "plan", plant.path, "--out", tmp_path / "plan.json").code == 0
    result = run_cli(capsys, "apply", plant.path, "--plan", tmp_path / "plan.json", "--auto-approve",
                     "--allow-axis-release")
    assert result.code == 0, result.err
    assert plant.matches_plant()


@pytest.mark.parametrize("endings", [(b"\n", b"\r\n"), (b"\r\n", b"\n")],
                         ids=["made on Linux, applied from Windows", "the other way"])
def test_a_plan_file_applies_from_a_checkout_with_other_line_endings(plant, capsys, tmp_path, endings):
    """CI plans on Linux, the person at the line applies from a Git for Windows checkout (CRLF), and back:
    the same text is the same plant file; one changed byte besides still makes the plan stale."""
    made, applied = endings
    text = plant.path.read_bytes().replace(b"\r\n", b"\n")
    plant.path.write_bytes(text.replace(b"\n", made))
    assert run_cli(capsys, "plan", plant.path, "--out", tmp_path / "plan.json").code == 0
    plant.path.write_bytes(text.replace(b"dwell: 0.5", b"dwell: 0.6", 1).replace(b"\n", applied))
    stale = run_cli(capsys, "apply", plant.path, "--plan", tmp_path / "plan.json", "--auto-approve",
                    "--allow-axis-release")
    assert stale.code == 1 and "stale plan — the plant file" in stale.err
    plant.path.write_bytes(text.replace(b"\n", applied))
    result = run_cli(capsys, "apply", plant.path, "--plan", tmp_path / "plan.json", "--auto-approve",
                     "--allow-axis-release")
    assert result.code == 0, result.err
    assert plant.matches_plant()


def test_a_plan_file_alone_finds_its_plant(plant, capsys, tmp_path):
    run_cli(capsys, "plan", plant.path, "--out", tmp_path / "plan.json")
    result = run_cli(capsys, "apply", "--plan", tmp_path / "plan.json", "--auto-approve",
                     "--allow-axis-release")
    assert result.code == 0, result.err


def test_a_plan_file_with_a_key_given_twice_is_refused_naming_it(plant, capsys, tmp_path):
    """JSON keeps the last of two keys: a reviewer reading the first "steps" would approve others."""
    run_cli(capsys, "plan", plant.path, "--out", tmp_path / "plan.json")
    text = (tmp_path / "plan.json").read_text()
    (tmp_path / "plan.json").write_text(text.replace('"steps": [', '"steps": [], "steps": [', 1))
    before = plant.images()
    result = run_cli(capsys, "apply", plant.path, "--plan", tmp_path / "plan.json", "--auto-approve",
                     "--allow-axis-release")
    assert (result.code, result.problems) == (1, [
        f'error: {tmp_path / "plan.json"}: the key "steps" is given twice in one object — make the '
        'plan again'])
    assert plant.images() == before


def test_a_plan_file_with_its_modules_reordered_is_refused_as_edited(plant, capsys, tmp_path):
    """The order of the modules is the order of the writes: a plan file is applied in the order
    prc3cfg wrote it (the plant file's), and one listing them otherwise was edited."""
    run_cli(capsys, "plan", plant.path, "--out", tmp_path / "plan.json")
    document = json.loads((tmp_path / "plan.json").read_text())
    modules = document["buses"][0]["modules"]
    modules[0], modules[1] = modules[1], modules[0]
    releasing = set(document["axis_releases"])  # listed in the modules' order: edited alike
    document["axis_releases"] = [n for n in (f"{b['name']}/{m['name']}" for b in document["buses"]
                                             for m in b["modules"]) if n in releasing]
    (tmp_path / "plan.json").write_text(json.dumps(document, indent=1))
    before = plant.images()
    result = run_cli(capsys, "apply", plant.path, "--plan", tmp_path / "plan.json", "--auto-approve",
                     "--allow-axis-release")
    assert (result.code, result.problems) == (1, [
        f"error: {tmp_path / 'plan.json'}: bus booth-a, module 2 (booth-a-right) is listed before bus "
        "booth-a, module 1 "
        "(booth-a-left), where prc3cfg writes the modules in the plant file's order — the plan file was "
        "changed after it "
        "was made; nothing was written: plan again and review it"])
    assert plant.images() == before


def unwritable_records(tmp_path, how: str):
    """A plant file (on ports where nothing listens) whose `.prc3cfg/` cannot be made or written."""
    folder = tmp_path / "checkout"
    folder.mkdir()
    plant = folder / "plant.yaml"
    plant.write_text(DEMO.read_text().replace("emulator://demo-a", "socket://127.0.0.1:9")
                     .replace("emulator://demo-b", "socket://127.0.0.1:19"))
    if how == "a file where the folder belongs":
        (folder / ".prc3cfg").write_text("")
    else:
        folder.chmod(0o555)
        if os.access(folder, os.W_OK):  # root writes anyway: the case above is this one's test there
            folder.chmod(0o755)
            pytest.skip("a read-only folder is writable to this user (root)")
    return plant


@pytest.mark.parametrize("how", ["a file where the folder belongs", "a read-only checkout"])
def test_apply_where_its_records_cannot_be_written_is_refused_before_the_line(tmp_path, capsys, how):
    plant = unwritable_records(tmp_path, how)
    try:
        result = run_cli(capsys, "apply", plant, "--auto-approve", "--allow-axis-release")
    finally:
        plant.parent.chmod(0o755)
    records = plant.parent / ".prc3cfg"
    assert result.code == 1, result.err
    (line,) = result.err.splitlines()  # about the folder, not the line: nothing listens on its ports
    where = records if how == "a file where the folder belongs" else plant.parent
    assert line.startswith(f"error: {where}: cannot write there (") and line.endswith(
        f"— apply keeps its snapshots and journal in {records}: make that a writable folder (or free "
        "space), then apply again"), line
    assert "Traceback" not in result.err


def test_stale_plan_refused_after_teach_in(plant, capsys, tmp_path):
    run_cli(capsys, "plan", plant.path, "--out", tmp_path / "plan.json")
    plant.emulators["booth-a"].teach_in(2, 1, 123)
    before = plant.images()
    result = run_cli(capsys, "apply", plant.path, "--plan", tmp_path / "plan.json", "--auto-approve",
                     "--allow-axis-release")
    assert result.code == 1
    assert "stale plan — bus booth-a, module 2 (booth-a-right) changed since the plan was made" in result.err
    assert plant.images() == before


def test_a_plan_of_another_plant_is_refused_as_such_not_as_a_change(plant, capsys, tmp_path):
    """A plan file made from another plant file (another `plant:` name) is not "the plant file changed":
    it names both plants and nothing is sent."""
    run_cli(capsys, "plan", plant.path, "--out", tmp_path / "plan.json")
    other = tmp_path / "other" / "plant.yaml"
    other.parent.mkdir()
    other.write_text(plant.path.read_text().replace("plant: demo-line", "plant: other-line", 1))
    result = run_cli(capsys, "apply", other, "--plan", tmp_path / "plan.json", "--auto-approve",
                     "--allow-axis-release")
    assert result.code == 1 and result.err.count("\n") == 1, result.err
    assert f"the plan of plant demo-line ({plant.path.resolve()}), not of other-line ({other})" in result.err
    assert "changed since" not in result.err and not (other.parent / ".prc3cfg" / "journal").exists()


def test_on_the_embedded_emulator_the_time_says_why_it_is_below_the_estimate(plant, capsys, tmp_path):
    """The embedded emulator answers at once: a 0.2 s apply or restore "estimated 6.0 s" says that the
    estimate is the line's — and does not where the port gives a line speed, at which it answers as a line
    does, nor over a socket."""
    text = ("plant: p\nbuses:\n  - name: line\n    port: emulator://line{query}\n    modules:\n"
            "      - address: 1\n        name: m1\n        programs:\n          1: {{position: "
            "0.3, speed: 0.3}}\n")
    said = ("— the embedded emulator answers at once: the estimate is what a line at the plant file's baud "
            "takes")
    for query, at_once in (("", True), ("?line-speed=38400", False)):
        embedded = tmp_path / f"embedded{len(query)}" / "plant.yaml"
        embedded.parent.mkdir()
        embedded.write_text(text.format(query=query))
        done = run_cli(capsys, "apply", embedded, "--auto-approve")
        assert done.code == 0 and "Time: " in done.out, done.err
        assert (said in done.out) is at_once, done.out
        snapshot = next((embedded.parent / ".prc3cfg" / "snapshots").iterdir())
        restored = run_cli(capsys, "restore", snapshot, "--auto-approve")
        assert restored.code == 0 and "Restore complete" in restored.out, restored.err
        assert (said in restored.out) is at_once, restored.out
    over_a_socket = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
    assert (over_a_socket.code == 0 and "Time: " in over_a_socket.out
            and "embedded emulator" not in over_a_socket.out)


def test_stale_plan_refused_after_plant_file_change(plant, capsys, tmp_path):
    run_cli(capsys, "plan", plant.path, "--out", tmp_path / "plan.json")
    plant.path.write_text(plant.path.read_text().replace("dwell: 0.5", "dwell: 0.6", 1))
    result = run_cli(capsys, "apply", plant.path, "--plan", tmp_path / "plan.json", "--auto-approve",
                     "--allow-axis-release")
    assert result.code == 1 and "stale plan — the plant file" in result.err
    assert not (tmp_path / ".prc3cfg" / "journal").exists()  # refused before any exchange on the line


def test_a_second_apply_on_the_same_line_is_refused(plant, capsys):
    port_line = next(line for line in plant.path.read_text().splitlines() if "socket://" in line)
    port = port_line.split("port:")[1].strip()
    with line_lock(line_keys(port), "another apply"):
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
    assert result.code == 1
    assert "the line is locked by" in result.err and f"pid {os.getpid()}" in result.err
    assert not plant.matches_plant()


def test_an_error_reply_stops_that_module_and_the_others_go_on(plant, capsys):
    plant.emulators["booth-b"].update(3, fault="E21")
    result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
    assert result.code == 1
    assert "bus booth-b, module 3 (booth-b-right): step 1 of" in result.err
    assert ("refused with code 25: operating condition is error E21 (positioning error) — clear "
            "the fault") in result.err
    assert ("written: nothing acknowledged" in result.err
            and "read back: unchanged, as before the apply" in result.err)
    assert "✓ bus booth-b, module 4 (booth-b-pretreat)" in result.out
    assert result.out.count("✓") == 5


def test_snapshot_and_restore(plant, capsys, tmp_path):
    before = plant.images()
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    snapshots = sorted((tmp_path / ".prc3cfg" / "snapshots").iterdir())
    assert len(snapshots) == 1
    snapshot = json.loads(snapshots[0].read_text())
    assert snapshot["plant_sha256"] and len(snapshot["modules"]) == 6
    refused = run_cli(capsys, "restore", snapshots[0], "--auto-approve")
    assert (refused.code == 1
            and "nothing was written; restore again with --allow-axis-release" in refused.err), refused.err
    restored = run_cli(capsys, "restore", snapshots[0], "--auto-approve", "--allow-axis-release")
    assert restored.code == 0, restored.err
    assert ("Restore complete: 6 modules written and verified." in restored.out
            and "Apply complete" not in restored.out)
    after = plant.images()
    for key, image in before.items():
        assert after[key].system == image.system
        for number, program in enumerate(snapshot["modules"][0]["programs"], start=1):
            if program is not None and key == ("booth-a", 1):
                assert after[key].program(number) == image.program(number)


def test_journal_records_every_exchange(plant, capsys, tmp_path):
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    (journal,) = (tmp_path / ".prc3cfg" / "journal").iterdir()
    events = [json.loads(line) for line in journal.read_text().splitlines()]
    exchanges = [e for e in events if e["event"] == "exchange"]
    assert {e["request"][:2] for e in exchanges} >= {"50", "20"}

    def attempts(kind: str) -> list[tuple[str, str, int]]:
        return sorted((e["bus"], e["request"], e["attempt"]) for e in events if e["event"] == kind)

    assert attempts("request") == attempts("exchange")
    # on a loaded machine the emulator may answer after the deadline: the journal says so, and the retry
    # follows
    tried_again = {(e["bus"], e["request"], e["attempt"] - 1) for e in exchanges}
    assert all((e["bus"], e["request"], e["attempt"]) in tried_again for e in exchanges if e["reply"] is None)
    assert any(e["reply"] is not None for e in exchanges)
    assert sum(e["event"] == "result" and e["verified"] for e in events) == 6


@pytest.mark.parametrize("seed", [*range(2),
                                  *(pytest.param(seed, marks=pytest.mark.soak) for seed in range(2, 50))])
def test_apply_converges_under_lost_and_damaged_frames(tmp_path, capsys, seed):
    with emulated_plant(tmp_path, faults=FaultInjection(drop_rate=0.1, corrupt_rate=0.05, seed=seed),
                        timeout=0.05) as plant:
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert result.code == 0, result.err
        assert plant.matches_plant()


@pytest.mark.parametrize("framing", ["open-driver", "stx"])
def test_apply_converges_on_every_framing_under_faults(tmp_path, capsys, framing):
    faults = FaultInjection(drop_rate=0.1, corrupt_rate=0.05, seed=11)
    with emulated_plant(tmp_path, faults=faults, timeout=0.1, framing=framing) as plant:
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert result.code == 0, result.err
        assert plant.matches_plant()


def test_an_apply_killed_half_way_converges_when_run_again(tmp_path):
    """A real process, SIGKILLed once it has started writing to a 9600-baud line, then run again."""
    with emulated_plant(tmp_path, line_speed=True, timeout=0.5) as plant:
        command = [sys.executable, "-m", "prc3cfg", "apply", str(plant.path), "--auto-approve",
                   "--allow-axis-release"]
        env = {**os.environ, "PRC3CFG_LOCK_DIR": str(tmp_path / "locks"), "PYTHONUNBUFFERED": "1"}
        with (tmp_path / "stderr").open("w") as stderr:
            killed = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=stderr, text=True, env=env)
            for line in killed.stdout:
                if line.startswith("Snapshot of the modules before writing"):
                    killed.send_signal(signal.SIGKILL)  # the first writes are on the line
                    break
        assert killed.wait(timeout=60) == -signal.SIGKILL, (tmp_path / "stderr").read_text()
        assert not plant.matches_plant()  # left half-way (a whole apply takes over a second here)
        assert list((tmp_path / "locks").iterdir())  # and its lock behind
        for emulator in plant.emulators.values():
            emulator.line_speed = False  # the kill is made: the run again is about converging, not timing
        again = subprocess.run(command, capture_output=True, text=True, env=env, timeout=120)
        assert again.returncode == 0, again.stderr
        assert plant.matches_plant()


def verification(tmp_path) -> list[str]:
    """The requests after each bus's last write in the newest apply's journal (hex, message only)."""
    newest = sorted((tmp_path / ".prc3cfg" / "journal").iterdir())[-1]
    exchanges = [e for e in map(json.loads, newest.read_text().splitlines()) if e["event"] == "exchange"]
    requests = []
    for bus in sorted({e["bus"] for e in exchanges}):
        on_bus = [e["request"] for e in exchanges if e["bus"] == bus]
        writes = [i for i, r in enumerate(on_bus) if r[:2] not in ("50", "51", "52")]
        requests += on_bus[writes[-1] + 1 :] if writes else []
    return requests


def slow_down_program_3(plant) -> None:
    """The reciprocator profile's program 3 a little slower: a 41h to each module that uses it."""
    document = yaml.safe_load(plant.path.read_text())
    document["profiles"]["reciprocator"]["programs"][3]["speed"] = 0.24
    plant.path.write_text(yaml.safe_dump(document, sort_keys=False))


def test_verification_reads_only_what_the_steps_could_have_changed(plant, capsys, tmp_path):
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    slow_down_program_3(plant)
    assert run_cli(capsys, "apply", plant.path, "--auto-approve").code == 0
    # program 3 of the five modules that take it from the profile
    assert verification(tmp_path) == ["5103"] * 5
    assert plant.matches_plant()


def test_full_verification_reads_the_system_and_every_program(plant, capsys, tmp_path):
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    slow_down_program_3(plant)
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--verify", "full").code == 0
    assert verification(tmp_path).count("5000") == 5


def test_a_system_step_is_verified_with_the_system_block(plant, capsys, tmp_path):
    """On a commissioned module (a factory-fresh one has every managed program verified: test_commissioning),
    a 20h and a 33h are verified by the system block and the programs they wrote."""
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-b-pretreat", "--auto-approve",
                   "--allow-axis-release").code == 0
    document = yaml.safe_load(plant.path.read_text())
    (pretreat,) = [m for bus in document["buses"] for m in bus["modules"] if m["name"] == "booth-b-pretreat"]
    pretreat["system"]["upper_reversing_point"] = 2.0
    pretreat["programs"][1]["position"] = 1.95
    plant.path.write_text(yaml.safe_dump(document, sort_keys=False))
    second = run_cli(capsys, "apply", plant.path, "--module", "booth-b-pretreat", "--auto-approve",
                     "--allow-axis-release")
    assert second.code == 0, second.err
    assert verification(tmp_path) == ["5000", "5101"], second.out  # the system, and program 1 (32h)
