"""The acceptance race of the line lock (issue 9): two real `prc3cfg apply` processes started
at the same instant on one line never both write — 200 races on one spelling of the line,
200 on two spellings of one address (`socket://localhost:P` and `socket://127.0.0.1:P`): the
soak tier's count; the fast tier runs 2 of each (one wave).

A line is an emulator server process (`prc3cfg emulator serve`); `LINES` of them are raced
side by side. A driver process — this file run as a script — imports the CLI and has no
thread (it checks). For each wave it writes two plant files per line, each in a directory of
its own so each apply keeps its own journal, whose program 1 position differs from the wave
before, so every race has something to write; it forks every child, all blocked reading one
pipe, and closing the pipe's write end releases them at once. Each child runs
`prc3cfg.cli.main(["apply", …])` with its output in files.

What a child wrote is read from its journal — every exchange whose request is not a read
(50h..52h) — not from what it prints, so two applies that both read the old state and both
write are caught even when both verify. In every race exactly one child writes, and the
other was refused ("locked by") or found nothing to do. Against the old lock file (create,
then write the holder; a file read empty taken for stale and deleted) both wrote in 16 of
200 races on one spelling, and in 147 of 200 on two spellings.

Two addresses of one gateway (issue 18: an emulator listening on 0.0.0.0, planted as
127.0.0.1 and 127.0.0.2) are two locks — no client can know they are one host — so there the
gateway itself keeps one client per line: the other apply is told "the gateway is busy".
With 64 connections allowed, both wrote in 20 of 20 races. One wave runs always, 200 races under
`soak`. And 2–6 applies at once, through six spellings of such a gateway, each in a shell of its
own (TMPDIR, no PRC3CFG_LOCK_DIR): one writer in every race — one wave of six in the fast tier,
100 races of every count under `soak`.
"""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
import tempfile
import traceback
from collections.abc import Iterator
from pathlib import Path

import pytest

#: Every race on one worker, whose module fixtures start the lines' servers once (once a worker, when spread).
pytestmark = pytest.mark.xdist_group("lock_race")
# raced side by side, each with its own emulator and lock: a wave; the soak tier's counts are multiples of it
LINES = 2
#: Races per test: a few in the fast tier, the acceptance's 200 in the soak tier.
ROUNDS = [LINES, pytest.param(200, marks=pytest.mark.soak)]
READS = {0x50, 0x51, 0x52}
APPLY = ["apply", "--auto-approve", "--allow-axis-release"]

#: A reply is never lost here, but on a machine busy with 8 applies and 4 emulators at once one came
#: after 0.2 s: its write was sent again, and the late acknowledgement answered the read after it — a
#: possible write that stopped the line (`PossibleWrite`), which these races are not about.
PLANT = """\
plant: race
buses:
  - name: booth-a
    port: {port}
    framing: crc16
    timeout: 5
    modules:
      - address: 1
        name: left
        programs:
          1: {{position: {position}, speed: 0.300}}
"""


def _position(n: int) -> str:
    """Program 1's position in round `n` (m): never the one of the round before, always ≤ S1 (0.400 m)."""
    return f"{0.100 + (n % 300) / 1000:.3f}"


def _writes(plant_dir: Path) -> int:
    """Write requests in the journal an apply in `plant_dir` left (none if it never held the line)."""
    journal = plant_dir / ".prc3cfg" / "journal"
    if not journal.exists():
        return 0
    events = [json.loads(line) for path in journal.iterdir() for line in path.read_text().splitlines()]
    return sum(e["event"] == "exchange" and bytes.fromhex(e["request"])[0] not in READS for e in events)


def _child(plant: Path, release: int) -> None:
    """In a forked child: output to files, wait for the release, run the CLI, exit with its code."""
    out = os.open(plant.parent / "stdout", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    err = os.open(plant.parent / "stderr", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(out, 1)
    os.dup2(err, 2)
    code = 70
    # each apply in a shell of its own: its own TMPDIR, no PRC3CFG_LOCK_DIR
    if os.environ.get("RACE_OWN_TMPDIR"):
        os.environ["TMPDIR"] = str(plant.parent)
        os.environ.pop("PRC3CFG_LOCK_DIR", None)
        tempfile.tempdir = None
    try:
        os.read(release, 1)  # EOF when the parent closes the write end: both children at once
        from prc3cfg.cli import main

        main([APPLY[0], str(plant), *APPLY[1:]])
        code = 0
    except SystemExit as exit:
        code = exit.code if isinstance(exit.code, int) else (0 if exit.code is None else 1)
    except BaseException:  # noqa: BLE001 — a forked child must reach os._exit, whatever it met
        traceback.print_exc()
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


def drive(lines: list[tuple[str, str]], waves: int, first: int, workdir: Path) -> list[dict]:
    """Race two applies on each of `lines` (the two ports one line is named by), `waves` times.

    A wave forks every child of every line before releasing them all with one pipe: the lines
    are independent (one lock each), so they share the wall time of pyserial's 0.3 s pause on
    closing a `socket://` port. Returns per race each child's exit code, writes and output."""
    from prc3cfg.cli import _register_commands

    _register_commands()

    results = []
    for wave in range(first, first + waves):
        plants = []
        for line, ports in enumerate(lines):
            for side, port in enumerate(ports):
                directory = workdir / f"{wave}-{line}-{side}"
                directory.mkdir()
                plant = directory / "plant.yaml"
                plant.write_text(PLANT.format(port=port, position=_position(wave)))
                plants.append(plant)
        if len(os.listdir("/proc/self/task")) != 1:
            raise RuntimeError("the driver has a thread: forking it is not safe")
        sys.stdout.flush()
        sys.stderr.flush()
        release, go = os.pipe()
        children = []
        for plant in plants:
            pid = os.fork()
            if pid == 0:
                os.close(go)
                _child(plant, release)
            children.append(pid)
        os.close(release)
        os.close(go)  # every child's read returns at once
        codes = [os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) for pid in children]
        start = 0
        for line, ports in enumerate(lines):
            racers, codes_ = plants[start : start + len(ports)], codes[start : start + len(ports)]
            start += len(ports)
            results.append({
                "race": f"wave {wave}, line {line}",
                "codes": codes_,
                "writes": [_writes(p.parent) for p in racers],
                "out": [(p.parent / "stdout").read_text() for p in racers],
                "err": [(p.parent / "stderr").read_text() for p in racers],
            })
    return results


def _servers(tmp_path_factory, host: str):
    """`LINES` emulator server processes with module 1 each, listening on `host`; yields their ports."""
    servers = []
    try:
        for _ in range(LINES):
            state = tmp_path_factory.mktemp("line") / "state.json"
            command = [sys.executable, "-m", "prc3cfg", "emulator", "serve", "--listen", f"{host}:0",
                       "--state", str(state), "--modules", "1"]
            servers.append(subprocess.Popen(command, stdout=subprocess.PIPE, text=True))
        banners = [server.stdout.readline() for server in servers]
        assert all(b.startswith(f"listening on {host}:") for b in banners), banners
        yield [int(b.split()[2].rpartition(":")[2]) for b in banners]
    finally:
        for server in servers:
            server.terminate()
            server.wait()


@pytest.fixture(scope="module")
def lines(tmp_path_factory):
    yield from _servers(tmp_path_factory, "127.0.0.1")


@pytest.fixture(scope="module")
def lines_on_every_address(tmp_path_factory):
    yield from _servers(tmp_path_factory, "0.0.0.0")


@pytest.fixture(scope="module")
def waves() -> Iterator[int]:
    """Wave numbers the lines have not raced yet: each wave's plants ask them for a new position."""
    return itertools.count()


def _race(tmp_path: Path, lines: list[tuple[str, str]], rounds: int, waves: Iterator[int],
          own_tmpdir: bool = False) -> list[dict]:
    """Run the driver in a process of its own (no thread of pytest's, no BLAS threads); with
    `own_tmpdir` every apply has its own TMPDIR and the machine's lock folder."""
    numbers = [next(waves) for _ in range(rounds // LINES)]
    env = {**os.environ, "PRC3CFG_LOCK_DIR": str(tmp_path / "locks"), "OPENBLAS_NUM_THREADS": "1",
           "OMP_NUM_THREADS": "1",
           **({"RACE_OWN_TMPDIR": "1"} if own_tmpdir else {})}
    command = [sys.executable, __file__, str(tmp_path), str(len(numbers)), str(numbers[0]), json.dumps(lines)]
    driver = subprocess.run(command, env=env, capture_output=True, text=True)
    assert driver.returncode == 0, driver.stderr
    return json.loads(driver.stdout)


def _judge(results: list[dict], rounds: int,
           refusal: str | tuple[str, ...] = "the line is locked by") -> None:
    """In every race exactly one apply wrote, and completed; each other one was refused (`refusal`)
    or found nothing left to do."""
    refusals = (refusal,) if isinstance(refusal, str) else refusal
    assert len(results) == rounds
    overlaps = [r for r in results if sum(map(bool, r["writes"])) > 1]
    assert not overlaps, f"two applies wrote in {len(overlaps)} of {rounds} races, e.g. {overlaps[0]}"
    for r in results:
        writer = [i for i, writes in enumerate(r["writes"]) if writes]
        assert len(writer) == 1, f"{r['race']}: no apply wrote: {r}"
        assert r["codes"][writer[0]] == 0 and "Apply complete" in r["out"][writer[0]], r
        for other in set(range(len(r["writes"]))) - set(writer):
            refused = r["codes"][other] == 1 and any(text in r["err"][other] for text in refusals)
            idle = r["codes"][other] == 0 and "Nothing to do" in r["out"][other]
            assert refused or idle, (f"{r['race']}: apply {other} neither was refused nor found nothing to "
                                     f"do: {r}")


@pytest.mark.parametrize("rounds", ROUNDS)
def test_two_applies_on_one_line_never_both_write(tmp_path, lines, waves, rounds):
    _judge(_race(tmp_path, [(f"socket://127.0.0.1:{p}",) * 2 for p in lines], rounds, waves), rounds)


@pytest.mark.parametrize("rounds", ROUNDS)
def test_two_spellings_of_one_address_never_both_write(tmp_path, lines, waves, rounds):
    spellings = [(f"socket://localhost:{p}", f"socket://127.0.0.1:{p}") for p in lines]
    _judge(_race(tmp_path, spellings, rounds, waves), rounds)


@pytest.mark.parametrize("rounds", [LINES, pytest.param(20, marks=pytest.mark.soak)])
def test_two_applies_with_their_own_tmpdir_never_both_write(tmp_path, lines, waves, rounds):
    """Two shells with another TMPDIR and no PRC3CFG_LOCK_DIR: both wrote in 4 of 5 races when the
    lock folder followed TMPDIR."""
    _judge(_race(tmp_path, [(f"socket://127.0.0.1:{p}",) * 2 for p in lines], rounds, waves, own_tmpdir=True),
           rounds)


@pytest.mark.parametrize("rounds", [LINES, pytest.param(200, marks=pytest.mark.soak)])
def test_two_addresses_of_one_gateway_never_both_write(tmp_path, lines_on_every_address, waves, rounds):
    spellings = [(f"socket://127.0.0.1:{p}", f"socket://127.0.0.2:{p}") for p in lines_on_every_address]
    _judge(_race(tmp_path, spellings, rounds, waves), rounds,
           refusal="the gateway is busy: another client holds the line")


#: Every spelling of one gateway listening on 0.0.0.0 a client can use: each resolves to a lock key of
#: its own or shares one — either way the gateway, or the lock, lets one writer through.
SPELLINGS = ["socket://127.0.0.1:{p}", "socket://localhost:{p}", "socket://127.0.0.2:{p}",
             "socket://0.0.0.0:{p}",
             "socket://127.0.0.3:{p}", "socket://[::ffff:127.0.0.1]:{p}"]


@pytest.mark.parametrize(("racers", "rounds"),
                         [(6, LINES), *[pytest.param(k, 20, marks=pytest.mark.soak) for k in range(2, 7)]])
def test_two_to_six_applies_with_every_spelling_and_environment_never_overlap(tmp_path,
                                                                              lines_on_every_address, waves,
                                                                              racers, rounds):
    """2–6 applies at once on one line, each through another spelling of the gateway and in a shell of
    its own (its own TMPDIR, no PRC3CFG_LOCK_DIR: the machine's lock folder): one writes, the others are
    refused by the lock or by the gateway, or find nothing left to do. Soak: 100 races."""
    spellings = [tuple(SPELLINGS[i].format(p=p) for i in range(racers)) for p in lines_on_every_address]
    _judge(_race(tmp_path, spellings, rounds, waves, own_tmpdir=True), rounds,
           refusal=("the line is locked by", "the gateway is busy: another client "
                                             "holds the line"))


if __name__ == "__main__":  # the driver: WORKDIR WAVES FIRST_WAVE LINES (JSON: [[port, port], …])
    json.dump(drive(json.loads(sys.argv[4]), int(sys.argv[2]), int(sys.argv[3]), Path(sys.argv[1])),
              sys.stdout)
