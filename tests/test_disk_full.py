"""A disk that refuses one of an apply's records after its first write — full, read-only or over the
file-size limit — at each kind of record: the journal, the snapshot (saved again as a further line's
writes begin), the line's record of what its modules hold, the record of an axis release and the
copy of the plant file applied in full. Whatever the record, the apply ends in its account — what
each module was sent and holds, which axes may be released, how to restore — and one line naming
the record it could not keep and the OS error: never a traceback, never exit 0, never a frame that
left without the record that belongs before it. A refusal before the first write writes nothing.

The refusals are real and come at a chosen point: every kind of record is kept on a small file
system of its own (a tmpfs, mounted for the test: root only), which the test fills (ENOSPC) or
remounts read-only (EROFS) from the emulator's side of the line when a chosen frame of the apply
arrives there — the apply, a process of its own, cannot go on before that frame's reply, so nothing
waits on the clock. The file-size limit (RLIMIT_FSIZE, EFBIG; SIGXFSZ is ignored by Python) cuts the
k-th record of a file instead, for the sweep of the soak tier.
"""

from __future__ import annotations

import contextlib
import errno
import os
import random
import re
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import yaml
from emulated import DEMO, emulated_plant, travel_list
from lossy import Loss

from prc3cfg.core.framing import Frame
from prc3cfg.core.image import ModuleImage
from prc3cfg.shell.testing import EmulatedPlant

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="tmpfs, mount and RLIMIT_FSIZE are Linux's")
AS_ROOT = pytest.mark.skipif(sys.platform != "linux" or os.geteuid() != 0,
                             reason="mounting a small tmpfs needs root")

#: The link's reply time-out: long enough that a busy machine repeats no exchange, so that a frame's
#: number in a clean run is its number in every run.
UNHURRIED = 2.0
READS = (0x50, 0x51, 0x52)
#: What the disk says when it refuses (ENOSPC, EROFS, EFBIG), or what prc3cfg says of a state folder it cannot
#: write.
OS_ERRORS = r"(No space left on device|Read-only file system|File too large|not writable)"
RELEASES = (0x10, 0x20)
#: Where each kind of record is kept: beside the plant file (`.prc3cfg/`) or in the state folder.
KINDS = {"journal": ".prc3cfg/journal", "snapshots": ".prc3cfg/snapshots", "applied": ".prc3cfg/applied",
         "lines": "state/lines", "releases": "state/releases"}
#: What the apply's closing error says it could not keep, for each kind.
NAMED = {"journal": "the journal", "snapshots": "the snapshot",
         "applied": "the copy of the plant file applied in full",
         "lines": "the line's record", "releases": "the record of an axis release"}


def one_line(tmp_path: Path) -> Path:
    """The demo plant's first bus alone: three modules on one line, written one after another."""
    document = yaml.safe_load(DEMO.read_text())
    document["buses"] = document["buses"][:1]
    source = tmp_path / "source"
    source.mkdir(exist_ok=True)
    (source / "one-line.yaml").write_text(yaml.safe_dump(document, sort_keys=False))
    return source / "one-line.yaml"


@contextlib.contextmanager
def small_disks(folders: list[Path], size: int = 4 * 2**20) -> Iterator[None]:
    """A tmpfs of `size` bytes mounted on each folder (made first), unmounted afterwards."""
    mounted: list[Path] = []
    try:
        for folder in folders:
            folder.mkdir(parents=True, exist_ok=True)
            done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size},mode=0755", "tmpfs",
                                   str(folder)],
                                  capture_output=True, text=True)
            if done.returncode != 0:
                pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
            mounted.append(folder)
        yield
    finally:
        for folder in reversed(mounted):
            subprocess.run(["umount", "-l", str(folder)], capture_output=True)


def fill(folder: Path, leave: int = 0) -> None:
    """The file system of `folder` full but for `leave` bytes (whole pages): the next page any file
    there needs is refused with ENOSPC."""
    status = os.statvfs(folder)
    free = status.f_bavail * status.f_frsize - leave
    fd = os.open(folder / "filler", os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
    try:
        chunk = 2**16
        while free > 0:
            try:
                free -= os.write(fd, bytes(min(chunk, free)))
            except OSError as error:
                assert error.errno == errno.ENOSPC and leave == 0, error
                if chunk == 1:
                    break
                chunk //= 2
    finally:
        os.close(fd)


def read_only(folder: Path) -> None:
    """The file system of `folder` remounted read-only: every write there is refused with EROFS."""
    subprocess.run(["mount", "-o", "remount,ro", str(folder)], check=True, capture_output=True)


@dataclass
class Line:
    """What reached the modules of a line, frame by frame, and a refusal to make when a frame arrives."""

    trigger: Callable[[Frame, int], bool] = lambda frame, number: False
    action: Callable[[], None] = lambda: None
    # (address, message) of each request forwarded
    frames: list[tuple[int, bytes]] = field(default_factory=list)
    acted_at: int | None = None
    wait: threading.Event | None = None  # held at the frame `held_at` until set
    held_at: Callable[[Frame, int], bool] = lambda frame, number: False

    def rule(self, frame: Frame, number: int) -> set[Loss]:
        if self.wait is not None and self.held_at(frame, number):
            assert self.wait.wait(30), "the other line never came to its chosen frame"
        if self.acted_at is None and self.trigger(frame, number):
            self.acted_at = number
            self.action()
        self.frames.append((frame.address, frame.message))
        return set()

    def writes(self, address: int) -> list[bytes]:
        return [message for to, message in self.frames if to in (address, 0) and message[0] not in READS]


def first_write(frame: Frame, _: int) -> bool:
    return frame.message[0] not in READS


def apply(plant: EmulatedPlant, *, limit: int | None = None, command: str = "apply",
          target: Path | None = None,
          plan: Path | None = None,
          env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    """`prc3cfg apply` (or `restore` of `target`) of the plant as a process of its own — of a plan file, if
    given — with a file-size limit, if given."""

    def limited() -> None:
        if limit is not None:
            import resource

            resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    planned = [] if plan is None else ["--plan", str(plan)]
    return subprocess.run([sys.executable, "-m", "prc3cfg", command, str(target or plant.path), *planned,
                           "--auto-approve", "--allow-axis-release"],
                          preexec_fn=limited, capture_output=True, text=True, timeout=120,
                          env=env)


def matches(held: ModuleImage, desired: ModuleImage) -> bool:
    return held.system == desired.system and all(w is None or h == w
                                                 for h, w in zip(held.programs, desired.programs))


def account_problems(plant: EmulatedPlant, before: dict[tuple[str, int], ModuleImage], lines: dict[str, Line],
                     result: subprocess.CompletedProcess[str]) -> list[str]:
    """Where the apply's output is not the whole truth of what the modules hold, by the emulators —
    or is not one line per problem without a traceback."""
    out, err = result.stdout, result.stderr
    if "Traceback" in out + err:
        return [f"a traceback (exit {result.returncode})"]
    problems = []
    if not all(line.startswith(("✗", "    ", "error: ", "note: ")) for line in err.splitlines()):
        problems.append("stderr is not one line per problem")
    blocks = {block.split(" (", 1)[0]: block for block in err.split("✗ ")[1:]}
    travel = travel_list(out)
    for bus, module in plant.plant.modules():
        where, key = f"bus {bus.name}, module {module.address}", (bus.name, module.address)
        state = plant.emulators[bus.name].module(module.address)
        held, was, sent = state.image, before[key], lines[bus.name].writes(module.address)
        verified = f"✓ {where} " in out
        block = blocks.get(where)
        if verified:
            if not matches(held, module.desired_image()):
                problems.append(f"{where}: said verified, holds other than the plant file")
            said = out.split(f"✓ {where} ", 1)[1].splitlines()[0]
            if f"{len(sent)} message{'s' if len(sent) != 1 else ''} written" not in said:
                problems.append(f"{where}: said verified with another count of messages than the "
                                f"{len(sent)} it was sent")
        elif block is None:
            if held != was or sent:
                problems.append(f"{where}: was sent {len(sent)} messages and is not in the account")
        elif "nothing was sent to it" in block:
            if held != was or sent:
                problems.append(f"{where}: said to have been sent nothing, was sent {len(sent)} messages")
        else:
            told = re.search(r"^    written: (.*)$", block, re.MULTILINE)
            unacknowledged = re.search(r"^    sent, not acknowledged: (.*)$", block, re.MULTILINE)
            count = sum(len(found[1].split("; ")) for found in (told, unacknowledged) if found
                        and found[1] != "nothing acknowledged")
            if count != len(sent):
                problems.append(f"{where}: said to have been sent {count} messages, was sent {len(sent)}")
            if "read back: unchanged" in block and held != was:
                problems.append(f"{where}: said unchanged, holds other than before")
        if not state.referenced and f"{bus.name}/{module.name}" not in travel:
            problems.append(f"{where}: its axes were released and it is not on the reference-travel list")
        if any(message[0] in RELEASES for message in sent) and f"{bus.name}/{module.name}" not in travel:
            problems.append(f"{where}: was sent a 10h/20h and is not on the reference-travel list")
    return problems


def refused_problems(result: subprocess.CompletedProcess[str], kind: str | None,
                     folder: Path | None) -> list[str]:
    """Where the apply's end is not exit 1 and one line naming the record of `kind` (under `folder`) — any
    record, where None — and the OS error."""
    problems = []
    if result.returncode != 1:
        problems.append(f"exit {result.returncode}, not 1")
    error = (result.stderr.strip().splitlines() or [""])[-1]
    named = [NAMED[kind]] if kind is not None else list(NAMED.values())
    if (not any(error.startswith(f"error: could not keep {what} ") for what in named)
        or str(folder or "") not in error):
        problems.append(f"the last line does not name {' or '.join(named)} under {folder}: {error!r}")
    elif not re.search(OS_ERRORS + r"\)", error):
        problems.append(f"the last line does not give the OS error: {error!r}")
    return problems


@dataclass
class Refused:
    plant: EmulatedPlant
    before: dict[tuple[str, int], ModuleImage]
    lines: dict[str, Line]
    result: subprocess.CompletedProcess[str]
    folders: dict[str, Path]

    def check(self, kind: str | None) -> None:
        """The account is exact, and the last line names the record of `kind` (any, where None) and the OS
        error."""
        # the line's record is named by its state folder where the disk refused its nameless file
        # (`prc3cfg.shell.line_record`)
        folder = (None if kind is None else self.folders[kind].parent if kind == "lines"
                  else self.folders[kind])
        problems = (account_problems(self.plant, self.before, self.lines, self.result)
                    + refused_problems(self.result, kind, folder))
        assert not problems, ("\n".join(problems) + f"\n--- stdout\n{self.result.stdout}\n--- "
                                                    f"stderr\n{self.result.stderr}")


def folder_of(tmp_path: Path, kind: str) -> Path:
    """The folder of a test's records of `kind`: its plant file's in `line`, its state folder (`conftest`)."""
    where = KINDS[kind]
    return tmp_path / where if where.startswith("state/") else tmp_path / "line" / where


@contextlib.contextmanager
def refusing(tmp_path: Path, source: Path, lines: dict[str, Line], *, kinds: tuple[str, ...] = tuple(KINDS),
             limit: int | None = None) -> Iterator[Callable[..., Refused]]:
    """An emulated plant in `tmp_path/line` whose records of `kinds` each lie on a small disk of their own,
    its lines' frames watched (and refused at) as `lines` say; gives the apply to run."""
    directory = tmp_path / "line"
    directory.mkdir()
    folders = {kind: folder_of(tmp_path, kind) for kind in KINDS}
    assert os.environ["PRC3CFG_STATE_DIR"] == str(tmp_path / "state")
    rules = {bus: line.rule for bus, line in lines.items()}
    with small_disks([folders[kind] for kind in kinds]), emulated_plant(directory, source=source,
                                                                        timeout=UNHURRIED,
                                                                        lossy=rules) as plant:
        before = plant.images()

        def run(**options: object) -> Refused:
            return Refused(plant, before, lines, apply(plant, limit=limit, **options),
                           folders)  # type: ignore[arg-type]

        yield run


@AS_ROOT
@pytest.mark.parametrize("kind", ["journal", "lines", "releases", "applied"])
def test_a_record_the_disk_refuses_after_the_first_write_ends_in_the_whole_account_and_one_line_naming_it(
    tmp_path, kind
):
    """One line of three modules; the chosen kind's disk refused as the first write (module 1's 20h)
    reaches the line — filled (the journal's file, open, grows into a page the disk no longer has) or
    remounted read-only (the others, each written afresh)."""
    folder = folder_of(tmp_path, kind)
    line = Line(first_write, lambda: (fill if kind == "journal" else read_only)(folder))
    with refusing(tmp_path, one_line(tmp_path), {"booth-a": line}) as run:
        refused = run()
        refused.check(kind)
        assert line.acted_at is not None
        if kind == "releases":  # module 2's 20h stays back: its record could not be kept
            assert refused.lines["booth-a"].writes(2) == []
        # refused after the writes: every module written and verified all the same
        if kind in ("lines", "applied"):
            assert refused.plant.matches_plant() and refused.result.stdout.count("✓ ") == 3


@AS_ROOT
def test_a_journal_the_disk_refuses_while_a_plan_file_is_proved_is_said_so_and_writes_nothing(tmp_path,
                                                                                              capsys):
    """`apply --plan` reads the whole plant back before its first write: the disk filled at its first
    read refuses the journal a later read's record (the next page of its file) — that read stays back,
    nothing is written, and the apply says which record it could not keep (it said "error: interrupted",
    exit 130, as if Ctrl-C)."""
    line = Line(action=lambda: fill(folder_of(tmp_path, "journal")))
    with refusing(tmp_path, one_line(tmp_path), {"booth-a": line}, kinds=("journal",)) as run:
        plan = tmp_path / "plan.json"
        made = subprocess.run([sys.executable, "-m", "prc3cfg", "plan", str(tmp_path / "line" / "plant.yaml"),
                               "--out", str(plan)],
                              capture_output=True, text=True, timeout=120)
        assert made.returncode in (0, 2), made.stderr
        line.trigger, line.frames[:] = lambda frame, number: True, []  # the apply's first frame
        refused = run(plan=plan)
        refused.check("journal")
        assert "while the modules were read back — nothing was written to any module" in refused.result.stderr
        assert (all(message[0] in READS for _, message in line.frames)
                and refused.plant.images() == refused.before)


@AS_ROOT
def test_a_snapshot_the_disk_refuses_as_a_further_line_begins_stops_every_line_and_the_one_saved_restores(
    tmp_path,
):
    """The demo plant's two lines, each written as soon as its own plan is whole: booth-b's first frame
    is held at the line until booth-a's first write arrives, when the snapshots' disk is filled — so
    booth-b's modules, added to the snapshot, cannot be saved: its writes stay back, booth-a stops
    before its next frame, and the snapshot named (booth-a's modules, saved before its first write)
    restores them once there is room."""
    first = threading.Event()
    a = Line(first_write, lambda: (fill(folder_of(tmp_path, "snapshots")), first.set()))
    b = Line(wait=first, held_at=lambda frame, number: number == 1)
    with refusing(tmp_path, DEMO, {"booth-a": a, "booth-b": b}, kinds=("snapshots",)) as run:
        refused = run()
        refused.check("snapshots")
        assert b.writes(1) == b.writes(3) == b.writes(4) == [] and a.writes(1), \
            "the refusal came elsewhere than chosen"
        snapshot = re.search(r"prc3cfg restore (\S+\.json)$", refused.result.stderr.strip())
        assert snapshot, refused.result.stderr
        (folder_of(tmp_path, "snapshots") / "filler").unlink()
        restored = apply(refused.plant, command="restore", target=Path(snapshot[1]))
        assert restored.returncode == 0, restored.stderr
        assert refused.plant.images() == refused.before


@AS_ROOT
def test_a_snapshot_the_disk_refuses_before_the_first_write_writes_nothing_and_says_so(tmp_path):
    """One page left on the snapshots' disk: enough for the check before the line is opened (a page's
    worth written and flushed), not for the snapshot of three modules — nothing is sent to any module."""
    with refusing(tmp_path, one_line(tmp_path), {"booth-a": (line := Line())}, kinds=("snapshots",)) as run:
        fill(folder_of(tmp_path, "snapshots"), leave=4096)
        refused = run()
        refused.check("snapshots")
        assert "nothing was written to any module" in refused.result.stderr.strip().splitlines()[-1]
        assert (all(message[0] in READS for _, message in line.frames)
                and refused.plant.images() == refused.before)


#: A clean apply of `one_line`, traced once per process: the frames that reached the line, and the journal's
#: size after each of its records.
_CLEAN: dict[str, list[int]] = {}


def clean_run(tmp_path: Path) -> tuple[int, list[int]]:
    """How many frames a clean apply of `one_line` sends, and its journal's size after each record."""
    if not _CLEAN:
        twin = tmp_path / "twin"
        twin.mkdir()
        line = Line()
        with emulated_plant(twin, source=one_line(tmp_path), timeout=UNHURRIED,
                            lossy={"booth-a": line.rule}) as plant:
            result = apply(plant, env=os.environ | {"PRC3CFG_STATE_DIR": str(twin / "state")})
        assert result.returncode == 0, result.stderr
        (journal,) = (twin / ".prc3cfg" / "journal").glob("*.jsonl")
        sizes = [len(record) for record in journal.read_bytes().splitlines(keepends=True)]
        _CLEAN.update(frames=[len(line.frames)],
                      ends=[sum(sizes[: index + 1]) for index in range(len(sizes))])
    return _CLEAN["frames"][0], _CLEAN["ends"]


def sweep(count: int, seed: str) -> list[tuple[str, str, float]]:
    """`count` points where the disk refuses: a kind of record and how (filled, read-only), or the file-size
    limit; and where, as a fraction of the frames (of the journal's records, for the limit) of a clean run."""
    chooser = random.Random(seed)
    points = []
    for _ in range(count):
        kind = chooser.choice([*KINDS, "limit"])
        how = ("limit" if kind == "limit" else "fill" if kind == "journal"
               else chooser.choice(["fill", "read-only"]))
        points.append((kind, how, round(chooser.random(), 3)))
    return points


#: Two points in the fast tier (the limit; a release record's disk read-only midway), 20 in the soak tier
#: (about 40 s on two cores).
POINTS = [("limit", "limit", 0.5), ("releases", "read-only", 0.6),
          *(pytest.param(*point, marks=pytest.mark.soak) for point in sweep(20, "issue 39, soak"))]


@pytest.mark.parametrize("kind, how, at", POINTS)
def test_a_disk_that_refuses_anywhere_in_an_apply_leaves_an_exact_account_and_no_untold_release(tmp_path,
                                                                                                kind, how,
                                                                                                at):
    """One line of three modules; the disk refuses a kind of record from a chosen frame on (filled or
    remounted read-only when that frame reaches the line), or every file past a size at which the journal
    has a chosen number of records (RLIMIT_FSIZE; then any record may be the first refused). Whatever
    the point: no traceback, the account is what the modules hold (the emulator's state), every module
    whose axes were released is on the travel list; exit 0 only for a whole, verified apply; else one
    line naming the record (or, before the first write, what stopped it) and nothing written then."""
    if kind != "limit" and (sys.platform != "linux" or os.geteuid() != 0):
        pytest.skip("mounting a small tmpfs needs root")
    frames, ends = clean_run(tmp_path)
    refuse = fill if how == "fill" else read_only
    line = Line() if kind == "limit" else Line(lambda frame, number: number == 1 + int(at * frames),
                                               lambda: refuse(folder_of(tmp_path, kind)))
    limit = ends[int(at * len(ends))] if kind == "limit" else None
    with refusing(tmp_path, one_line(tmp_path), {"booth-a": line}, kinds=() if kind == "limit" else (kind,),
                  limit=limit) as run:
        refused = run()
        result = refused.result
        wrote = any(message[0] not in READS for _, message in line.frames)
        if result.returncode == 0:  # the refusal came after the last record of its kind that mattered
            assert "Apply complete" in result.stdout and refused.plant.matches_plant(), \
                result.stdout + result.stderr
        elif not wrote:  # before the first write: one line, and nothing written
            assert result.returncode == 1 and "Traceback" not in result.stderr, result.stderr
            error = result.stderr.strip().splitlines()[-1]
            assert error.startswith("error: ") and re.search(OS_ERRORS, error), error
            assert refused.plant.images() == refused.before
        else:
            refused.check(None if kind == "limit" else kind)


def adopt(plant: EmulatedPlant, reason: str, limit: int | None = None,
          env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    def limited() -> None:
        if limit is not None:
            import resource

            resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return subprocess.run([sys.executable, "-m", "prc3cfg", "adopt", str(plant.path), "--auto-approve",
                           "--reason", reason],
                          preexec_fn=limited, capture_output=True, text=True, timeout=120,
                          env=env)


def test_a_journal_the_disk_refuses_after_an_adopt_wrote_the_plant_file_says_so_in_one_line(tmp_path):
    """`adopt` journals what it adopts, writes the plant file, then journals that it did. The file-size
    limit set just past the journal's first two records (measured on a twin; a long reason makes the
    journal the largest file written) refuses the last: the plant file is written all the same, and
    one line says so and names the journal — it was a traceback."""
    reason = "a reason long enough that the journal outgrows every other file adopt writes " * 250

    def adopted_line(directory: Path, limit: int | None,
                     state: Path) -> tuple[subprocess.CompletedProcess[str], bytes]:
        with emulated_plant(directory, source=one_line(tmp_path), timeout=UNHURRIED) as plant:
            env = os.environ | {"PRC3CFG_STATE_DIR": str(state)}
            assert apply(plant, env=env).returncode == 0
            plant.emulators["booth-a"].teach_in(1, 2, 160)
            return adopt(plant, reason, limit, env), plant.path.read_bytes()

    (tmp_path / "twin").mkdir()
    (tmp_path / "line").mkdir()
    clean, _ = adopted_line(tmp_path / "twin", None, tmp_path / "twin-state")
    assert clean.returncode == 0, clean.stderr
    (journal,) = sorted((tmp_path / "twin" / ".prc3cfg" / "journal").glob("*.jsonl"))[-1:]
    header, adopt_record, _ = (len(record) for record in journal.read_bytes().splitlines(keepends=True))
    refused, written = adopted_line(tmp_path / "line", header + adopt_record + 40, tmp_path / "state")
    assert refused.returncode == 1 and "Traceback" not in refused.stderr, refused.stderr
    error = refused.stderr.strip().splitlines()[-1]
    assert (error.startswith("error: could not keep the journal (") and "File too large" in error
            and "was adopted and written" in error), error
    assert b"position: 0.16\n" in written  # the taught value, adopted
