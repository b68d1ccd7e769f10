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
- The plant file last applied in full (`.prc3cfg/applied/<plant>.yaml`, a copy written after
  an apply that verified every module of the plant): what `plan` compares with to say which
  modules and programs left the plant file — they stay on the hardware as they are. (What the
  modules hold is the line's record's: `prc3cfg.shell.bases`.)

`check_writable` tells, before an apply opens a line, whether these can be written at all (a
read-only checkout, a full disk, a file where `.prc3cfg` belongs): an apply that could not keep
its snapshot and journal must not start writing modules.
"""

from __future__ import annotations

import errno
import json
import os
import tempfile
import threading
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TextIO

from pydantic import BaseModel, Field, ValidationError

from prc3cfg.core.contract import Text, json_path, said
from prc3cfg.core.image import ModuleImage, images_from_json
from prc3cfg.errors import UserError
from prc3cfg.shell.files import FileProblem, read_json, write_atomically
from prc3cfg.shell.link import Exchange
from prc3cfg.shell.platform import open_text

SNAPSHOT_FORMAT = "prc3cfg-snapshot/1"
#: The folders under `.prc3cfg/` an apply writes.
KINDS = ("snapshots", "journal", "applied")


def _stamp() -> str:
    return datetime.now(UTC).strftime("%Y%m%dT%H%M%S.%fZ")


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
        raise UserError(f"{error.filename or records}: cannot write there ({error.strerror}) — apply keeps its snapshots and "
                        f"journal in {records}: make that a writable folder (or free space), then apply again") from None


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
    lines: dict[str, LineTaken] = field(default_factory=dict)  # bus → its line (empty in snapshots before 0.1.0's)

    def to_json(self) -> dict[str, Any]:
        return {
            "format": SNAPSHOT_FORMAT,
            "plant": str(self.plant_path),
            "plant_sha256": self.plant_sha256,
            "taken": self.taken,
            "lines": {bus: {"port": line.port, "framing": line.framing, "keys": list(line.keys)} for bus, line in sorted(self.lines.items())},
            "modules": [{"bus": bus, **image.to_json()} for (bus, _), image in sorted(self.images.items())],
        }

    def save(self) -> Path:
        directory = records_dir(self.plant_path, "snapshots")
        directory.mkdir(parents=True, exist_ok=True)
        path = directory / f"{self.taken}-{self.plant_path.stem}.json"
        write_atomically(path, self._text())
        return path

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
             lines: dict[str, LineTaken]) -> Snapshot:  # fmt: skip
        return cls(plant_path.resolve(), plant_sha256, _stamp(), dict(images), dict(lines))

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
                raise ValueError(said(error, lambda loc: json_path(loc, "the snapshot"), _SnapshotDocument)) from None
            images = {(m.bus, image.address): image for m, image in zip(document.modules, images_from_json(data["modules"], "modules"))}
            plant = Path(document.plant)
            beside = path.resolve().parent.parent.parent / plant.name  # PLANT_DIR/.prc3cfg/snapshots/…
            if not plant.is_absolute() or (not plant.exists() and beside.exists()):
                plant = beside  # an older relative path, or the plant repository moved
            lines = {bus: LineTaken(line.port, line.framing, tuple(line.keys)) for bus, line in document.lines.items()}
            return cls(plant, document.plant_sha256, document.taken, images, lines)
        except ValueError as error:
            raise UserError(f"{path}: not a readable snapshot ({error}) — {remedy}") from None


class _Placed(BaseModel):
    """A snapshot's module: the bus it was read on (the rest of it is its image, `images_from_json`)."""

    bus: Text


class _Line(BaseModel):
    port: Text
    framing: Text
    keys: list[Text]


class _SnapshotDocument(BaseModel):
    """A snapshot as `Snapshot.load` reads it."""

    modules: list[_Placed]
    plant: Text
    plant_sha256: Text
    taken: Text
    lines: dict[str, _Line] = Field(default_factory=dict)  # none in snapshots before 0.1.0's


def applied_copy(plant_path: Path) -> Path:
    """Where the copy of the plant file last applied in full is kept."""
    return records_dir(plant_path, "applied") / plant_path.name


def save_applied(plant_path: Path, text: bytes) -> None:
    """Keep the plant file just applied in full and verified (atomically)."""
    write_atomically(applied_copy(plant_path), text.decode("utf-8"))


class Journal:
    """Every exchange of one apply, appended as JSON lines; thread-safe (buses run in parallel).

    The file is made at the first record, so an apply that never reached the line leaves none."""

    def __init__(self, plant_path: Path) -> None:
        self.path = records_dir(plant_path, "journal") / f"{_stamp()}-{plant_path.stem}.jsonl"
        self._handle: TextIO | None = None
        self._lock = threading.Lock()

    def record(self, event: str, **fields: Any) -> None:
        line = json.dumps({"time": datetime.now(UTC).isoformat(), "event": event, **fields})
        with self._lock:
            if self._handle is None:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self._handle = open_text(self.path, "a")
            self._handle.write(line + "\n")
            self._handle.flush()

    def request(self, exchange: Exchange) -> None:
        """An attempt about to go out (before its frame leaves: a port that fails after sending
        leaves it in the journal all the same)."""
        self.record("request", bus=exchange.bus, address=exchange.address, request=exchange.request.hex(), attempt=exchange.attempt)

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

    def close(self) -> None:
        if self._handle is not None:
            self._handle.close()
