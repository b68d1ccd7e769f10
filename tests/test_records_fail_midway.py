"""A disk that refuses the apply's records midway (full, over a quota): the apply stops before its
next frame on every line and says exactly what each module was sent — never a traceback, never a
frame that left without its record.

The refusal is real: the apply runs as its own process with a file-size limit (RLIMIT_FSIZE, the
kernel's EFBIG — what a full disk's ENOSPC is to the code: an OSError from a write) set a few
frames past the journal's size when the first write goes out, before every module was sent one,
measured on a twin line first.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import resource
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from emulated import emulated_plant, run_cli, travel_list

from prc3cfg.core.image import ModuleImage
from prc3cfg.shell.testing import EmulatedPlant

pytestmark = pytest.mark.skipif(not hasattr(resource, "RLIMIT_FSIZE"),
                                reason="no file-size limit on this system")


#: The link's reply time-out: long enough that a busy machine repeats no exchange — a repeat makes one
#: journal longer than its twin's, and the limit measured on one would fall outside the other's writes.
UNHURRIED = 2.0


def journal_of(directory: Path) -> Path:
    (journal,) = (directory / ".prc3cfg" / "journal").glob("*.jsonl")
    return journal


def twin_journal(tmp_path: Path, capsys: pytest.CaptureFixture) -> list[bytes]:
    """The records of a whole apply of a twin line."""
    twin = tmp_path / "twin"
    twin.mkdir()
    with emulated_plant(twin, timeout=UNHURRIED) as plant:
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    return journal_of(twin).read_bytes().splitlines(keepends=True)


def read_backs(records: list[bytes]) -> tuple[int, dict[str, int], int]:
    """The journal's header, each line's records before its first write (its read-back: a line's own
    records come in the same order whatever turns the lines' threads take, the lines' records
    interleaved as they do), and the snapshot and `apply` records that come before a line's first write."""
    header, lines, before = len(records[0]), {}, 0
    writing: set[str] = set()
    for raw in records[1:]:
        entry = json.loads(raw)
        if entry.get("event") in ("snapshot", "apply") and not writing:
            before += len(raw)
        elif entry.get("event") in ("request", "exchange") and entry["bus"] not in writing:
            if entry.get("event") == "request" and not entry["request"].startswith(("50", "51", "52")):
                writing.add(entry["bus"])
            else:
                lines[entry["bus"]] = lines.get(entry["bus"], 0) + len(raw)
    return header, lines, before


def limit_within_the_writes(tmp_path: Path, capsys: pytest.CaptureFixture) -> int:
    """A size the journal passes a few frames after the first write went out, whatever turns the lines'
    threads take: past every line's read-back and the first line's snapshot and `apply`, and 1,500
    bytes more — the first frame's records (about 500 bytes), a few more at most (the records' lengths
    vary by a byte or two with the times in them)."""
    header, lines, before = read_backs(twin_journal(tmp_path, capsys))
    return header + sum(lines.values()) + before + 1500


def limited_apply(path: Path, size: int) -> subprocess.CompletedProcess[str]:
    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (size, size))

    return subprocess.run([sys.executable, "-m", "prc3cfg", "apply", str(path), "--auto-approve",
                           "--allow-axis-release"],
                          preexec_fn=limit, capture_output=True, text=True, timeout=120)


@contextlib.contextmanager
def refused_apply(tmp_path: Path, size: int) -> Iterator[tuple[EmulatedPlant, dict,
                                                               subprocess.CompletedProcess[str], str]]:
    """An apply of a fresh line (its folder `line`) whose journal the disk refuses past `size` bytes: it
    ended with exit 1, no traceback, and an error naming the journal it could not keep. The plant (still
    emulated), its images before, the apply's result and its last line."""
    line = tmp_path / "line"
    line.mkdir()
    with emulated_plant(line, timeout=UNHURRIED) as plant:
        factory = plant.images()
        result = limited_apply(plant.path, size)
        assert result.returncode == 1, result.stderr
        assert "Traceback" not in result.stdout + result.stderr
        error = result.stderr.strip().splitlines()[-1]
        assert (error.startswith("error: could not keep the journal ")
                and journal_of(line).name in error), error
        yield plant, factory, result, error


def test_a_journal_the_disk_refuses_midway_stops_every_line_before_its_next_frame_with_an_exact_account(
    tmp_path, capsys
):
    with refused_apply(tmp_path, limit_within_the_writes(tmp_path, capsys)) as (plant, factory, result,
                                                                                error):
        assert "every line stopped before its next frame" in error and "prc3cfg restore " in error
        held = plant.images()
        # what each module was told to have been sent is what it holds
        # (none where one line was written whole and verified while the other still read back)
        accounts = {block.split(" (", 1)[0]: block for block in result.stderr.split("✗ ")[1:]}
        desired = {(bus.name, m.address): m.desired_image() for bus, m in plant.plant.modules()}
        nothing_sent, all_acknowledged = set(), set()
        for (bus, address), image in held.items():
            account = accounts.get(f"bus {bus}, module {address}")
            if f"✓ bus {bus}, module {address} " in result.stdout:  # verified before the refusal
                assert matches(image, desired[(bus, address)])
                continue
            if account is None:  # not in the account (its line was still reading back): not touched
                assert image == factory[(bus, address)]
                nothing_sent.add((bus, address))
                continue
            if ("nothing was sent to it" in account
                or "stopped (a record could not be kept) before step 1 of" in account):
                nothing_sent.add((bus, address))
                assert image == factory[(bus, address)], account
            elif (done := re.search(r"verifying: (\d+) of (\d+) steps? acknowledged",
                                    account)) and done[1] == done[2]:
                all_acknowledged.add((bus, address))
                assert matches(image, desired[(bus, address)]), account
        assert nothing_sent, "the limit stopped no module before its first frame"
        assert any(image != factory[key] for key, image in held.items()), ("the limit stopped every module "
                                                                           "before its first frame")
        # the travel list names exactly the modules whose system block a 20h changed (none: no list)
        travel = travel_list(result.stdout)
        released = {key for key, image in held.items() if image.system != factory[key].system}
        names = {(bus.name, m.address): f"{bus.name}/{m.name}" for bus, m in plant.plant.modules()}
        said = sorted(name.strip() for name in travel.split(": ", 1)[1].split(",")) if travel else []
        assert said == sorted(names[key] for key in released), travel
        # the journal holds every frame that left: each module that holds anything new has its requests in it
        requested = set()
        for raw in journal_of(tmp_path / "line").read_bytes().splitlines():
            try:
                entry = json.loads(raw)
            except ValueError:
                continue  # the record the limit cut
            if entry.get("event") == "request" and not entry["request"].startswith(("50", "51", "52")):
                requested.add((entry["bus"], entry["address"]))
        assert {key for key, image in held.items() if image != factory[key]} <= requested
        # nothing stays vouched for: with room on the disk, the next apply finds the rest and finishes
        again = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert again.code == 0, again.err
        assert "Apply complete" in again.out and plant.matches_plant()


def test_a_journal_the_disk_refuses_while_the_modules_are_read_back_is_said_so_not_an_interruption(tmp_path,
                                                                                                   capsys):
    """The limit half way through the read-back of the line with the shorter one (measured on a twin): before
    any line's first write. The read whose record was refused stays back, nothing is written, and the apply
    says it could not keep its journal — it said "error: interrupted", exit 130, as if Ctrl-C."""
    header, lines, _ = read_backs(twin_journal(tmp_path, capsys))
    size = header + min(lines.values()) // 2  # before any line's first write, whichever line reads back first
    with refused_apply(tmp_path, size) as (plant, factory, _, error):
        assert "while the modules were read back — nothing was written to any module" in error, error
        assert plant.images() == factory


def matches(held: ModuleImage, desired: ModuleImage) -> bool:
    return held.system == desired.system and all(w is None or h == w
                                                 for h, w in zip(held.programs, desired.programs))


def test_an_apply_with_a_whole_disk_is_not_stopped(tmp_path, capsys):
    """The same limit, far above what an apply writes: the check can pass."""
    with emulated_plant(tmp_path) as plant:
        result = limited_apply(plant.path, 50 * 1024 * 1024)
        assert result.returncode == 0, result.stderr
        assert "Apply complete" in result.stdout and plant.matches_plant()
        assert os.path.getsize(journal_of(tmp_path)) < 50 * 1024 * 1024
