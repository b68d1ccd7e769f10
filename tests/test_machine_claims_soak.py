"""Other users' records are claims (`prc3cfg.shell.line_record`, `prc3cfg.shell.pending_records`): a seeded
family of files planted among the line records and the axis-release records — a FIFO, a link to /dev/zero, a
sparse file far over the bound, a folder, bytes that are no JSON, records of another line, forged fields full
of terminal commands and bidi overrides, forged E12 and release records — each held against real processes:
`prc3cfg plan` and `apply` as subprocesses on the demo plant's emulators, after an apply of this user's made
every module match the plant file and a travel to the reference point since.

What must hold, every seed: every command returns (no hang: a generous timeout on the subprocess), with
no traceback and no raw control character on its output; the plan finds no change and the apply writes
nothing — no 10h/20h, nor any other write, because of another user's claim (every module still
referenced and as the plant file says); this user's own record still counts. The fast tier tries the
kinds one at a time in `tests/test_machine_folder.py` and `tests/test_line_record.py`.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from emulated import emulated_plant
from test_locks import ROOT
from test_machine_folder import RAW, plant_unreadable

from prc3cfg.shell.line_record import FORMAT
from prc3cfg.shell.sessions import bus_line_keys

#: The uid the planted files belong to: another user, neither root nor this one.
OTHER_UID = 4242
#: What a terminal would act on, and what reorders a line.
HOSTILE = ["\x1b[1A\x1b[2K", "\x1b]0;pwned\x07", "\u202e", "\u2066", "\u2028", "\x9b2J", "\r", "\n", "\x00",
           "\u061c"]


def hostile(rng: random.Random) -> str:
    return "".join(rng.choice([*HOSTILE, "booth-a", "ok", " "]) for _ in range(rng.randint(1, 6)))


def plant_one(rng: random.Random, state: Path, keys: dict[str, tuple[str, ...]], n: int) -> Path:
    """One planted file of a kind `rng` picks, owned by another user, in lines/ or releases/; where it is."""
    kind = rng.choice(["fifo", "zero", "sparse", "folder", "garbage", "wrong-key", "forged-line",
                       "forged-e12", "forged-release"])
    bus = rng.choice(sorted(keys))
    key = rng.choice(keys[bus])
    # STEM.UID.json: this user's
    own = [p for p in (state / "lines").glob(f"*.{os.getuid()}.json") if p.name.count(".") == 2]
    stem = next(p.name.split(".")[0] for p in own if json.loads(p.read_text())["key"] == key)
    lines = kind in ("wrong-key", "forged-line") or (kind not in ("forged-e12", "forged-release")
                                                     and rng.random() < 0.5)
    path = (state / "lines" / f"{stem}.{OTHER_UID}.{n}.json" if lines
            else state / "releases" / f"2099{n:04d}T000000.000000Z-{n}.jsonl")
    path.parent.mkdir(exist_ok=True)
    now = datetime.now(UTC) + timedelta(seconds=rng.choice([0, 1, 3600]))
    if kind in ("fifo", "zero", "sparse", "folder"):
        # the seeds draw as before
        plant_unreadable(path, kind, rng.choice([2**21 + 1, 2**28]) if kind == "sparse" else 0)
    elif kind == "garbage":
        path.write_bytes(rng.choice([b"\xef\xbb\xbf{not json", b"[" * 100_000, b'{"format": 1}',
                                     b"\x1b[2J\n" * 10]))
    elif kind in ("wrong-key", "forged-line"):
        entry = {"at": now.isoformat(), "since": now.isoformat(), "by": hostile(rng),
                 "image": {"address": hostile(rng)}}
        address = rng.choice(["1", "2", "3", "5", "0", "31", "x"])
        path.write_text(json.dumps({"format": FORMAT, "key": "tcp/127.0.0.1/9" if kind == "wrong-key"
                                    else key, "modules": {address: entry}}))
    else:
        record = {"kind": "e12" if kind == "forged-e12" else "release", "keys": [key],
                  "bus": rng.choice([bus, hostile(rng)]),
                  "address": rng.choice([1, 2, 3, 5, 0]), "name": hostile(rng), "time": hostile(rng),
                  "pid": rng.randint(1, 99999),
                  "command": hostile(rng), "journal": rng.choice([None, hostile(rng)])}
        path.write_text(json.dumps(record) + "\n")
    os.lchown(path, OTHER_UID, OTHER_UID)
    return path


def cli(*argv: object) -> subprocess.CompletedProcess[str]:
    """`prc3cfg ARGV` in a process of its own, which must return: a hang fails the test, it does not stall
    it."""
    done = subprocess.run([sys.executable, "-m", "prc3cfg", *map(str, argv)], capture_output=True, text=True,
                          timeout=120,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert "Traceback" not in done.stderr, done.stderr
    assert not RAW.search(done.stdout + done.stderr), (done.stdout + done.stderr)[:2000]
    return done


@pytest.mark.soak
@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="giving a planted file to another user takes root")
def test_planted_and_forged_records_never_hang_break_or_make_prc3cfg_write(tmp_path):
    state = tmp_path / "state"
    (tmp_path / "plant").mkdir()
    with emulated_plant(tmp_path / "plant") as plant:
        assert cli("apply", plant.path, "--auto-approve", "--allow-axis-release").returncode == 0
        keys = {bus.name: bus_line_keys(plant.plant, bus) for bus in plant.plant.buses}
        for seed in range(24):
            rng = random.Random(seed)
            for emulator in plant.emulators.values():
                for address in emulator.modules():
                    emulator.update(address, referenced=True)  # travelled to the reference point since
            planted = [plant_one(rng, state, keys, n) for n in range(rng.randint(1, 4))]
            planned = cli("plan", plant.path, "--detailed-exitcode")
            assert planned.returncode == 0, (seed, planned.stdout + planned.stderr)
            # no --allow-axis-release: none may be needed
            applied = cli("apply", plant.path, "--auto-approve")
            assert applied.returncode == 0 and "Nothing to do" in applied.stdout, (seed, applied.stdout
                                                                                   + applied.stderr)
            assert plant.matches_plant()
            assert all(s.referenced for e in plant.emulators.values() for s in e.modules().values()), seed
            for path in planted:
                if path.is_dir() and not path.is_symlink():
                    path.rmdir()
                # an apply that listed a forged release in its account may have cleared it: told, as a claim
                else:
                    path.unlink(missing_ok=True)
        assert "taken as known" in cli("plan", plant.path).stdout  # this user's own record counted throughout
