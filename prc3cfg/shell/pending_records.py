r"""Records pending on a line until told or cleared: axis releases nobody has been told of yet — kept on disk
from before the frame leaves until an account has named them — and modules in E12 or another fault state.

A 10h or 20h releases the axes of every module it reaches (a broadcast: of every module on the
line). Before such a frame is put on the line — and as soon as a read is answered as a write is,
on a line where damage can turn one into the other — a record of it — the line's identities, bus,
address (0 for a broadcast) and module, the time, the process and the apply's journal — is
appended to this run's file and flushed to disk (`fsync`), so a process killed a moment later
still leaves someone who knows. The record is removed only once an apply's closing account,
which lists the module on its reference-travel list (or shows its system parameters unchanged),
has been printed (`Releases.told`). Until then every command that opens the line — read, plan,
apply, restore, scan, import, adopt — reports it (`of_line`), and the next apply on the line
lists it in its own account and so clears it.

The records live in the machine's folder (`prc3cfg.shell.machine_folder`: /var/lib/prc3cfg; Windows:
%ProgramData%\prc3cfg), which an administrator makes once with the serial ports' group (`prc3cfg
setup-machine`: every user of the lines writes there, none removes another's file) — else in the user's own
state folder, which no other user sees (`machine_folder.unshared` is the hint that says so). One file per
apply (`<time>-<pid>.jsonl`), whatever the plant file's folder: `scan`, which has no plant file, finds them by
the line's identities (`prc3cfg.shell.locks.line_keys`).

Another user's file there is a claim (`Pending.owner`): read as another user may have made it — a
regular file only, never through a link, never blocking, at most `LIMIT` bytes, each field of its
type (`passed_over` names what is none) — and told as their claim, every field escaped. It may make
prc3cfg read (an E12 claim: the module is read in full, `prc3cfg.api`), never write: only this
user's or root's E12 record, or the module's own refusal, makes a plan send a 10h/20h.

Does not own when a release happens (`prc3cfg.shell.apply`) nor what is said of it (`prc3cfg.cli`).
"""

from __future__ import annotations

import contextlib
import json
import os
import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from prc3cfg.core.error_codes import FAULT_STATES, fault_said
from prc3cfg.core.text import shown
from prc3cfg.shell import platform
from prc3cfg.shell.files import FileProblem, Why, read_owned, write_atomically
from prc3cfg.shell.machine_folder import RELEASES, folder, state_dirs

#: The largest file of records read: an apply's records are a line of about 300 bytes per module
#: released or in E12 — 8 buses × 30 modules twice over is 150 KB, a fourteenth of this.
LIMIT = 2 * 2**20

#: What a record is of: an axis release nobody was told of, or a module that reported E12 ("system
#: parameters not set", code 23) — which only a 10h/20h clears, so the next plan writes them first —
#: or another fault state (E09, E21, …: its `code`), which a read cannot see: told by every command
#: that opens the line until a write to the module is acknowledged.
RELEASE, E12, FAULT = "release", "e12", "fault"


@dataclass(frozen=True, slots=True)
class Pending:
    """A 10h/20h that went out (or was about to) — or a read a module executed as a write — that no
    account has named yet; or (`kind` E12) a module that answered code 23 and has not been cleared.
    Its fields are as its file says: another user's (`owner`) could say anything."""

    keys: tuple[str, ...]  # the line's identities
    bus: str
    address: int  # 0: a broadcast, which reached every module on the line
    name: str  # the module, or for a broadcast the modules the plant knows on the line
    time: str
    pid: int
    # the prc3cfg command that sent it: apply, restore — or plan, read, when a read became a write
    command: str
    journal: str | None
    file: Path
    kind: str = RELEASE
    # who wrote it, where that is another user ("alice (uid 1001)"): a claim; None: this user or root
    owner: str | None = None
    code: int | None = None  # `kind` FAULT: the code the module refused a write with (`FAULT_STATES`)

    def said(self) -> str:
        """One line: which module, when, which run — and what to do; every field escaped, another user's told
        as their claim."""
        who = (f"bus {shown(self.bus)}, module {self.address} ({shown(self.name)})" if self.address
               else f"bus {shown(self.bus)}, every module on the line ({shown(self.name)})")
        journal = f", journal {shown(self.journal)}" if self.journal else ""
        run = f"pid {self.pid}, {shown(self.time)}{journal}"
        said = (f"{who}: is in {fault_said(self.code)} — it refused a write of prc3cfg "
                f"{shown(self.command)} ({run}) so, and a "
                "read cannot tell whether it still is: its values may match the plant file, the machine is "
                "not in production "
                "order; clear the fault on the module — the next write to it acknowledged clears this"
                if self.kind == FAULT and self.code is not None else
                f"{who}: prc3cfg {shown(self.command)} ({run}) sent it a 10h/20h, or a frame it took for "
                "one, and no account has "
                "said so — its axes may be released: travel to the reference point before production; the "
                "next apply on this "
                "line lists it and clears this")
        return said if self.owner is None else f"{self.owner}'s record says: {said}"


def of_line(keys: Iterable[str], kind: str | None = RELEASE) -> list[Pending]:
    """Every record of `kind` (None: of every kind) on a line with one of `keys` that is not cleared yet
    (another user's in the machine's folder too: a claim, `owner` says whose — told all the same, an untold
    release errs the wrong way; it may make prc3cfg read, never write)."""
    wanted = set(keys)
    found = []
    for path in _files():
        entries, owner = _entries(path)
        for entry in entries:
            record = _pending(entry, path,
                              None if platform.trusted_owner(owner) else platform.uid_name(owner))
            if record is not None and kind in (None, record.kind) and wanted & set(record.keys):
                found.append(record)
    return found


def _pending(entry: dict[str, Any], path: Path, owner: str | None) -> Pending | None:
    """The record a line of a file says, every field of its type (None: it is no record)."""
    texts = [text for name in ("bus", "name", "time", "command") if isinstance(text := entry.get(name), str)]
    keys, address, pid, journal, kind, code = (entry.get(name)
                                               for name in ("keys", "address", "pid", "journal", "kind",
                                                            "code"))
    if not (isinstance(keys, list) and all(isinstance(key, str) for key in keys) and len(texts) == 4
            and type(address) is int and type(pid) is int and (journal is None or isinstance(journal, str))
            and kind in (None, RELEASE, E12, FAULT)
            and (kind != FAULT or (type(code) is int and code in FAULT_STATES))):
        return None
    bus, name, time, command = texts
    return Pending(tuple(keys), bus, address, name, time, pid, command, journal, path, kind or RELEASE, owner,
                   code if kind == FAULT else None)


def _files() -> list[Path]:
    """The files of records in every state folder."""
    found: list[Path] = []
    for directory in state_dirs():
        with contextlib.suppress(OSError):
            found += sorted((directory / RELEASES).glob("*.jsonl"))
    return found


def passed_over() -> list[str]:
    """One line for each file among the records of axis releases that is none — a FIFO, a link, a folder,
    more than `LIMIT` bytes: what it is, and that it was passed over."""
    said = []
    for path in _files():
        try:
            read_owned(path, LIMIT)
        except FileProblem as problem:
            if problem.why is not Why.MISSING:
                said.append(f"{shown(str(path))}: {problem} — passed over as no record of an axis release; "
                            "remove it")
    return said


def _entries(path: Path) -> tuple[list[dict], int]:
    """The records of a file — a line cut by a kill as it was written is left out (its frame never left) —
    and its owner; none where it is no file of records (`passed_over`)."""
    try:
        data, owner = read_owned(path, LIMIT)
    except FileProblem:
        return [], 0
    entries = []
    for line in data.decode("utf-8", "replace").splitlines():
        try:
            entry = json.loads(line)
        except (ValueError, RecursionError):
            continue
        if isinstance(entry, dict):
            entries.append(entry)
    return entries, owner


class Releases:
    """The records of one apply: `record` before a release frame leaves; `told` once the account is out."""

    def __init__(self, command: str, journal: Path | None = None) -> None:
        self.command, self.journal = command, journal
        self._path: Path | None = None
        self._lock = threading.Lock()
        self._recorded: set[tuple[str, str, int]] = set()

    def record(self, keys: tuple[str, ...], bus: str, address: int, name: str, kind: str = RELEASE,
               code: int | None = None) -> None:
        """Durably, before the frame leaves: a 10h/20h to `address` on the line `keys` (once per module);
        or a module that reported a fault state (`kind` E12, FAULT with its `code`)."""
        with self._lock:
            if (kind, bus, address) in self._recorded:
                return
            stamp = datetime.now(UTC)
            if self._path is None:
                self._path = folder() / f"{stamp.strftime('%Y%m%dT%H%M%S.%fZ')}-{os.getpid()}.jsonl"
            line = json.dumps({"kind": kind, "keys": list(keys), "bus": bus, "address": address, "name": name,
                               "time": stamp.isoformat(timespec="seconds"), "pid": os.getpid(),
                               "command": self.command,
                               "journal": None if self.journal is None else str(self.journal)}
                              | ({"code": code} if code is not None else {}))
            fd = os.open(self._path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | platform.NO_INHERIT, 0o644)
            try:
                os.write(fd, (line + "\n").encode())
                os.fsync(fd)
            finally:
                os.close(fd)
            self._recorded.add((kind, bus, address))

    @property
    def path(self) -> Path | None:
        """The file of these records, once there is one: what `told` names."""
        return self._path


def told(path: Path | None, earlier: Iterable[Pending] = ()) -> None:
    """The account naming an apply's releases — those of its records' file at `path` — and the
    `earlier` ones it listed has been printed: those records go (others — another line's, an E12 — stay)."""
    cleared(earlier)
    if path is not None:
        _keep(path, lambda entry: entry.get("kind", RELEASE) != RELEASE)


def cleared(records: Iterable[Pending]) -> None:
    """These records are settled: out of their files."""
    gone: dict[Path, set[tuple[str, str, int]]] = {}
    for record in records:
        gone.setdefault(record.file, set()).add((record.kind, record.bus, record.address))
    for path, which in gone.items():
        def keep(entry: dict[str, Any], which: set[tuple[str, str, int]] = which) -> bool:
            return (entry.get("kind", RELEASE), entry.get("bus"), entry.get("address")) not in which

        _keep(path, keep)


def _keep(path: Path, keep: Callable[[dict], bool]) -> None:
    """Only the records of `path` that `keep` says; the file goes when none is left. Where this user
    may not change it (another user's record in the machine's sticky folder) it stays as it is: the
    next command warns once more, which errs the safe way."""
    kept = [entry for entry in _entries(path)[0] if keep(entry)]
    with contextlib.suppress(OSError):
        if kept:
            write_atomically(path, "".join(json.dumps(entry) + "\n" for entry in kept))
        else:
            path.unlink(missing_ok=True)
