"""What an apply leaves behind: snapshots of the modules before the first write, and a journal.

- A snapshot (`.prc3cfg/snapshots/<time>-<plant>.json` beside the plant file) holds the
  read-back images of every module an apply will touch (with every program a system
  change could clamp), the line each bus's modules were read on (port, framing, identities),
  the plant file's absolute path and hash, and the time — `prc3cfg
  restore` plans and applies back to it, from any directory. It is written atomically
  (`prc3cfg.shell.files`) before the first write: a killed apply leaves a whole snapshot or none.
- A journal (`.prc3cfg/journal/<time>-<plant>.jsonl`) records every exchange of an apply,
  one JSON object per line: each attempt as a `request` before its frame leaves, then as an
  `exchange` with time, bus, address, request and reply in hex, attempt, duration.
- Who, where, what and why (`header`): the first record of every journal, and a copy in every
  snapshot — the command, user, host, prc3cfg's version, the command line, the plant file (path,
  SHA-256, and its git commit and whether the work tree was clean), the plan file's SHA-256 and
  the reason given.
- A hash chain: every journal record after the header carries `prev`, the SHA-256 of the line
  before it (its bytes, without the newline); each time the snapshot is written a `snapshot`
  record carries the snapshot file's SHA-256 — the journal begins with the read-back, before the
  snapshot exists, so the header cannot; and the header of a journal carries `previous`, the
  name, line count and last line's SHA-256 of the plant's newest journal when it began (that
  journal is checked first: `prc3cfg.shell.audit`, which also checks records;
  `prc3cfg.shell.recorded_runs` lists and prunes them).
- The plant file last applied in full (`.prc3cfg/applied/<plant>.yaml`, a copy written after
  an apply that verified every module of the plant): what `plan` compares with to say which
  modules and programs left the plant file — they stay on the hardware as they are. (What the
  modules hold is the line's record's: `prc3cfg.shell.line_record`.)

`check_writable` tells, before an apply opens a line, whether these can be written at all (a
read-only checkout, a full disk, a file where `.prc3cfg` belongs): an apply that could not keep
its snapshot and journal must not start writing modules.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from pydantic import BaseModel, Field, ValidationError

from prc3cfg import __version__
from prc3cfg.core.contract import LATER, Text, json_path, said
from prc3cfg.core.image import ModuleImage, images_from_json
from prc3cfg.errors import UserError
from prc3cfg.shell import platform
from prc3cfg.shell.files import FileProblem, read_json, write_atomically
from prc3cfg.shell.platform import open_text, resolved

if TYPE_CHECKING:
    from prc3cfg.shell.link.client import Exchange

SNAPSHOT_FORMAT = "prc3cfg-snapshot/1"
#: The folders under `.prc3cfg/` an apply writes.
KINDS = ("snapshots", "journal", "applied")


#: The length of `_stamp()`, which begins every record file's name: "20261126T061428.123456Z".
STAMP_LENGTH = 23
#: The environment variable a reason is taken from when none is given (`--reason`).
REASON_VARIABLE = "PRC3CFG_REASON"
#: How long `git` may take to say a plant file's commit and whether its work tree is clean.
GIT_TIMEOUT = 3.0


def _stamp() -> str:
    return datetime.now(UTC).strftime("%Y%m%dT%H%M%S.%fZ")


def line_hash(line: bytes) -> str:
    """What the next record's `prev` says of a journal line: the SHA-256 of its bytes, without the newline."""
    return hashlib.sha256(line).hexdigest()


def reason_given(reason: str | None) -> str | None:
    """The reason of a write: `reason`, else `PRC3CFG_REASON`; None when neither says anything."""
    chosen = reason if reason is not None else os.environ.get(REASON_VARIABLE)
    return (chosen.strip() or None) if chosen is not None else None


def git_state(plant_path: Path) -> dict[str, Any]:
    """The plant file in git: `commit` (HEAD), `clean` (no tracked file changed in the work tree),
    `plant_file` ("committed", "changed", "untracked" or "ignored") — or, where git cannot say,
    each None and `said` why (not in a git work tree, git not found, timed out, refused). git runs
    with a time-out, without the repository's file-system monitor (a program its config names) and
    without taking the index's lock."""
    unknown = {"commit": None, "clean": None, "plant_file": None}
    folder = resolved(plant_path).parent
    env = os.environ | {"GIT_OPTIONAL_LOCKS": "0", "LC_ALL": "C"}

    def git(*args: str) -> str:
        done = subprocess.run(["git", "-c", "core.fsmonitor=false", "-C", str(folder), *args],
                              capture_output=True, text=True,
                              timeout=GIT_TIMEOUT, env=env, stdin=subprocess.DEVNULL)
        if done.returncode != 0:
            first = (done.stderr.strip().splitlines() or [f"git {args[0]} failed"])[0]
            raise LookupError(first.removeprefix("fatal: "))
        return done.stdout

    try:
        if git("rev-parse", "--is-inside-work-tree").strip() != "true":
            return unknown | {"said": "not in a git work tree"}
        try:
            commit: str | None = git("rev-parse", "--verify", "-q", "HEAD").strip()
        except LookupError:
            commit = None  # a repository without a commit yet
        clean = git("status", "--porcelain=v1", "--untracked-files=no") == ""
        mark = git("status", "--porcelain=v1", "--untracked-files=all", "--ignored", "--",
                   resolved(plant_path).name)[:2]
        state = {"": "committed", "??": "untracked", "!!": "ignored"}.get(mark, "changed")
        return {"commit": commit, "clean": clean, "plant_file": state, "said": None if commit
                else "no commit yet"}
    except FileNotFoundError:
        return unknown | {"said": "git not found on PATH"}
    except subprocess.TimeoutExpired:
        return unknown | {"said": f"git did not answer within {GIT_TIMEOUT:g} s"}
    except (LookupError, OSError) as error:
        said = str(error)
        if "not a git repository" in said:
            return unknown | {"said": "not in a git work tree"}
        return unknown | {"said": f"git: {said}"}


def header(command: str, plant_path: Path, plant_name: str, plant_sha256: str, *, reason: str | None,
           plan_file: Path | None = None, argv: Sequence[str] | None = None,
           policy: dict[str, Any] | None = None) -> dict[str, Any]:
    """Who runs `command` on the plant file, where, with what and why — the first record of a journal and the
    `header` of its snapshot (`Journal` adds the journal's name and its link to the plant's journal before);
    `policy`: what the policy file the plant file names found and what was overridden, or None."""
    plan = None
    if plan_file is not None:
        try:
            plan = {"path": str(resolved(plan_file)),
                    "sha256": hashlib.sha256(plan_file.read_bytes()).hexdigest()}
        except OSError as error:
            raise UserError(f"{plan_file}: cannot read it ({error.strerror}) — nothing was written") from None
    return {
        "command": command,
        "user": platform.user_name(),
        "uid": platform.user_id(),
        "host": socket.gethostname(),
        "pid": os.getpid(),
        "prc3cfg": __version__,
        "argv": list(sys.argv if argv is None else argv),
        "plant": {"name": plant_name, "path": str(resolved(plant_path)), "sha256": plant_sha256,
                  "git": git_state(plant_path)},
        "plan_file": plan,
        "reason": reason_given(reason),
        "policy": policy,
    }


def records_dir(plant_path: Path, kind: str) -> Path:
    return plant_path.parent / ".prc3cfg" / kind


def check_writable(plant_path: Path) -> None:
    """`UserError` naming `.prc3cfg/` beside the plant file, and what to do, unless each folder an
    apply writes there can be made (or is a folder) and written: a nameless file of a few KiB is
    written and flushed in the nearest folder of each that exists, and leaves nothing behind."""
    records = plant_path.parent / ".prc3cfg"
    probed: set[Path] = set()
    try:
        for kind in KINDS:
            folder = records_dir(plant_path, kind)
            while not folder.exists() and not folder.is_symlink():
                folder = folder.parent
            if not folder.is_dir():
                raise NotADirectoryError(errno.ENOTDIR, "a file, not a folder", str(folder))
            if folder not in probed:
                probed.add(folder)
                with tempfile.TemporaryFile(dir=folder) as probe:
                    probe.write(bytes(4096))
                    probe.flush()
                    os.fsync(probe.fileno())
    except OSError as error:
        raise UserError(f"{error.filename or records}: cannot write there ({error.strerror}) — apply keeps "
                        "its snapshots and "
                        f"journal in {records}: make that a writable folder (or free space), then "
                        "apply again") from None


@dataclass(frozen=True, slots=True)
class LineTaken:
    """The line a snapshot's modules were read on: the bus's port, framing and the line's identities
    (`prc3cfg.shell.locks.line_keys`) — `restore` writes them back onto that line only."""

    port: str
    framing: str
    keys: tuple[str, ...]

    def same_line(self, port: str, framing: str, keys: tuple[str, ...]) -> bool:
        return framing == self.framing and (port == self.port or bool(set(keys) & set(self.keys)))


@dataclass(frozen=True, slots=True)
class Snapshot:
    plant_path: Path
    plant_sha256: str
    taken: str
    images: dict[tuple[str, int], ModuleImage]  # (bus, address) → image
    # bus → its line (empty in snapshots before 0.1.0's)
    lines: dict[str, LineTaken] = field(default_factory=dict)
    # who, where, what and why (`header`; none in snapshots written before records had headers)
    header: dict[str, Any] | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "format": SNAPSHOT_FORMAT,
            **({} if self.header is None else {"header": self.header}),
            "plant": str(self.plant_path),
            "plant_sha256": self.plant_sha256,
            "taken": self.taken,
            "lines": {bus: {"port": line.port, "framing": line.framing, "keys": list(line.keys)}
                      for bus, line in sorted(self.lines.items())},
            "modules": [{"bus": bus, **image.to_json()} for (bus, _), image in sorted(self.images.items())],
        }

    def save(self) -> Path:
        path, _ = self.saved()
        return path

    def saved(self) -> tuple[Path, str]:
        """Written (atomically): where, and the SHA-256 of what was written there. An apply saves its
        snapshot again as each further line's reads end: then it goes in place through a hidden
        temporary name (`write_atomically`), which a kill before the rename leaves beside it — whole
        where the file system has unnamed files, else perhaps cut short; either way not a .json, which
        is all the commands that read snapshots look at."""
        path = self.path
        path.parent.mkdir(parents=True, exist_ok=True)
        text = self._text()
        write_atomically(path, text)
        return path, hashlib.sha256(text.encode("utf-8")).hexdigest()

    @property
    def path(self) -> Path:
        """Where `saved` writes it."""
        return records_dir(self.plant_path, "snapshots") / f"{self.taken}-{self.plant_path.stem}.json"

    def _text(self) -> str:
        """The snapshot as JSON, one module a line: it is written before the first write on its line,
        which waits for it — json's indenting encoder is pure Python, five times slower than the
        compact one each module is encoded with (10 ms for 30 modules against 2)."""
        document = self.to_json()
        modules = ",\n  ".join(json.dumps(module) for module in document.pop("modules"))
        head = "".join(f"\n {json.dumps(key)}: {json.dumps(value)}," for key, value in document.items())
        return f'{{{head}\n "modules": [\n  {modules}\n ]\n}}\n'

    @classmethod
    def take(cls, plant_path: Path, plant_sha256: str, images: dict[tuple[str, int], ModuleImage],
             lines: dict[str, LineTaken], header: dict[str, Any] | None = None) -> Snapshot:
        return cls(resolved(plant_path), plant_sha256, _stamp(), dict(images), dict(lines), header)

    @classmethod
    def load(cls, path: Path) -> Snapshot:
        remedy = "name a file under .prc3cfg/snapshots/"
        try:
            data = read_json(path)
        except FileProblem as problem:
            raise UserError(f"{problem.where(path)}: {problem} — {remedy}") from None
        try:
            if not isinstance(data, dict) or data.get("format") != SNAPSHOT_FORMAT:
                raise ValueError(f'expected "format": "{SNAPSHOT_FORMAT}"')
            try:
                document = _SnapshotDocument.model_validate(data)
            except ValidationError as error:
                where = "the snapshot"
                raise ValueError(said(error, lambda loc: json_path(loc, where), _SnapshotDocument)) from None
            images = {(m.bus, image.address): image
                      for m, image in zip(document.modules, images_from_json(data["modules"], "modules"))}
            plant = Path(document.plant)
            beside = resolved(path).parent.parent.parent / plant.name  # PLANT_DIR/.prc3cfg/snapshots/…
            if not plant.is_absolute() or (not plant.exists() and beside.exists()):
                plant = beside  # an older relative path, or the plant repository moved
            lines = {bus: LineTaken(line.port, line.framing, tuple(line.keys))
                     for bus, line in document.lines.items()}
            return cls(plant, document.plant_sha256, document.taken, images, lines, document.header)
        except ValueError as error:
            raise UserError(f"{path}: not a readable snapshot ({error}) — {remedy}") from None


class _Placed(BaseModel):
    """A snapshot's module: the bus it was read on (the rest of it is its image, `images_from_json`). The
    snapshot's models are built when one is first loaded (`LATER`): restore and records read snapshots, a plan
    and an apply never — building them cost 1.5 ms of CPU of each."""

    model_config = LATER

    bus: Text


class _Line(BaseModel):
    model_config = LATER

    port: Text
    framing: Text
    keys: list[Text]


class _SnapshotDocument(BaseModel):
    """A snapshot as `Snapshot.load` reads it."""

    model_config = LATER

    modules: list[_Placed]
    plant: Text
    plant_sha256: Text
    taken: Text
    lines: dict[str, _Line] = Field(default_factory=dict)  # none in snapshots before 0.1.0's
    header: dict[str, Any] | None = None  # none in snapshots written before records had headers


def applied_copy(plant_path: Path) -> Path:
    """Where the copy of the plant file last applied in full is kept."""
    return records_dir(plant_path, "applied") / plant_path.name


def save_applied(plant_path: Path, text: bytes) -> None:
    """Keep the plant file just applied in full and verified (atomically)."""
    write_atomically(applied_copy(plant_path), text.decode("utf-8"))


class Journal:
    """Every exchange of one run, appended as JSON lines, each chained to the one before (`prev`);
    thread-safe (buses run in parallel).

    The file is made at the first record, after the `header`, so a run that never reached the line
    leaves none. `previous` is the plant's journal this one follows (`prc3cfg.shell.audit.follow`)."""

    def __init__(self, plant_path: Path, header: dict[str, Any] | None = None,
                 previous: dict[str, Any] | None = None) -> None:
        self.path = records_dir(plant_path, "journal") / f"{_stamp()}-{plant_path.stem}.jsonl"
        self.header = None if header is None else header | {"journal": self.path.name, "previous": previous}
        self._handle: TextIO | None = None
        self._prev: str | None = None
        self._lock = threading.Lock()

    def record(self, event: str, **fields: Any) -> None:
        with self._lock:
            if self._handle is None:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self._handle = open_text(self.path, "a")
                if self.header is not None:
                    self._write("header", self.header)
            self._write(event, fields)

    def _write(self, event: str, fields: dict[str, Any]) -> None:
        assert self._handle is not None
        now = datetime.now(UTC).isoformat()
        line = json.dumps({"time": now, "event": event, **fields, "prev": self._prev})
        self._handle.write(line + "\n")
        self._handle.flush()
        self._prev = line_hash(line.encode("utf-8"))

    def request(self, exchange: Exchange) -> None:
        """An attempt about to go out (before its frame leaves: a port that fails after sending
        leaves it in the journal all the same)."""
        self.record("request", bus=exchange.bus, address=exchange.address, request=exchange.request.hex(),
                    attempt=exchange.attempt)

    def exchange(self, exchange: Exchange) -> None:
        self.record(
            "exchange",
            bus=exchange.bus,
            address=exchange.address,
            request=exchange.request.hex(),
            reply=None if exchange.reply is None else exchange.reply.hex(),
            attempt=exchange.attempt,
            duration_s=round(exchange.duration, 6),
        )

    @property
    def begun(self) -> bool:
        """Whether the journal's file was made (its first record kept): a run that never reached the line has
        none."""
        return self._handle is not None

    def close(self) -> None:
        if self._handle is not None:
            self._handle.close()
