"""What `apply` must not assume (issue 17): that a declaration in a plant file is true, that one yes
covers every later release, that a read cannot become a write, that a killed process leaves
someone who knows — each a test across the real link client and a real emulator, a `LossyProxy`
between them where a frame must be lost, damaged or watched.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from dataclasses import replace
from pathlib import Path

import pytest
from emulated import PLANNED_TRAVEL, emulated_plant, run_cli, travel_list
from lossy import Loss
from test_broadcast import declared, full_line

from prc3cfg.core.device import ModuleState
from prc3cfg.core.framing import Frame
from prc3cfg.shell.emulator.server import Emulator
from prc3cfg.shell.locks import line_keys, line_lock
from prc3cfg.shell.plant_files import load_plant
from prc3cfg.shell.testing import EmulatedPlant


def journal_events(directory: Path) -> list[dict]:
    folder = directory / ".prc3cfg" / "journal"
    return [json.loads(line) for path in sorted(folder.glob("*.jsonl"))
            for line in path.read_text().splitlines()]


def sent(directory: Path) -> list[tuple[int, str]]:
    """(address, request hex) of every exchange the applies under `directory` journalled."""
    return [(e["address"], e["request"]) for e in journal_events(directory) if e["event"] == "exchange"]


def edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new, 1))


# -- 2. consent is per module ----------------------------------------------------------------


def test_a_repair_never_releases_the_axes_of_a_module_the_operator_was_not_asked_about(tmp_path, capsys):
    """The plan releases only booth-a-left; booth-a-right's system block is changed on the floor while the
    apply runs. Its repair would need a 20h: never sent — the module is reported as needing a new plan."""
    armed, floor_changed = False, False

    def floor(frame, _):
        nonlocal floor_changed
        if (armed and frame.address == 2 and frame.message[:1] not in (b"\x50", b"\x51", b"\x52")
            and not floor_changed):
            floor_changed = True  # as booth-a-right's own write goes out, someone changes its S7 on the panel
            emulator = plant.emulators["booth-a"]
            image = emulator.module(2).image
            emulator.update(2, image=replace(image, system=replace(image.system, S7=900)))
        return set()

    with emulated_plant(tmp_path, lossy={"booth-a": floor}) as plant:
        commissioned(plant, capsys)
        edit(plant.path, "name: booth-a-left\n",
             "name: booth-a-left\n    system: {upper_reversing_point: 2.3}\n")
        edit(plant.path, "position: 2.0\n", "position: 1.99\n")  # booth-a-right: a program change only
        before, armed = len(sent(tmp_path)), True
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release", "--verify",
                         "full")
        assert floor_changed
        assert result.code == 1, result.out + result.err
        assert "booth-a-right" in result.err and "plan again" in result.err
        releases = [(a, r) for a, r in sent(tmp_path)[before:] if r[:2] in ("10", "20")]
        # booth-a-left's, agreed to; none to booth-a-right
        assert releases and {a for a, _ in releases} == {1}
        assert plant.emulators["booth-a"].module(2).referenced
        assert plant.emulators["booth-a"].module(2).image.system.S7 == 900


# -- 4. a release is recorded before its frame leaves, and told until an account names it -------


def test_an_apply_killed_after_its_20h_leaves_every_later_command_saying_so_until_an_account_lists_it(
    tmp_path, capsys
):
    fifo = tmp_path / "trace.fifo"
    os.mkfifo(fifo)
    with emulated_plant(tmp_path, line_speed=True, timeout=0.5) as plant:
        process = subprocess.Popen([sys.executable, "-m", "prc3cfg", "apply", str(plant.path),
                                    "--auto-approve",
                                    "--allow-axis-release", "--trace", str(fifo)], text=True,
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        with fifo.open() as trace:
            release: str | None = None
            for line in trace:
                _, bus, direction, frame = line.rstrip("\n").split("\t")[:4]
                # a crc16 request: A5h, address, length, message ID
                if (bus, direction) == ("booth-a", ">") and frame[6:8] == "20":
                    release = frame
                elif release is not None and (bus, direction) == ("booth-a", "<"):
                    process.kill()  # the 20h was answered, so executed: no account will ever be printed
                    frame = release
                    break
            threading.Thread(target=trace.read, daemon=True).start()
            process.wait()
        address = int(frame[2:4], 16)
        name = {1: "booth-a-left", 2: "booth-a-right", 5: "booth-a-top"}[address]
        assert not plant.emulators["booth-a"].module(address).referenced  # it did release the axes
        for emulator in plant.emulators.values():
            emulator.line_speed = False  # the kill is made: what follows is about records, not timing

        planned = run_cli(capsys, "plan", plant.path)
        assert planned.code == 0
        warnings = [line for line in planned.err.splitlines() if "warning" in line]
        # the module whose 20h was seen on the line — and any whose 20h was about to leave when it died
        assert any(f"bus booth-a, module {address} ({name})" in line for line in warnings)
        assert all(f"pid {process.pid}" in line and "may be released" in line for line in warnings)
        port = next(bus.port for bus in load_plant(plant.path).buses if bus.name == "booth-a")
        scanned = run_cli(capsys, "scan", "--port", port, "--timeout", "0.1")
        assert f"bus booth-a, module {address} ({name})" in scanned.err  # no plant file: found by the line

        applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert applied.code == 0, applied.err
        assert f"booth-a/{name} (possibly: an earlier prc3cfg apply, pid {process.pid}" in applied.out
        again = run_cli(capsys, "plan", plant.path)
        assert "warning" not in again.err  # told once in an account: no more


# -- 1. a declaration in a file is not proof -------------------------------------------------


def test_a_module_the_plant_does_not_list_stops_every_broadcast_and_is_named(tmp_path, capsys):
    """The plant lists 28 modules and says they are all; a 29th is on the line. It must hear nothing."""
    source = declared(full_line(tmp_path, modules=28))
    with emulated_plant(tmp_path, source=source, unlisted={"line": [29]}) as plant:
        planned = run_cli(capsys, "plan", plant.path, "--json")
        assert json.loads(planned.out)["buses"][0]["unlisted_modules"] == [29]
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert result.code == 0, result.err
        assert "a module answers at address 29, which the plant file does not list" in result.out
        assert 0 not in {address for address, _ in sent(tmp_path)}  # no broadcast
        stranger = plant.emulators["line"].module(29)
        assert stranger.referenced and stranger == ModuleState.factory(29)  # untouched
        assert plant.matches_plant()


def test_a_reviewed_plan_with_broadcasts_is_refused_once_a_module_the_plant_does_not_list_answers(tmp_path,
                                                                                                  capsys):
    source = declared(full_line(tmp_path, modules=28))
    powered = False  # module 30, which the plant does not list, is switched off while the plan is made
    off = lambda frame, _: {Loss.REQUEST} if frame.address == 30 and not powered else set()  # noqa: E731
    with emulated_plant(tmp_path, source=source, unlisted={"line": [30]}, lossy={"line": off}) as plant:
        made = tmp_path / "plan.json"
        assert run_cli(capsys, "plan", plant.path, "--out", made).code == 0
        document = json.loads(made.read_text())
        assert document["buses"][0]["broadcasts"] and document["buses"][0]["proven_silent"] == [29, 30]
        powered = True
        refused = run_cli(capsys, "apply", plant.path, "--plan", made, "--auto-approve",
                          "--allow-axis-release")
        assert refused.code == 1
        assert "stale plan — on bus line a module now answers at address 30" in refused.err
        assert not [r for _, r in sent(tmp_path) if r[:2] not in ("50", "51", "52")]  # nothing written


# -- 3. on a line without error detection a read can become a write -----------------------------

#: open-driver ends a frame by the gap ZVZ, waited after every frame at each end: 8 ms (over seven characters
#: at 9600 8N1) rather than the default 20 ms, so a test's hundreds of exchanges take half the time.
UNCHECKED = {"framing": "open-driver", "parity": "none", "accept_undetected_damage": True, "zvz": 0.008}


class Once:
    """A `LossyProxy` rule: once `armed`, the next request with message ID `message_id` to `address`
    suffers `loss` — then nothing more."""

    def __init__(self, address: int, message_id: int, loss: Loss) -> None:
        self.address, self.message_id, self.loss, self.armed = address, message_id, loss, False

    def __call__(self, frame: Frame, _: int) -> set[Loss]:
        if self.armed and frame.address == self.address and frame.message[0] == self.message_id:
            self.armed = False
            return {self.loss}
        return set()


def commissioned(plant: EmulatedPlant, capsys: pytest.CaptureFixture) -> None:
    """The plant applied from factory modules, and every module of booth-a travelled to its reference
    point."""
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    for address in (1, 2, 5):
        plant.emulators["booth-a"].update(address, referenced=True)


def test_apply_on_a_line_without_error_detection_needs_the_risk_accepted_in_the_plant_file(tmp_path, capsys):
    with emulated_plant(tmp_path, framing="open-driver", parity="none") as plant:
        refused = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert refused.code == 1
        (line,) = refused.err.splitlines()
        assert "bus booth-a: open-driver with parity none detects no damage" in line
        assert "parity: even" in line and "accept_undetected_damage: true" in line
        assert not (tmp_path / ".prc3cfg" / "journal").exists()  # the line was not touched


def test_a_read_the_module_executes_as_a_10h_is_a_possible_release_never_accepted(tmp_path, capsys):
    """The first 50h to booth-a-right arrives as 10h: the module goes to factory defaults and answers
    "accepted". The plan stops in one line; every later command says the module may be released."""
    flip = Once(2, 0x50, Loss.AS_INIT)
    with emulated_plant(tmp_path, lossy={"booth-a": flip}, **UNCHECKED) as plant:
        commissioned(plant, capsys)
        flip.armed = True
        planned = run_cli(capsys, "plan", plant.path)
        assert planned.code == 1
        assert "bus booth-a, module 2: a read (50h) was answered as a write is" in planned.err
        assert not plant.emulators["booth-a"].module(2).referenced  # it did execute a 10h
        again = run_cli(capsys, "plan", plant.path)
        assert ("bus booth-a, module 2 (booth-a-right): prc3cfg plan" in again.err
                and "may be released" in again.err)
        applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert applied.code == 0, applied.err
        assert "booth-a/booth-a-right" in travel_list(applied.out)


def test_a_write_whose_address_became_the_broadcast_is_found_on_every_module_of_the_line(tmp_path, capsys):
    """Booth-a-left's 20h arrives at address 0: booth-a-right and booth-a-top take its system block and
    release their axes. Their own steps never touched the system: they are read all the same, and named."""
    flip = Once(1, 0x20, Loss.TO_BROADCAST)
    with emulated_plant(tmp_path, lossy={"booth-a": flip}, **UNCHECKED) as plant:
        commissioned(plant, capsys)
        edit(plant.path, "name: booth-a-left\n", "name: booth-a-left\n    system: {circuit_gain: 900}\n")
        flip.armed = True
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert (not plant.emulators["booth-a"].module(2).referenced
                and not plant.emulators["booth-a"].module(5).referenced)
        assert result.code == 1, result.out
        travel = travel_list(result.out)
        assert ("booth-a/booth-a-left" in travel and "booth-a/booth-a-right" in travel
                and "booth-a/booth-a-top" in travel)
        assert not [line for line in result.out.splitlines() if "✓ bus booth-a, module 2" in line
                    or "✓ bus booth-a, module 5" in line]
        assert ("✗ bus booth-a, module 2 (booth-a-right): the read-back shows other system "
                "parameters") in result.err
        differs = [line for line in result.err.splitlines()
                   if "read back, it differs from the plant file:" in line]
        assert len(differs) == 2 and all("circuit gain" in line for line in differs)
        assert "✓ bus booth-b" not in result.out  # no release on that line: nothing to watch for


def test_a_verifying_read_executed_as_a_10h_stops_the_line_and_names_the_module(tmp_path, capsys):
    """Booth-a-right's verifying read arrives as 10h: nothing more is sent on booth-a, the module is on
    the reference-travel list, and no module of the line is called verified after it."""
    armed, written, after = False, False, []

    def flip(frame, _):
        nonlocal armed, written
        if after:
            after.append(frame)
        written |= armed and frame.address == 2 and frame.message[0] < 0x50  # its write has gone out
        if written and frame.address == 2 and frame.message[:1] in (b"\x51", b"\x52"):
            armed = written = False
            after.append(frame)
            return {Loss.AS_INIT}
        return set()

    with emulated_plant(tmp_path, lossy={"booth-a": flip}, **UNCHECKED) as plant:
        commissioned(plant, capsys)
        edit(plant.path, "position: 2.0\n", "position: 1.99\n")  # booth-a-right: a program change only
        armed = True
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert after, "the verifying read was never sent"
        assert result.code == 1
        assert "booth-a/booth-a-right" in travel_list(result.out)
        assert ("✗ bus booth-a, module 2 (booth-a-right): bus booth-a, module 2: a read (51h) was answered "
                "as a write is") in result.err \
            or "a read (52h) was answered as a write is" in result.err
        # afterwards: its system block read, nothing else
        assert [f.message[:1] for f in after[1:]] == [b"\x50"] * len(after[1:])


# -- 7. a module in RUN ---------------------------------------------------------------------


def test_a_running_module_is_told_to_stop_and_left_out_never_written_in_a_loop(tmp_path, capsys):
    with emulated_plant(tmp_path) as plant:
        plant.emulators["booth-a"].update(2, mode="run", active_program=1)
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert result.code == 1
        (line,) = [line for line in result.err.splitlines() if line.startswith("✗")]
        assert line.startswith("✗ bus booth-a, module 2 (booth-a-right): running: step 1 of ")
        assert line.endswith("— stop it (STOP and AUTOMATIC) and apply again")
        writes_to_2 = [r for a, r in sent(tmp_path) if a == 2 and r[:2] not in ("50", "51", "52")]
        assert len(writes_to_2) == 1  # refused once, never again, its other steps left out
        assert plant.emulators["booth-a"].module(2).image == ModuleState.factory(2).image
        assert "✓ bus booth-a, module 1 (booth-a-left)" in result.out  # the others go on


# -- 8. a module in E12 ----------------------------------------------------------------------


def test_a_module_in_e12_is_given_its_system_parameters_by_the_next_plan_gated_and_saying_why(tmp_path,
                                                                                              capsys):
    with emulated_plant(tmp_path) as plant:
        commissioned(plant, capsys)
        emulator = plant.emulators["booth-a"]
        # its system parameters read back as the plant file's, yet it is in E12
        emulator.update(2, fault="E12")
        edit(plant.path, "position: 2.0\n", "position: 1.99\n")  # booth-a-right: a program change only
        first = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert first.code == 1
        assert ("the module is in E12 (system parameters not set), which only a 10h/20h clears — "
                "plan again") in first.err
        assert emulator.module(2).referenced  # nothing released without asking

        planned = run_cli(capsys, "plan", plant.path)
        assert ("it reported E12 (system parameters not set), which only this clears (20h)  ⚠ "
                "RELEASES AXES") in planned.out
        assert travel_list(planned.out, PLANNED_TRAVEL) == f"⚠ {PLANNED_TRAVEL} booth-a/booth-a-right"
        refused = run_cli(capsys, "apply", plant.path, "--auto-approve")
        # gated like any release
        assert refused.code == 1 and "the plan releases the axes of booth-a/booth-a-right" in refused.err
        second = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert second.code == 0, second.err
        assert emulator.module(2).fault is None and plant.matches_plant()
        assert "No changes" in run_cli(capsys, "plan", plant.path).out  # cleared: no 20h for nothing


# -- 9. firmware without read messages -------------------------------------------------------


def test_a_module_whose_firmware_has_no_read_messages_is_said_so_once_not_blamed_on_the_line(tmp_path,
                                                                                             capsys):
    asked: list[bytes] = []

    def count(frame, _):
        if frame.address == 2:
            asked.append(frame.message)
        return set()

    with emulated_plant(tmp_path, lossy={"booth-a": count}) as plant:
        plant.emulators["booth-a"].update(2, read_messages=False)  # PRC 3 before firmware 3.03.1
        result = run_cli(capsys, "plan", plant.path)
        assert result.code == 1
        (line,) = result.problems
        assert (line == "error: bus booth-a, module 2: answers 50h as an unknown message — its firmware has "
                        "no read messages (they came with PRC 3.03.1), so prc3cfg can neither plan nor "
                        "verify it: update the module's firmware")
        assert asked == [bytes([0x50, 0])]  # asked once: a checksum passed, so it is no damage


# -- 5. a wait for the line does not apply the file as it was before the wait --------------------


def test_an_apply_that_waited_for_the_line_refuses_a_plant_file_edited_meanwhile(tmp_path):
    with emulated_plant(tmp_path) as plant:
        port = next(bus.port for bus in load_plant(plant.path).buses if bus.name == "booth-a")
        with line_lock(line_keys(port), "another apply"):
            process = subprocess.Popen([sys.executable, "-m", "prc3cfg", "apply", str(plant.path),
                                        "--auto-approve",
                                        "--allow-axis-release", "--lock-timeout", "600"], text=True,
                                       stdout=subprocess.PIPE, stderr=subprocess.PIPE)
            assert "waiting for the line lock held by" in process.stderr.readline()
            edit(plant.path, "position: 2.0\n", "position: 1.99\n")  # adopt, or an editor, while it waits
        out, err = process.communicate(timeout=120)
    assert process.returncode == 1, out + err
    assert err.splitlines()[-1] == (f"error: {plant.path}: the plant file changed while this command waited "
                                    "for the line — "
                                    "nothing was read or written: run it again, with the file as it is now")
    assert not (tmp_path / ".prc3cfg" / "journal").exists()
    assert all(state.image == ModuleState.factory(a).image
               for a, state in plant.emulators["booth-a"].modules().items())


# -- 6. a snapshot goes back onto the line it was taken on --------------------------------------


def test_restore_refuses_a_snapshot_of_one_line_onto_another_unless_told(tmp_path, capsys):
    with emulated_plant(tmp_path) as plant, Emulator({a: ModuleState.factory(a) for a in (1, 2, 5)}) as other:
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
        (snapshot,) = (tmp_path / ".prc3cfg" / "snapshots").iterdir()
        host, port = other.listen("127.0.0.1", 0)
        old_port = next(bus.port for bus in load_plant(plant.path).buses if bus.name == "booth-a")
        edit(plant.path, old_port, f"socket://{host}:{port}")  # the plant's booth-a now names another line
        refused = run_cli(capsys, "restore", snapshot, "--auto-approve", "--allow-axis-release")
        assert refused.code == 1
        assert refused.problems == [
            f"error: {snapshot}: taken on bus booth-a at {old_port} (crc16), which the plant file now puts "
            f"at socket://{host}:{port} "
            "(crc16) — restoring there would write one line's modules onto another; nothing was "
            "written: give "
            "--onto-current-lines if that is what you mean"]
        assert all(s.image == ModuleState.factory(a).image for a, s in other.modules().items())
        told = run_cli(capsys, "restore", snapshot, "--auto-approve", "--allow-axis-release",
                       "--onto-current-lines")
        assert told.code == 0, told.err
