"""The emulator's journal (`prc3cfg.shell.emulator.state`): every accepted write is on disk before it
is answered, without rewriting the state file, and a killed emulator loses nothing it
acknowledged — checked by SIGKILL of a real `prc3cfg emulator serve` at random points."""

from __future__ import annotations

import errno
import json
import os
import random
import select
import shutil
import signal
import subprocess
import sys
import threading
from dataclasses import replace
from pathlib import Path

import pytest
import serial
from emulator_client import Client, listening, spawn

from prc3cfg.core import codec
from prc3cfg.core.device import ModuleState
from prc3cfg.core.framing import Direction
from prc3cfg.core.image import Program
from prc3cfg.errors import UserError
from prc3cfg.shell.emulator import state as store
from prc3cfg.shell.emulator.bus import BROADCAST
from prc3cfg.shell.emulator.server import Emulator
from prc3cfg.shell.emulator.state import JOURNAL_FORMAT, journal_path, load_state, state_document

ACCEPTED = b"\x00\x00"


def modules(*addresses: int) -> dict[int, ModuleState]:
    return {a: ModuleState.factory(a) for a in addresses}


def write(program: int, position: int) -> bytes:
    return codec.WriteProgram(program, Program(P=position, V=100)).encode()


def identity(path: Path) -> tuple[int, int, int]:
    status = os.stat(path)
    return status.st_ino, status.st_size, status.st_mtime_ns


def send_only(client: Client, address: int, message: bytes) -> None:
    """Send without waiting for a reply (a broadcast has none)."""
    client.port.write(client.framing.encode(Direction.REQUEST, address, message))


def client_of(emulator: Emulator) -> Client:
    host, port = emulator.listen()
    return Client(f"socket://{host}:{port}")


def test_a_write_goes_into_the_journal_and_the_state_file_takes_it_on_exit(tmp_path):
    state = tmp_path / "bus.json"
    with Emulator(modules(1, 3), state_path=state) as emulator:
        created = identity(state)  # at start: there was none
        client = client_of(emulator)
        try:
            assert [client.send(1, write(n, 100 + n)) for n in (4, 5, 6)] == [ACCEPTED] * 3
        finally:
            client.close()
        assert identity(state) == created  # not rewritten
        lines = journal_path(state).read_text().splitlines()
        assert lines[0] == f"{JOURNAL_FORMAT} {json.loads(state.read_text())['generation']}"
        assert lines[1:] == [f"1 {write(n, 100 + n).hex()}" for n in (4, 5, 6)]
        # the state file and its journal: what was acknowledged
        assert load_state(state) == emulator.modules()
    assert not journal_path(state).exists()
    saved = json.loads(state.read_text())  # the contract alone, after a clean exit
    assert [m["programs"][n - 1]["P"] for m in saved["modules"] if m["address"] == 1
            for n in (4, 5, 6)] == [104, 105, 106]


def test_what_is_on_disk_is_what_was_acknowledged_after_every_write(tmp_path):
    """Writes, broadcasts, refused writes and reads, with a compaction every 7 journal lines: a copy of
    the folder taken after any reply — what a kill would leave — loads as the modules the emulator holds."""
    state = tmp_path / "live" / "bus.json"
    kept = {9: replace(ModuleState.factory(9), mode="run")}
    rng = random.Random(3)
    with Emulator(modules(1, 2, 3), state_path=state, unserved=kept, compact_every=7) as emulator:
        client = client_of(emulator)
        try:
            for step in range(60):
                address = rng.choice([BROADCAST, 1, 2, 3])
                # 5000: refused, P > S1
                message = write(rng.randrange(1, 65), rng.choice([50, 150, 250, 399, 5000]))
                send_only(client, address, message) if address == BROADCAST else client.send(address, message)
                # a broadcast is processed by now
                assert client.send(1, codec.ReadSystem().encode()) is not None
                copy = tmp_path / f"copy-{step}"
                shutil.copytree(state.parent, copy)
                assert load_state(copy / "bus.json") == {**kept, **emulator.modules()}, f"step {step}"
                assert len(journal_path(state).read_text().splitlines()) <= 1 + 7
        finally:
            client.close()
    assert load_state(state) == {**kept, **emulator.modules()}


def test_a_journal_left_behind_is_replayed_and_compacted_at_start(tmp_path):
    state = tmp_path / "live" / "bus.json"
    with Emulator(modules(1, 2), state_path=state) as emulator:
        client = client_of(emulator)
        try:
            assert client.send(2, write(7, 321)) == ACCEPTED
            send_only(client, BROADCAST, codec.WriteSpeeds(((4, 123),)).encode())
            assert client.send(2, codec.ReadSystem().encode()) is not None
        finally:
            client.close()
        killed = tmp_path / "killed"
        shutil.copytree(state.parent, killed)  # what SIGKILL would leave behind
        held = emulator.modules()
    left = killed / "bus.json"
    # the header, the write, the broadcast to both
    assert len(journal_path(left).read_text().splitlines()) == 1 + 1 + 2
    assert load_state(left) == held
    with Emulator(load_state(left), state_path=left) as restarted:
        assert load_state(left) == held
        assert store._load_file(left) == held  # compacted: the state file alone holds it all
        generation = json.loads(left.read_text())["generation"]
        assert journal_path(left).read_text().splitlines() == [f"{JOURNAL_FORMAT} {generation}"]
        assert restarted.modules() == held


GENERATION = "5f0c2a7e9b1d4c3a8e6f0a1b2c3d4e5f"


def journal(state: Path, *lines: str, generation: str = GENERATION, end: str = "\n") -> None:
    journal_path(state).write_text("\n".join([f"{JOURNAL_FORMAT} {generation}", *lines]) + end)


def test_a_cut_line_is_ignored_and_a_journal_the_state_file_took_in_has_nothing_to_replay(tmp_path):
    state = tmp_path / "bus.json"
    state.write_text(json.dumps(state_document(modules(1), GENERATION, replaces="0123")))
    factory = modules(1)
    written = ModuleState.factory(1).image.with_programs({3: Program(P=200, V=100)})
    # the last line cut by a kill
    journal(state, f"1 {write(3, 200).hex()}", f"1 {write(4, 300).hex()[:9]}", end="")
    assert load_state(state) == {1: ModuleState(written)}
    # killed between saving the state file and a fresh journal
    journal(state, f"1 {write(3, 200).hex()}", generation="0123")
    assert load_state(state) == factory
    journal(state, f"2 {write(3, 200).hex()}")  # a module served from factory defaults, not yet in the file
    taught = ModuleState(ModuleState.factory(2).image.with_programs({3: Program(P=200, V=100)}))
    assert load_state(state) == {**factory, 2: taught}


@pytest.mark.parametrize(
    ("line", "says"),
    [
        ("1 21zz", "bus.json.journal:3: not an address and a message in hex — fix or delete the line"),
        ("one 2100", "bus.json.journal:3: not an address and a message in hex — fix or delete the line"),
        ("40 2100", "bus.json.journal:3: address 40 is outside 1..30 — fix or delete the line"),
    ],
)
def test_a_journal_line_that_is_not_a_write_is_refused_with_its_line_number(tmp_path, line, says):
    state = tmp_path / "bus.json"
    state.write_text(json.dumps(state_document(modules(1), GENERATION)))
    journal(state, f"1 {write(3, 200).hex()}", line)
    with pytest.raises(UserError) as refused:
        load_state(state)
    assert str(refused.value) == f"{tmp_path}/{says}"


def test_a_write_the_journal_cannot_take_is_taken_back_and_neither_answered_nor_applied(tmp_path, monkeypatch,
                                                                                        caplog):
    state = tmp_path / "bus.json"
    sync = os.fdatasync
    failures = [OSError(errno.EIO, "Input/output error")]

    def fails_once(fd: int) -> None:
        if failures:
            raise failures.pop()
        sync(fd)

    with Emulator(modules(1), state_path=state) as emulator:
        client = client_of(emulator)
        try:
            assert client.send(1, write(3, 111)) == ACCEPTED
            monkeypatch.setattr(store.os, "fdatasync", fails_once)
            assert client.send(1, write(3, 222)) is None  # not answered
            assert emulator.module(1).image.program(3).P == 111  # not applied
            assert load_state(state)[1].image.program(3).P == 111  # and taken back from the journal
            assert client.send(1, write(4, 333)) == ACCEPTED  # the next write is saved by compaction
            assert store._load_file(state)[1].image.program(4).P == 333
        finally:
            client.close()
    assert f"{state}: cannot save the emulator state file (Input/output error)" in caplog.text
    assert load_state(state)[1].image.program(3).P == 111


# -- SIGKILL of a real `prc3cfg emulator serve` -----------------------------------------------

#: Kill-and-restart rounds: a few in the fast tier, 24 in the soak tier. The fast tier's 4 (its schedule drawn
#: from random.Random(5)) still hold a round past a compaction (1,224 writes), two short ones and a kill
#: during a start.
ROUNDS = [4, pytest.param(24, marks=pytest.mark.soak)]
MODULES = 30


def written(state: Path) -> dict[tuple[int, int], int]:
    """Every program's position in the state file alone (the contract), by (address, program)."""
    return {(m["address"], n): p["P"] for m in json.loads(state.read_text())["modules"]
            for n, p in enumerate(m["programs"], 1)}


def kill_during_start(process, state: Path, before: tuple[int, int, int] | None) -> None:
    """SIGKILL as soon as the state file changes (the start's compaction) or the emulator listens."""
    while process.poll() is None:
        try:
            if identity(state) != before:
                break
        except FileNotFoundError:
            pass
        if select.select([process.stdout], [], [], 0)[0]:  # it listens: the start is over
            break
    process.kill()


@pytest.mark.parametrize("rounds", ROUNDS)
def test_a_killed_emulator_loses_no_acknowledged_write(tmp_path, rounds):
    """Rounds of writes to a real `emulator serve --state`, each ended by SIGKILL — after a random number
    of acknowledged writes (past a compaction at 1,000 in some rounds) while the client keeps writing, or
    during the start's replay and compaction — then a restart: every acknowledged write is in the state
    file the restarted emulator compacted, and the one write in flight at the kill is there or not."""
    state = tmp_path / "bus.json"
    # the rounds killed in the start and each round's writes: drawn from `schedule` alone, never after
    # writes whose number the kill's timing decides (one rng for both took no round in the start under load)
    schedule = random.Random(5)
    allowed: dict[tuple[int, int], set[int]] = {}  # (address, program) → positions the state may hold
    killed_in_start = writes = 0
    for round_ in range(rounds + 1):
        before = identity(state) if state.exists() else None
        process, log = spawn(tmp_path, "--state", str(state), "--modules", f"1-{MODULES}")
        if 0 < round_ < rounds and schedule.random() < 0.25:
            kill_during_start(process, state, before)
            process.wait()
            killed_in_start += 1
            continue
        served = listening(process, log)
        held = written(state)
        for key, positions in allowed.items():
            assert held[key] in positions, (f"round {round_}: {key} holds {held[key]}, acknowledged "
                                            f"{positions}")
        allowed = {key: {held[key]} for key in allowed}
        if round_ == rounds:
            process.terminate()
            assert process.wait() == 0, log.read_text()
            break
        writes += kill_after_writes(served, random.Random(schedule.randrange(2**32)), allowed)
        assert process.wait() == -signal.SIGKILL, log.read_text()
    assert not journal_path(state).exists()  # the last exit was clean
    assert "Traceback" not in log.read_text()
    assert killed_in_start > 0 and writes > 200 * rounds


def kill_after_writes(served, rng: random.Random, allowed: dict[tuple[int, int], set[int]]) -> int:
    """Write until a SIGKILL, sent from another thread after a random number of acknowledged writes,
    ends the emulator; `allowed` follows what the state may hold. The writes acknowledged."""
    target = rng.choice([rng.randrange(0, 300), rng.randrange(900, 1_500)])
    reached = threading.Event()
    killer = threading.Thread(target=lambda: (reached.wait(), served.process.kill()))
    killer.start()
    client = Client(served.url)
    acknowledged = 0
    try:
        while True:
            if acknowledged == target:
                reached.set()
            address, program, position = rng.randint(1, MODULES), rng.randint(1, 64), rng.randrange(0, 401)
            key = (address, program)
            factory = ModuleState.factory(address).image.program(program).P
            allowed[key] = allowed.get(key, {factory}) | {position}  # in flight: it may be executed or not
            try:
                reply = client.send(address, write(program, position))
            except (serial.SerialException, OSError):
                break
            if reply is None:
                break
            assert reply == ACCEPTED
            allowed[key] = {position}
            acknowledged += 1
    finally:
        reached.set()
        killer.join()
        client.close()
    return acknowledged


# -- one emulator per state file ----------------------------------------------------------------

EMULATED_PLANT = """\
plant: owned
buses:
  - name: booth-a
    port: emulator://line
    framing: crc16
    modules:
      - address: 1
        name: left
        programs:
          1: {position: 0.200, speed: 0.300}
"""


def refused_serve(directory: Path, *options: str) -> subprocess.CompletedProcess:
    """Run `emulator serve OPTIONS`, which must be refused: stopped (and the test failed) if it listens."""
    directory.mkdir()
    process, log = spawn(directory, *options)
    banner = process.stdout.readline()
    if banner:
        process.terminate()
        process.wait()
        pytest.fail(f"a second emulator of the state file started: {banner}")
    return subprocess.CompletedProcess(process.args, process.wait(), "", log.read_text())


def test_an_emulator_owns_its_state_file_while_it_runs(tmp_path):
    """`emulator serve --state FILE` and an `emulator://` apply on the same file (the apply's verified
    writes were lost when the server exited), or a second serve: the second is refused in one line
    naming the first; once the first exits, the file is free."""
    plant = tmp_path / "plant.yaml"
    plant.write_text(EMULATED_PLANT)
    state = tmp_path / ".prc3cfg" / "emulators" / "line.json"
    state.parent.mkdir(parents=True)
    process, log = spawn(tmp_path, "--state", str(state), "--modules", "1")
    served = listening(process, log)
    try:
        apply = subprocess.run([sys.executable, "-m", "prc3cfg", "apply", str(plant), "--auto-approve",
                                "--allow-axis-release"],
                               capture_output=True, text=True)
        second = refused_serve(tmp_path / "second", "--state", str(state))
    finally:
        served.process.terminate()
        assert served.process.wait() == 0, log.read_text()
    for refused in (apply, second):
        assert refused.returncode == 1 and refused.stdout in ("", None), refused
        assert refused.stderr.count("\n") == 1, refused.stderr
        in_use = (f"error: {state}: the state file is in use by another emulator (pid "
                  f"{served.process.pid}, since 20")
        assert refused.stderr.startswith(in_use), refused.stderr
    assert "Apply complete" in subprocess.run([sys.executable, "-m", "prc3cfg", "apply", str(plant),
                                               "--auto-approve", "--allow-axis-release"],
                                              capture_output=True, text=True).stdout
    assert written(state)[(1, 1)] == 200


# -- damaged state files and journals: replayed whole, or refused in one line ------------------------


def _reformat(indent, **options):
    return lambda text: json.dumps(json.loads(text), indent=indent, **options)


def _journal_lines(text: str) -> list[str]:
    return text.split("\n")


DAMAGE = {  # name: (what is done to the state file's text, to the journal's text, "replays" | "refuses")
    "intact": (None, None, "replays"),
    "state: a final newline": (lambda t: t + "\n", None, "replays"),
    "state: a byte-order mark": (lambda t: "\ufeff" + t, None, "replays"),
    "state: pretty-printed": (_reformat(4), None, "replays"),
    "state: on one line": (_reformat(None, separators=(",", ":")), None, "replays"),
    "state: keys sorted": (_reformat(2, sort_keys=True), None, "replays"),
    "state: CRLF line ends": (lambda t: t.replace("\n", "\r\n"), None, "replays"),
    "state: tab indents": (_reformat("\t"), None, "replays"),
    "state: a byte-order mark, CRLF and a final newline": (lambda t: "\ufeff" + t.replace("\n", "\r\n")
                                                           + "\r\n", None, "replays"),
    "journal: CRLF line ends": (None, lambda t: t.replace("\n", "\r\n"), "replays"),
    "journal: a byte-order mark": (None, lambda t: "\ufeff" + t, "replays"),
    "journal: a last line cut by a kill": (None, lambda t: t + "1 2104", "replays"),
    "journal: NUL bytes after the last line": (None, lambda t: t + "\0" * 512, "replays"),
    "journal: a blank line at the end": (None, lambda t: t + "\n", "replays"),
    "journal: trailing spaces": (None, lambda t: t.replace("\n", "  \n"), "replays"),
    "journal: CRLF, state pretty-printed": (_reformat(4), lambda t: t.replace("\n", "\r\n"), "replays"),
    "journal: a damaged header": (None, lambda t: t.replace("-journal/2 ", "-journal/2 x", 1), "refuses"),
    "journal: no header": (None, lambda t: t.partition("\n")[2], "refuses"),
    "journal: a header of an unknown format": (None, lambda t: t.replace("journal/2", "journal/9", 1),
                                               "refuses"),
    "journal: emptied": (None, lambda t: "", "refuses"),
    "journal: only a header cut short": (None, lambda t: t[:12], "refuses"),
    "state: deleted": ("delete", None, "refuses"),
    "state: emptied": (lambda t: "", None, "refuses"),
    "state: another emulator's": (lambda t: json.dumps({**json.loads(t), "generation": "another"}), None,
                                  "refuses"),
    "state: the extension keys dropped by a tool": (
        lambda t: json.dumps({k: v for k, v in json.loads(t).items() if k in ("format", "modules")}), None,
                                                    "refuses"),
    "state: took the journal in, killed before a fresh one": ("compacted", None, "replays"),
}


@pytest.fixture(scope="module")
def killed(tmp_path_factory) -> tuple[Path, dict[int, ModuleState]]:
    """A folder as SIGKILL leaves it — a state file and a journal of acknowledged writes — and the modules
    acknowledged."""
    state = tmp_path_factory.mktemp("live") / "bus.json"
    with Emulator(modules(1, 2), state_path=state) as emulator:
        client = client_of(emulator)
        try:
            assert [client.send(a, write(n, 100 + n)) for a, n in ((1, 4), (2, 5), (1, 6))] == [ACCEPTED] * 3
            send_only(client, BROADCAST, codec.WriteSpeeds(((4, 123),)).encode())
            assert client.send(2, write(9, 321)) == ACCEPTED
        finally:
            client.close()
        copy = tmp_path_factory.mktemp("killed")
        for path in (state, journal_path(state)):
            shutil.copy(path, copy / path.name)
        held = emulator.modules()
    assert (held != modules(1, 2) and len(journal_path(copy / "bus.json").read_text().splitlines()) == 1 + 3
            + 2 + 1)
    return copy / "bus.json", held


@pytest.mark.parametrize("case", DAMAGE, ids=list(DAMAGE))
def test_a_damaged_state_file_or_journal_is_replayed_whole_or_refused_in_one_line(tmp_path, killed, case):
    """Against a journal bonded to a hash of the state file's bytes, 21 of these 24 cases failed: acknowledged
    writes dropped without a word, or a refusal that named neither both files nor what to do."""
    source, held = killed
    state = tmp_path / "bus.json"
    state_text, journal_text = source.read_text(), journal_path(source).read_text()
    on_state, on_journal, outcome = DAMAGE[case]
    if on_journal is not None:
        journal_text = on_journal(journal_text)
    journal_path(state).write_text(journal_text, newline="")
    if on_state == "compacted":  # what an emulator killed inside its compaction leaves
        generation = journal_text.partition("\n")[0].split()[1]
        state.write_text(json.dumps(state_document(held, "next", replaces=generation)))
    elif on_state != "delete":
        state.write_text(on_state(state_text) if on_state else state_text, newline="")
    try:
        with Emulator(load_state(state), state_path=state) as restarted:
            started = restarted.modules()
    except UserError as refused:
        assert outcome == "refuses", f"{case}: refused: {refused}"
        message = str(refused)
        assert "\n" not in message and str(state) in message and str(journal_path(state)) in message, message
        assert " — " in message or ". " in message, message
        assert journal_path(state).read_bytes() == journal_text.encode()  # kept for whoever mends it
        return
    assert outcome == "replays", f"{case}: started with {started}"
    assert started == held, f"{case}: acknowledged writes lost"
    assert load_state(state) == held


def test_a_journal_the_state_file_took_in_is_gone_before_the_next_save(tmp_path, killed):
    """Killed inside a compaction, then again inside the next start's: the journal two saves back
    must not be left beside a state file that no longer names it."""
    source, held = killed
    state = tmp_path / "bus.json"
    journal_text = journal_path(source).read_text()
    journal_path(state).write_text(journal_text)
    state.write_text(json.dumps(state_document(held, "next", replaces=journal_text.split()[1])))
    with Emulator(load_state(state), state_path=state) as restarted:
        # the state file holds it all: the first write begins a journal
        assert not journal_path(state).exists()
        assert restarted.modules() == held
        client = client_of(restarted)
        try:
            assert client.send(1, write(7, 77)) == ACCEPTED
        finally:
            client.close()
        assert json.loads(state.read_text())["replaces"] == "next"
        assert journal_path(state).read_text().split()[1] == json.loads(state.read_text())["generation"]
