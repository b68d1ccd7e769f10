"""What `apply` must not assume (issue 17): that a declaration in a plant file is true, that one yes
covers every later release, that a read cannot become a write, that a killed process leaves
someone who knows — each a test across the real link client and a real emulator, a `LossyProxy`
between them where a frame must be lost, damaged or watched.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from emulated import emulated_plant, run_cli

TRAVEL = "Travel to reference point required before production on:"


def journal_events(directory: Path) -> list[dict]:
    folder = directory / ".prc3cfg" / "journal"
    return [json.loads(line) for path in sorted(folder.glob("*.jsonl")) for line in path.read_text().splitlines()]


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
        if armed and frame.address == 2 and frame.message[:1] not in (b"\x50", b"\x51", b"\x52") and not floor_changed:
            floor_changed = True  # as booth-a-right's own write goes out, someone changes its S7 on the panel
            emulator = plant.emulators["booth-a"]
            image = emulator.module(2).image
            emulator.update(2, image=replace(image, system=replace(image.system, S7=900)))
        return set()

    with emulated_plant(tmp_path, lossy={"booth-a": floor}) as plant:
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
        for address in (1, 2, 5):
            plant.emulators["booth-a"].update(address, referenced=True)  # travelled to the reference point
        edit(plant.path, "name: booth-a-left\n", "name: booth-a-left\n    system: {upper_reversing_point: 2.3}\n")
        edit(plant.path, "position: 2.0\n", "position: 1.99\n")  # booth-a-right: a program change only
        before, armed = len(sent(tmp_path)), True
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release", "--verify", "full")
        assert floor_changed
        assert result.code == 1, result.out + result.err
        assert "booth-a-right" in result.err and "plan again" in result.err
        releases = [(a, r) for a, r in sent(tmp_path)[before:] if r[:2] in ("10", "20")]
        assert releases and {a for a, _ in releases} == {1}  # booth-a-left's, agreed to; none to booth-a-right
        assert plant.emulators["booth-a"].module(2).referenced
        assert plant.emulators["booth-a"].module(2).image.system.S7 == 900
