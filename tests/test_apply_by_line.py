"""Each line written as soon as its own plan is whole: with no question between the plan and the
writes (`--auto-approve --allow-axis-release`), a short line is written while a long one is still
read back — from the frame trace of a real apply on emulated 9600-baud lines. With a question, the
whole plant is read and planned first, for a person to review."""

from __future__ import annotations

from pathlib import Path

from emulated import emulated_plant, run_cli

from prc3cfg import api

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
                                   short=MODULE.format(address=1, bus="short")))  # fmt: skip
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
        applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release", "--trace", trace)
        assert applied.code == 0, applied.err
        assert plant.matches_plant()
    sent = requests(trace)
    first_write = next(i for i, (bus, write) in enumerate(sent) if bus == "short" and write)
    last_read = max(i for i, (bus, write) in enumerate(sent) if bus == "long" and not write and i < min(
        j for j, (b, w) in enumerate(sent) if b == "long" and w))  # fmt: skip
    assert first_write < last_read, "the short line waited for the long line's read-back"
    assert "Snapshot of the modules before writing" in applied.out and "Apply complete: 7 modules written and verified." in applied.out


def test_with_a_question_every_line_is_read_and_planned_before_the_first_write(tmp_path):
    shown = []
    with open(tmp_path / "apply.trace", "w") as trace, emulated_plant(tmp_path, source=two_lines(tmp_path), line_speed=True,
                                                                     timeout=0.5) as plant:  # fmt: skip
        result = api.apply(plant.plant, gates=api.Gates(show=shown.append, allow_axis_release=True, approve=lambda _: True),
                           options=api.LineOptions(trace=trace))  # fmt: skip
    assert result.verified and len(shown) == 1 and len(shown[0].changes) == 7
    sent = requests(tmp_path / "apply.trace")
    first_write = next(i for i, (_, write) in enumerate(sent) if write)
    assert all(not write for _, write in sent[:first_write]) and {bus for bus, _ in sent[:first_write]} == {"long", "short"}
    assert sum(not write for bus, write in sent[:first_write] if bus == "long") >= 6  # every module of the long line read first
