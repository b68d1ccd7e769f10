"""Each line written as soon as its own plan is whole: with no question between the plan and the
writes (`--auto-approve --allow-axis-release`), a short line is written while a long one is still
read back — from the frame trace of a real apply on emulated 9600-baud lines. With a question, the
whole plant is read and planned first, for a person to review."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from emulated import emulated_plant, run_cli
from lossy import Loss, Rule

from prc3cfg import api
from prc3cfg.core.device import ModuleState
from prc3cfg.core.framing import Frame
from prc3cfg.shell import pending_records
from prc3cfg.shell.plant_files import load_plant
from prc3cfg.shell.sessions import bus_line_keys
from prc3cfg.shell.testing import EmulatedPlant

MODULE = """\
      - address: {address}
        name: {bus}-{address}
        programs:
          1: {{position: 0.1{address}0, speed: 0.300}}
          2: {{position: 0.0{address}0, speed: 0.300}}
"""
PLANT = """\
plant: by-line
buses:
  - name: long
    port: emulator://long
    framing: crc16
    modules:
{long}
  - name: short
    port: emulator://short
    framing: crc16
    modules:
{short}
"""


def two_lines(directory: Path) -> Path:
    """A plant of a line of six modules and a line of one."""
    source = directory / "source.yaml"
    source.write_text(PLANT.format(long="".join(MODULE.format(address=a, bus="long") for a in range(1, 7)),
                                   short=MODULE.format(address=1, bus="short")))
    return source


def requests(trace: Path) -> list[tuple[str, bool]]:
    """Each request of a trace in order: its bus, and whether it writes (a crc16 frame: A5h, address,
    length, message ID — a write is below 50h)."""
    found = []
    for line in trace.read_text().splitlines():
        _, bus, direction, frame = line.split("\t")[:4]
        if direction == ">":
            found.append((bus, int(frame[6:8], 16) < 0x50))
    return found


def test_a_line_is_written_while_another_is_still_read_when_no_question_stands_between(tmp_path, capsys):
    trace = tmp_path / "apply.trace"
    with emulated_plant(tmp_path, source=two_lines(tmp_path), line_speed=True, timeout=0.5) as plant:
        applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release", "--trace",
                          trace)
        assert applied.code == 0, applied.err
        assert plant.matches_plant()
    sent = requests(trace)
    first_write = next(i for i, (bus, write) in enumerate(sent) if bus == "short" and write)
    last_read = max(i for i, (bus, write) in enumerate(sent) if bus == "long" and not write and i < min(
        j for j, (b, w) in enumerate(sent) if b == "long" and w))
    assert first_write < last_read, "the short line waited for the long line's read-back"
    assert ("Snapshot of the modules before writing" in applied.out
            and "Apply complete: 7 modules written and verified." in applied.out)


def test_with_a_question_every_line_is_read_and_planned_before_the_first_write(tmp_path):
    shown = []
    with open(tmp_path / "apply.trace", "w") as trace, emulated_plant(tmp_path, source=two_lines(tmp_path),
                                                                      line_speed=True,
                                                                     timeout=0.5) as plant:
        gates = api.Gates(show=shown.append, allow_axis_release=True, approve=lambda _: True)
        result = api.apply(plant.plant, gates=gates,
                           options=api.LineOptions(trace=trace))
    assert result.verified and len(shown) == 1 and len(shown[0].changes) == 7
    sent = requests(tmp_path / "apply.trace")
    first_write = next(i for i, (_, write) in enumerate(sent) if write)
    assert (all(not write for _, write in sent[:first_write])
            and {bus for bus, _ in sent[:first_write]} == {"long", "short"})
    # every module of the long line read first
    assert sum(not write for bus, write in sent[:first_write] if bus == "long") >= 6


# -- a line whose read-back fails while another is written ------------------------------------

SYSTEM = "name: {bus}-{address}\n        system: {{upper_reversing_point: 2.3}}\n"


def releasing_lines(directory: Path) -> Path:
    """`two_lines`, every module given a system change: each plan releases axes (a 20h)."""
    source = two_lines(directory)
    text = source.read_text()
    for bus, addresses in (("long", range(1, 7)), ("short", [1])):
        for address in addresses:
            text = text.replace(f"name: {bus}-{address}\n", SYSTEM.format(bus=bus, address=address))
    source.write_text(text)
    return source


def refused_after_the_short_line_wrote() -> tuple[dict[str, Rule], threading.Event]:
    """Lossy rules: the long line's read of its last module (a 50h to address 6) is answered with an
    error code — once the short line's first write has left, which the read waits for."""
    writing = threading.Event()

    def short(frame: Frame, _: int) -> set[Loss]:
        if frame.message[0] < 0x50:
            writing.set()
        return set()

    def long(frame: Frame, _: int) -> set[Loss]:
        if frame.address == 6 and frame.message[:1] == b"\x50":
            # the short line's write is on its way: never a race with the long line's read-back
            writing.wait(60)
            return {Loss.REFUSAL}
        return set()

    return {"short": short, "long": long}, writing


def written_and_untouched(plant: EmulatedPlant) -> None:
    """The short line's module holds the plant file; the long line's modules their factory images."""
    desired = load_plant(plant.path)
    (short,) = [m for bus, m in desired.modules() if bus.name == "short"]
    held = plant.emulators["short"].module(1).image
    assert (held.system == short.desired_image().system
            and held.programs[:2] == short.desired_image().programs[:2])
    for address in range(1, 7):
        held = plant.emulators["long"].module(address).image
        assert held == ModuleState.factory(address).image, f"long/{address} was written"


def test_a_line_whose_read_back_fails_is_not_written_and_the_other_is_written_and_verified(tmp_path, capsys):
    rules, writing = refused_after_the_short_line_wrote()
    with emulated_plant(tmp_path, source=releasing_lines(tmp_path), line_speed=True, timeout=0.5,
                        lossy=rules) as plant:
        applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert writing.is_set()
        written_and_untouched(plant)
    assert applied.code == 1, applied.out + applied.err
    errors = [line for line in applied.err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, applied.err
    assert "bus long, module 6 (long-6): read 50h refused with code 32" in errors[0]
    assert "nothing was written on bus long" in errors[0] and "prc3cfg restore" in errors[0]
    assert "✓ bus short, module 1 (short-1)" in applied.out
    events = [json.loads(line) for path in (tmp_path / ".prc3cfg" / "journal").iterdir()
              for line in path.read_text().splitlines()]
    assert [e["modules"] for e in events if e["event"] == "apply"] == [["short/1"]]
    assert [(e["bus"], e["address"], e["verified"]) for e in events
            if e["event"] == "result"] == [("short", 1, True)]
    writes = {(e["bus"], e["address"]) for e in events if e["event"] == "exchange"
              and int(e["request"][:2], 16) < 0x50}
    assert writes == {("short", 1)}
    (snapshot,) = (tmp_path / ".prc3cfg" / "snapshots").iterdir()
    assert [(m["bus"], m["address"]) for m in json.loads(snapshot.read_text())["modules"]] == [("short", 1)]


def test_the_release_records_of_a_line_read_back_in_part_hold_exactly_the_releases_sent(tmp_path):
    rules, _ = refused_after_the_short_line_wrote()
    with emulated_plant(tmp_path, source=releasing_lines(tmp_path), line_speed=True, timeout=0.5,
                        lossy=rules) as plant:
        with pytest.raises(api.ApplyFailed) as failed:
            api.apply(plant.plant, gates=api.Gates(allow_axis_release=True))
        written_and_untouched(plant)
        keys = {bus.name: bus_line_keys(plant.plant, bus) for bus in plant.plant.buses}
        result = failed.value.result
        assert [(r.bus, r.address) for r in result.runs] == [("short", 1)] and result.runs[0].verified
        assert (len(result.unread) == 1
                and result.unread[0].startswith("bus long, module 6 (long-6): read 50h refused"))
        assert [(r.bus, r.address) for r in pending_records.of_line(keys["short"])] == [("short", 1)]
        assert pending_records.of_line(keys["long"]) == []
        api.told(result)
        assert pending_records.of_line(keys["short"]) == []


def test_ctrl_c_while_one_line_writes_and_the_other_still_reads_says_which_line_was_not_written(tmp_path):
    """SIGINT as the short line's first write leaves, the long line held at its last module's read
    until the signal is sent: the apply stops, the account names the long line as not written."""
    fifo = tmp_path / "trace.fifo"
    os.mkfifo(fifo)
    signalled = threading.Event()

    def long(frame: Frame, _: int) -> set[Loss]:
        if frame.address == 6 and frame.message[:1] == b"\x50":
            signalled.wait(60)  # the long line is still reading when the signal comes
        return set()

    with emulated_plant(tmp_path, source=two_lines(tmp_path), line_speed=True, timeout=0.5,
                        lossy={"long": long}) as plant:
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        process = subprocess.Popen([sys.executable, "-m", "prc3cfg", "apply", str(plant.path),
                                    "--auto-approve", "--allow-axis-release",
                                    "--trace", str(fifo)], env=env, text=True, stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE)
        with fifo.open() as trace:
            for line in trace:
                _, bus, direction, frame = line.rstrip("\n").split("\t")[:4]
                # crc16: A5h, address, length, ID
                if (bus, direction) == ("short", ">") and int(frame[6:8], 16) < 0x50:
                    process.send_signal(signal.SIGINT)
                    signalled.set()
                    break
            threading.Thread(target=trace.read, daemon=True).start()
            out, err = process.communicate()
        for address in range(1, 7):
            held = plant.emulators["long"].module(address).image
            assert held == ModuleState.factory(address).image, f"long/{address} was written"
    assert process.returncode == 130, err
    assert err.splitlines()[-1] == "error: interrupted"
    assert ("bus long: interrupted before its read-back and plan were whole — nothing was "
            "written on it") in err.splitlines()
    first = next(line for line in (out + err).splitlines() if line.startswith(("✓ bus", "✗ bus")))
    assert first.startswith(("✓ bus short", "✗ bus short"))
    assert "Interrupted: " in out
    events = [json.loads(line) for path in (tmp_path / ".prc3cfg" / "journal").iterdir()
              for line in path.read_text().splitlines()]
    assert events[-1]["event"] == "interrupted"
    assert {e["bus"] for e in events if e["event"] == "exchange"
            and int(e["request"][:2], 16) < 0x50} == {"short"}


class _Events:
    """A frame trace (`LineOptions.trace`) that keeps every line beside the plans shown, in the order they
    came."""

    def __init__(self) -> None:
        self.events: list[tuple[str, ...]] = []

    def write(self, text: str) -> int:
        for line in text.splitlines():
            _, bus, direction, frame = line.split("\t")[:4]
            if direction == ">":
                self.events.append(("frame", bus, frame[6:8]))  # crc16: A5h, address, length, message ID
        return len(text)

    def flush(self) -> None:
        pass


def test_each_lines_plan_is_shown_before_its_first_write_also_without_a_question(tmp_path):
    """`--auto-approve --allow-axis-release`: a line is written as soon as its own plan is whole, and that
    plan — its 20h marked — is shown before the line's first write, not once every line is planned."""
    trace = _Events()
    with emulated_plant(tmp_path) as plant:

        def shown(line_plan) -> None:
            trace.events.append(("shown", line_plan.modules[0].bus, *(c.bus for c in line_plan.modules)))

        gates = api.Gates(show=lambda _: None, allow_axis_release=True, show_line=shown)
        result = api.apply(api.load(plant.path), gates=gates,
                           options=api.LineOptions(trace=trace))  # type: ignore[arg-type]
        api.told(result)
    events = trace.events
    for bus in ("booth-a", "booth-b"):
        showing = [i for i, e in enumerate(events) if e[0] == "shown" and e[1] == bus]
        writes = [i for i, e in enumerate(events) if e[0] == "frame" and e[1] == bus
                  and e[2] not in ("50", "51", "52")]
        assert len(showing) == 1 and writes and showing[0] < writes[0], events
        assert set(events[showing[0]][1:]) == {bus}  # that line's modules only
