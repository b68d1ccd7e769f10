"""Where an emulator keeps its modules: the state file `prc3-emulator/1` (interfaces.md §3)
and, while it runs, the journal beside it.

The state file is the contract other programs read. It is written whole, atomically
(`prc3cfg.shell.files.write_atomically`), so a killed emulator leaves either the old or the new
file, never half of one; and it is read bounded (`prc3cfg.shell.files.read_json`).

Rewriting the whole file after every write costs tens of milliseconds of CPU (30 modules),
so a running emulator (`Store`) appends every write it accepts to a journal beside the
state file, `NAME.json.journal`, and flushes it to disk (fdatasync) before the write is
answered — microseconds of CPU and one disk flush:

    prc3-emulator-journal/1 SHA256        the state file it follows: sha256 of its bytes
    ADDRESS MESSAGE                       a write a module accepted: its address 1..30 and
    …                                     the PRC 3 message in lower-case hex

`load_state` reads the state file and replays the journal on it with the device model, so
a killed emulator loses no write it acknowledged. A broadcast is one line per module it
changed. A last line cut short by a kill (no newline) was never acknowledged: ignored. A
journal that does not follow the state file beside it (its SHA256 is another file's) is
ignored: the emulator was killed after its state file took everything in, or the file was
replaced by hand. The journal is **compacted** — every module written into the state file,
a fresh journal begun — when the emulator starts with no state file or a journal left
behind, after every `COMPACT_EVERY` journal lines, on changes through the Python API (mode,
fault, Teach In: no message says them), and on exit, which then removes the journal:
**after a clean exit the state file holds everything; while an emulator runs, the journal
holds the tail.**

An emulator **owns** its state file while it runs: a kernel lock (`flock`) on `NAME.json.lock`
beside it, which names the owner (pid, since when) and dies with its process. A second
emulator of the same file — `emulator serve --state`, or the `emulator://` port of a plant
file — is refused at its start, naming the first: two would each keep their own modules
and the last to exit would overwrite the other's acknowledged writes. The lock file stays
(an empty one after a clean exit), as line locks do (`prc3cfg.shell.locks`).

A write is appended only while the state file and the journal are the very files the
store last wrote; when either was removed, replaced or changed meanwhile, or an append
failed, the write is saved by compaction instead. `OSError` when neither can save it: the
emulator then puts the modules back and does not answer the write.

Loading refuses, naming the module and the field, every value a module could not hold
because no message can carry it: each system parameter and program field must be a whole
number within the device's range for its kind (`prc3cfg.core.device.VALUE_RANGES`; P within
0..9999 and V within 1..600, the widest S1, S4 and S5 allow — all well inside a 16-bit
data word), the address S9 within 1..30, a program list of exactly 64, `mode`, `fault`,
`active_program` and `referenced` as interfaces.md §3 lists them. Relations between
values are not checked: a real module can hold a position above its S1 after a Teach In.
A journal line that is not an address and a message is refused with its line number.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import json
import logging
import os
import stat
from datetime import datetime, timezone
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from prc3cfg.core import device
from prc3cfg.core.device import VALUE_RANGES, ModuleState, value_range
from prc3cfg.core.image import DEFAULT_SYSTEM, MAX_MODULE_ADDRESS, PROGRAM_COUNT, PROGRAM_FIELDS, SYSTEM_KEYS, whole
from prc3cfg.core.render import plural
from prc3cfg.errors import UserError
from prc3cfg.shell.files import JSON_LIMIT, FileProblem, Why, read_json, read_regular, write_atomically

log = logging.getLogger(__name__)

FORMAT = "prc3-emulator/1"
JOURNAL_FORMAT = "prc3-emulator-journal/1"
COMPACT_EVERY = 1000  # journal lines between compactions: a restart replays at most this many

#: System parameters under which P and V may take every value any module allows.
_WIDEST = replace(DEFAULT_SYSTEM, S1=VALUE_RANGES["S1"][1], S4=VALUE_RANGES["S4"][1], S5=VALUE_RANGES["S5"][0])
#: The range a state file may hold, for each system parameter and program field.
_RANGES = {key: value_range(key, _WIDEST)[:2] for key in (*SYSTEM_KEYS, *PROGRAM_FIELDS)}


def load_state(path: Path) -> dict[int, ModuleState]:
    """The modules stored in `path` and its journal, by address; {} when neither exists yet."""
    modules = _load_file(path)
    for number, (address, message) in enumerate(_journal(path), 2):
        if not 1 <= address <= MAX_MODULE_ADDRESS:
            raise UserError(f"{journal_path(path)}:{number}: address {address} is outside 1..{MAX_MODULE_ADDRESS} — fix or delete the line")
        state = modules.get(address) or ModuleState.factory(address)  # a module the file lacks was served from factory defaults
        modules[address] = device.process(state, message).state
    return modules


def modules_to_serve(path: Path | None, addresses: list[int] | None) -> tuple[dict[int, ModuleState], dict[int, ModuleState]]:
    """(served, unserved) for `emulator serve --state PATH`: the modules at `addresses` — else
    those of the state file at `path`, else 1..30 — as the state file holds them or at factory
    defaults, and the modules the state file holds that are not served (kept in it untouched).

    A state file whose folder does not exist is refused (UserError): `serve` makes no folders,
    so a mistyped --state is said before the emulator starts, not kept somewhere new. (The
    emulators of `emulator://` ports make their folder, `.prc3cfg/emulators/`, themselves.)"""
    if path is not None:
        _check_folder(path)
    stored = load_state(path) if path is not None else {}
    wanted = addresses or sorted(stored) or range(1, MAX_MODULE_ADDRESS + 1)
    served = {address: stored.get(address) or ModuleState.factory(address) for address in wanted}
    return served, {address: state for address, state in stored.items() if address not in served}


def _check_folder(path: Path) -> None:
    """The folder of the state file `path` exists; UserError, naming --state, otherwise."""
    folder = path.parent
    try:
        found = os.stat(folder)
    except (FileNotFoundError, NotADirectoryError):
        raise UserError(f"--state {path}: the folder {folder} does not exist — create it first") from None
    except OSError as error:
        raise UserError(f"--state {path}: cannot reach the folder {folder} ({error.strerror}) — name a state file in a folder you can write to") from None
    if not stat.S_ISDIR(found.st_mode):
        raise UserError(f"--state {path}: {folder} is not a folder — name a state file in a folder")


def journal_path(path: Path) -> Path:
    return path.with_name(f"{path.name}.journal")


def owner_path(path: Path) -> Path:
    """The lock file by which a running emulator owns the state file `path`."""
    return path.with_name(f"{path.name}.lock")


def _journal(path: Path) -> list[tuple[int, bytes]]:
    """The writes of the journal beside the state file `path`, if it follows that file; [] otherwise."""
    try:
        lines = read_regular(journal_path(path), JSON_LIMIT).split(b"\n")[:-1]  # the last: b"" or a torn line
    except FileProblem as problem:
        if problem.why is Why.MISSING:
            return []
        raise UserError(f"{journal_path(path)}: {problem} — delete it to start from the state file alone") from None
    try:
        base = hashlib.sha256(read_regular(path, JSON_LIMIT)).hexdigest()
    except FileProblem:
        return []
    if not lines or lines[0] != f"{JOURNAL_FORMAT} {base}".encode():
        return []
    writes = []
    for number, line in enumerate(lines[1:], 2):
        address, _, message = line.partition(b" ")
        try:
            writes.append((int(address.decode("ascii")), bytes.fromhex(message.decode("ascii"))))
        except ValueError:
            raise UserError(f"{journal_path(path)}:{number}: not an address and a message in hex — fix or delete the line") from None
    return writes


def _load_file(path: Path) -> dict[int, ModuleState]:
    """The modules of the state file `path` alone; {} when it does not exist yet."""
    try:
        data = read_json(path)
    except FileProblem as problem:
        if problem.why is Why.MISSING:
            return {}
        remedy = "fix or delete it" if problem.why is Why.NOT_JSON else "give an emulator state file, or a path where none is yet"
        raise UserError(f"{problem.where(path)}: {problem} — {remedy}") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise UserError(f"{path}: not an emulator state file — expected \"format\": \"{FORMAT}\"")
    entries = data.get("modules", [])
    if not isinstance(entries, list):
        raise UserError(f"{path}: \"modules\" must be a list of modules — fix or delete it")
    modules: dict[int, ModuleState] = {}
    for index, entry in enumerate(entries):
        where = f"module entry {index}"
        try:
            if not isinstance(entry, dict):
                raise ValueError("is not an object")
            address = _whole(entry, "address", 1, MAX_MODULE_ADDRESS, name="address S9")
            where = f"module {address}"
            state = _module(entry)
        except ValueError as error:
            raise UserError(f"{path}: {where}: {error} — fix or delete the entry") from None
        if address in modules:
            raise UserError(f"{path}: module address {address} appears twice — keep one entry")
        modules[address] = state
    return modules


def _module(entry: dict[str, Any]) -> ModuleState:
    """A module from its checked state-file entry; ValueError names the field and what is wrong."""
    system = entry.get("system")
    if not isinstance(system, dict):
        raise ValueError("system: missing, or not an object")
    _values(system, SYSTEM_KEYS, "system")
    programs = entry.get("programs")
    if not isinstance(programs, list) or len(programs) != PROGRAM_COUNT:
        held = plural(len(programs), "program") if isinstance(programs, list) else repr(programs)
        raise ValueError(f"programs: a list of all {PROGRAM_COUNT} programs is needed, not {held}")
    for number, program in enumerate(programs, 1):
        if not isinstance(program, dict):
            raise ValueError(f"program {number}: {program!r} is not a program")
        _values(program, PROGRAM_FIELDS, f"program {number}")
    if entry.get("active_program") is not None:
        _whole(entry, "active_program", 1, PROGRAM_COUNT, name="active_program")
    if not isinstance(entry.get("fault"), str | None):
        raise ValueError(f"fault = {entry['fault']!r} must be null or the name of a fault")
    if not isinstance(entry.get("referenced", True), bool):
        raise ValueError(f"referenced = {entry['referenced']!r} must be true or false")
    return ModuleState.from_json(entry)  # mode and fault: the device model's own checks


def _values(data: dict[str, Any], keys: tuple[str, ...], where: str) -> None:
    """Each of `keys` in `data` a whole number within its range; ValueError naming the first that is not."""
    for key in keys:
        value = data.get(key)
        low, high = _RANGES[key]
        if type(value) is not int or not low <= value <= high:
            _whole(data, key, low, high, name=f"{where}: {key}")


def _whole(data: dict[str, Any], key: str, low: int, high: int, *, name: str) -> int:
    """`data[key]`, a whole number within low..high; ValueError saying what it is otherwise."""
    if key not in data:
        raise ValueError(f"{name} is missing")
    value = whole(data[key], name)
    if not low <= value <= high:
        raise ValueError(f"{name} = {value} is outside {low}..{high}")
    return value


def state_document(modules: Mapping[int, ModuleState]) -> dict:
    return {"format": FORMAT, "modules": [modules[a].to_json() for a in sorted(modules)]}


def save_state(path: Path, modules: Mapping[int, ModuleState]) -> None:
    """Write the state file atomically; OSError when it cannot be written."""
    write_atomically(path, _text(modules))


def _text(modules: Mapping[int, ModuleState]) -> str:
    return json.dumps(state_document(modules), indent=1)


class Store:
    """The state file and the journal of one running emulator. Not thread-safe: the emulator
    serialises every call. Each saving call is given every module (served and kept) by address."""

    def __init__(self, path: Path, *, compact_every: int = COMPACT_EVERY) -> None:
        self.path = path
        self.journal = journal_path(path)
        self.compact_every = compact_every
        self._fd: int | None = None  # the journal being appended to; None: the next write compacts
        self._files: tuple[tuple[int, ...], tuple[int, ...]] | None = None  # the state file and journal as last written
        self._entries = 0  # lines in the journal
        self._size = 0  # bytes in the journal
        self._without_journal = False  # a journal could not be begun (logged once)
        self._closed = False  # after `close`, nothing more is saved
        self._owner: int | None = None  # the locked `owner_path`, while this store owns the state file

    def start(self, modules: Mapping[int, ModuleState]) -> None:
        """Own the state file (UserError naming the emulator that does), then compact when there
        is no state file yet or a journal was left behind (a killed emulator's, replayed by
        `load_state`); OSError when the state file cannot be written."""
        self._own()
        try:
            if not self.path.exists() or self.journal.exists():
                self.compact(modules)
        except BaseException:
            self._disown()
            raise

    def _own(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)  # as the state file's first save would
        fd = os.open(owner_path(self.path), os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            try:
                record = json.loads(os.pread(fd, 4096, 0))
                holder = f"pid {record['pid']}, since {record['since']}"
            except (OSError, ValueError, KeyError, TypeError):
                holder = "starting"
            finally:
                os.close(fd)
            raise UserError(f"{self.path}: the state file is in use by another emulator ({holder}) — stop that "
                            "emulator first, or give this one another state file") from None  # fmt: skip
        record = {"pid": os.getpid(), "since": datetime.now(timezone.utc).isoformat(timespec="seconds")}
        with contextlib.suppress(OSError):  # the details only name the owner to a second emulator
            os.ftruncate(fd, 0)
            os.pwrite(fd, json.dumps(record).encode(), 0)
        self._owner = fd

    def _disown(self) -> None:
        if self._owner is not None:
            with contextlib.suppress(OSError):
                os.ftruncate(self._owner, 0)
            os.close(self._owner)  # the lock goes with the last descriptor
            self._owner = None

    def record(self, writes: list[tuple[int, bytes]], modules: Mapping[int, ModuleState]) -> None:
        """Make accepted writes durable — (address, message) per module changed — before they
        are answered: appended to the journal, or by compaction; OSError when neither can."""
        if self._closed:
            raise OSError(errno.ESHUTDOWN, "the emulator has closed its state file")
        if self._fd is None or self._entries + len(writes) > self.compact_every or not self._unchanged():
            self.compact(modules)
            return
        lines = "".join(f"{address} {message.hex()}\n" for address, message in writes).encode()
        try:
            if os.write(self._fd, lines) != len(lines):
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.journal))
            os.fdatasync(self._fd)
        except OSError:
            with contextlib.suppress(OSError):  # take back what reached the file, as the modules are put back
                os.ftruncate(self._fd, self._size)
            self._close_journal()  # and never append after a line that may be cut short: the next write compacts
            raise
        self._entries += len(writes)
        self._size += len(lines)

    def compact(self, modules: Mapping[int, ModuleState]) -> None:
        """Write every module into the state file, then begin a fresh journal; OSError when the
        state file cannot be written. A journal that cannot be begun leaves every later write to
        compaction (logged), the state file holding them."""
        if self._closed:
            raise OSError(errno.ESHUTDOWN, "the emulator has closed its state file")
        text = _text(modules)
        write_atomically(self.path, text)
        self._close_journal()
        header = f"{JOURNAL_FORMAT} {hashlib.sha256(text.encode()).hexdigest()}\n".encode()
        try:
            fd = os.open(self.journal, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND | os.O_CLOEXEC, 0o644)
            try:
                os.write(fd, header)
                os.fdatasync(fd)
                _sync_folder(self.path.parent)
                self._files = (_identity(os.stat(self.path)), _identity(os.fstat(fd))[:2])
            except OSError:
                os.close(fd)
                raise
        except OSError as error:
            with contextlib.suppress(OSError):  # an old journal must not outlive the state file it follows
                self.journal.unlink(missing_ok=True)
            if not self._without_journal:
                log.warning("%s: cannot keep a journal (%s) — every write rewrites the state file", self.journal, error.strerror or error)
                self._without_journal = True
            return
        if self._without_journal:
            log.warning("%s: keeping a journal again", self.journal)
            self._without_journal = False
        self._fd, self._entries, self._size = fd, 0, len(header)

    def close(self, modules: Mapping[int, ModuleState]) -> None:
        """On exit: the state file takes everything, and the journal is removed. OSError when
        the state file cannot be written; the journal is then kept for the next start. A write
        that comes later (a connection that outlived the emulator's close) is refused."""
        self._closed = True
        try:
            if self._fd is None and not self.journal.exists():
                return
            if self._fd is None or self._entries or not self._unchanged():  # after a failed append the journal holds lines
                save_state(self.path, modules)
            self._close_journal()
            self.journal.unlink(missing_ok=True)
            _sync_folder(self.path.parent)
        finally:
            self._disown()

    def _unchanged(self) -> bool:
        """Whether the state file and the journal are the files this store last wrote."""
        try:
            return (_identity(os.stat(self.path)), _identity(os.stat(self.journal))[:2]) == self._files
        except OSError:
            return False

    def _close_journal(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def _identity(status: os.stat_result) -> tuple[int, ...]:
    """A file as it is now: device, inode, size, modification time."""
    return status.st_dev, status.st_ino, status.st_size, status.st_mtime_ns


def _sync_folder(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def cannot_save(path: Path, error: OSError) -> str:
    """What went wrong saving the state file `path`, in a few words (for logs and errors)."""
    reason = error.strerror or str(error)
    if error.filename is not None and Path(error.filename) in path.parents:  # its folder is the trouble
        reason = f"{reason}: {error.filename}"
    return f"{path}: cannot save the emulator state file ({reason})"
