"""Where an emulator keeps its modules: the state file `prc3-emulator/1` (docs/files.md "Emulator state")
and, while it runs, the journal beside it.

The state file is the contract other programs read. It is written whole, atomically
(`prc3cfg.shell.files.write_atomically`), so a killed emulator leaves either the old or the new
file, never half of one; and it is read bounded (`prc3cfg.shell.files.read_json`).

Rewriting the whole file after every write costs tens of milliseconds of CPU (30 modules),
so a running emulator (`Store`) appends every write it accepts to a journal beside the
state file, `NAME.json.journal`, and flushes it to disk (fdatasync) before the write is
answered — microseconds of CPU and one disk flush:

    prc3-emulator-journal/2 GENERATION    the state file it follows: its "generation"
    ADDRESS MESSAGE                       a write a module accepted: its address 1..30 and
    …                                     the PRC 3 message in lower-case hex

The bond between the two is an identifier inside the state file, not its bytes: every save gives the state
file a new `"generation"` (a random hex string) and names the one it replaces, `"replaces"` — extension keys
of the file docs/files.md describes ("Emulator state") — so a state file that was reformatted, pretty-printed
or given a byte-order mark or a final newline still bonds with its journal (CRLF line ends and a byte-order
mark in the journal, blank lines and a last line cut by a kill — never acknowledged — are read past too).

`load_state` reads the state file and replays the journal on it with the device model, so
a killed emulator loses no write it acknowledged. A broadcast is one line per module it
changed. A journal of the generation the state file replaces is one the state file took in
(an emulator killed between saving the state file and beginning a fresh journal):
nothing to replay. Any other journal is refused, the emulator not started, in one line
naming both files and what to do — its header damaged, the state file of another
generation or of none (replaced, or rewritten by a tool that drops the extension keys),
missing or unreadable — never dropped in silence. (A journal of the older format
`prc3-emulator-journal/1 SHA256` is replayed when SHA256 is that of the state file's
bytes, and refused otherwise.) The journal is **compacted** — every module written into
the state file, a fresh journal begun — when the emulator starts with no state file or a
journal left behind, after every `COMPACT_EVERY` journal lines, on changes through the
Python API (mode, fault, Teach In: no message says them), and on exit, which then removes
the journal: **after a clean exit the state file holds everything; while an emulator runs,
the journal holds the tail.**

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
number within the device's range for its kind (`prc3cfg.core.device.widest_range`; P within
0..9999 and V within 1..600, the widest S1, S4 and S5 allow — all well inside a 16-bit
data word), the address S9 within 1..30, a program list of exactly 64, `mode`, `fault`,
`active_program` and `referenced` as docs/files.md lists them ("Emulator state"). Relations between
values are not checked: a real module can hold a position above its S1 after a Teach In.
A journal line that is not an address and a message is refused with its line number.

It is long because the state file and its journal are one contract: a start replays the journal onto
the file, and a compaction rewrites both; `Store` and the loaders share every check.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import logging
import os
import stat
import uuid
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated, Any

from pydantic import BaseModel, Field, Strict, ValidationError, create_model

from prc3cfg.core import device
from prc3cfg.core.contract import LATER, Flag, exactly, one_of, within, worded
from prc3cfg.core.device import ModuleState, widest_range
from prc3cfg.core.image import (
    MAX_MODULE_ADDRESS,
    PROGRAM_COUNT,
    PROGRAM_FIELDS,
    SYSTEM_KEYS,
    ModuleImage,
    Program,
    SystemParameters,
)
from prc3cfg.errors import UserError
from prc3cfg.shell import platform
from prc3cfg.shell.files import JSON_LIMIT, FileProblem, Why, read_json, read_regular, write_atomically

log = logging.getLogger(__name__)

FORMAT = "prc3-emulator/1"
JOURNAL_FORMAT = "prc3-emulator-journal/2"
_OLD_JOURNAL_FORMAT = "prc3-emulator-journal/1"  # bonded by a hash of the state file's bytes
COMPACT_EVERY = 1000  # journal lines between compactions: a restart replays at most this many

#: The range a state file may hold, for each system parameter and program field.
_RANGES = {key: widest_range(key) for key in (*SYSTEM_KEYS, *PROGRAM_FIELDS)}


def load_state(path: Path) -> dict[int, ModuleState]:
    """The modules stored in `path` and its journal, by address; {} when neither exists yet.
    UserError, naming both files and what to do, when a journal cannot be replayed onto the
    state file beside it."""
    journal = journal_path(path)
    lines = _journal_lines(path)
    if lines is None:
        return _load_file(path)
    keep = f"{journal} holds writes acknowledged since {path} was saved"
    try:
        data = read_json(path)
    except FileProblem as problem:
        if problem.why is Why.MISSING:
            raise UserError(f"{path}: missing, but its journal {keep} — put the state file back, or move "
                            "the journal "
                            "aside to start from factory modules") from None
        raise UserError(f"{problem.where(path)}: {problem}, and its journal {keep} — fix the state file "
                        "(the journal "
                        "replays onto it)") from None
    modules = _modules(path, data)
    header, writes = ((lines[0] if lines else b"").split(b" ") + [b""])[:2], lines[1:]
    generation, replaces = (data.get(key) for key in ("generation", "replaces"))
    if (header[0] == JOURNAL_FORMAT.encode() and generation is not None
        and header[1] == str(generation).encode()):
        pass
    elif (header[0] == JOURNAL_FORMAT.encode() and replaces is not None
          and header[1] == str(replaces).encode()):
        return modules  # the state file took this journal in
    elif (header[0] == _OLD_JOURNAL_FORMAT.encode()
          and header[1] == hashlib.sha256(read_regular(path, JSON_LIMIT)).hexdigest().encode()):
        pass
    else:
        found = (f"generation {header[1].decode('ascii', 'replace')}" if header[0] == JOURNAL_FORMAT.encode()
                 else "a damaged header" if lines else "no header (it is empty)")
        held = f"generation {generation}" if generation is not None else "no generation"
        raise UserError(f"{journal}: {found}, and {path} beside it has {held} — the journal cannot be "
                        "replayed onto it. "
                        "Put back the state file it follows, or move the journal aside to start from "
                        f"{path} alone "
                        "(its writes are then lost)")
    for number, (address, message) in enumerate(_writes(journal, writes), 2):
        if not 1 <= address <= MAX_MODULE_ADDRESS:
            raise UserError(f"{journal}:{number}: address {address} is outside 1..{MAX_MODULE_ADDRESS} — "
                            "fix or delete the line")
        # a module the file lacks was served from factory defaults
        state = modules.get(address) or ModuleState.factory(address)
        modules[address] = device.process(state, message).state
    return modules


def modules_to_serve(path: Path | None,
                     addresses: list[int] | None) -> tuple[dict[int, ModuleState], dict[int, ModuleState]]:
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
        raise UserError(f"--state {path}: cannot reach the folder {folder} ({error.strerror}) — "
                        "name a state file in a folder you can write to") from None
    if not stat.S_ISDIR(found.st_mode):
        raise UserError(f"--state {path}: {folder} is not a folder — name a state file in a folder")


def journal_path(path: Path) -> Path:
    return path.with_name(f"{path.name}.journal")


def owner_path(path: Path) -> Path:
    """The lock file by which a running emulator owns the state file `path`."""
    return path.with_name(f"{path.name}.lock")


def _journal_lines(path: Path) -> list[bytes] | None:
    """The lines of the journal beside the state file `path` — a byte-order mark, CR line ends
    and trailing blanks taken off, blank lines and a last line cut short (never acknowledged)
    left out; None when there is no journal."""
    try:
        text = read_regular(journal_path(path), JSON_LIMIT)
    except FileProblem as problem:
        if problem.why is Why.MISSING:
            return None
        raise UserError(f"{journal_path(path)}: {problem} — it holds writes acknowledged since {path} was "
                        "saved: make it readable") from None
    # the last: b"" or a torn line
    lines = [line.rstrip() for line in text.removeprefix(b"\xef\xbb\xbf").split(b"\n")[:-1]]
    return [line for line in lines if line]


def _writes(journal: Path, lines: list[bytes]) -> list[tuple[int, bytes]]:
    """The writes of journal lines (after the header); UserError naming the first that is not one."""
    writes = []
    for number, line in enumerate(lines, 2):
        address, _, message = line.partition(b" ")
        try:
            writes.append((int(address.decode("ascii")), bytes.fromhex(message.decode("ascii"))))
        except ValueError:
            raise UserError(f"{journal}:{number}: not an address and a message in hex — fix or "
                            "delete the line") from None
    return writes


def _load_file(path: Path) -> dict[int, ModuleState]:
    """The modules of the state file `path` alone; {} when it does not exist yet."""
    try:
        data = read_json(path)
    except FileProblem as problem:
        if problem.why is Why.MISSING:
            return {}
        remedy = ("fix or delete it" if problem.why is Why.NOT_JSON
                  else "give an emulator state file, or a path where none is yet")
        raise UserError(f"{problem.where(path)}: {problem} — {remedy}") from None
    return _modules(path, data)


def _modules(path: Path, data: object) -> dict[int, ModuleState]:
    """The modules of the state file `path` as read (`data`), checked (`_StateFile`)."""
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise UserError(f"{path}: not an emulator state file — expected \"format\": \"{FORMAT}\"")
    try:
        checked = _StateFile.model_validate(data)
    except ValidationError as error:
        detail = error.errors(include_url=False)[0]
        remedy = "fix or delete the entry" if len(detail["loc"]) > 1 else "fix or delete it"
        raise UserError(f"{path}: {worded(detail, lambda loc: _place(data, loc), _StateFile)} "
                        f"— {remedy}") from None
    modules: dict[int, ModuleState] = {}
    for entry in checked.modules:
        if entry.address in modules:
            raise UserError(f"{path}: module address {entry.address} appears twice — keep one entry")
        try:
            modules[entry.address] = entry.state()
        # what no one field says (`ModuleState`): firmware without F2 has no reads either
        except ValueError as error:
            raise UserError(f"{path}: module {entry.address}: {error} — fix or delete the entry") from None
    return modules


def _place(data: dict[str, Any], loc: Sequence[str | int]) -> str:
    """A place in a state file as its modules are named: "module 3: program 7: P", "module entry 0: address
    S9"."""
    if len(loc) < 2:
        return "modules"
    entry = data["modules"][loc[1]]
    address = entry.get("address") if isinstance(entry, dict) else None
    named = type(address) is int and 1 <= address <= MAX_MODULE_ADDRESS and loc[2:3] != ("address",)
    words = [f"module {address}" if named else f"module entry {loc[1]}"]
    for part in loc[2:]:
        if isinstance(part, int):  # a program's number, not its index
            words[-1] = f"program {part + 1}"
        else:
            words.append("address S9" if part == "address" else part)
    return ": ".join(words)


def _ranged(name: str, keys: tuple[str, ...]) -> type[BaseModel]:
    """A model of `keys`, each a whole number within its range (`_RANGES`), every one required."""
    fields: dict[str, Any] = {key: (Annotated[int, Strict(), within(*_RANGES[key])], ...) for key in keys}
    return create_model(name, __config__=LATER, **fields)


_System = _ranged("_System", SYSTEM_KEYS)
_Program = _ranged("_Program", PROGRAM_FIELDS)


class _Module(BaseModel):
    """A module of the state file: a value no message can carry is refused (the module docstring)."""

    model_config = LATER

    address: Annotated[int, Strict(), within(1, MAX_MODULE_ADDRESS)]
    system: _System  # type: ignore[valid-type]
    programs: Annotated[list[_Program], exactly(PROGRAM_COUNT)]  # type: ignore[valid-type]
    mode: Annotated[str, Strict(), one_of(device.MODES)] = "stop"
    active_program: Annotated[int, Strict(), within(1, PROGRAM_COUNT)] | None = None
    fault: Annotated[str, Strict(), one_of(device.FAULT_CODES)] | None = None
    referenced: Flag = True
    read_messages: Flag = True
    f2_messages: Flag = True

    def state(self) -> ModuleState:
        image = ModuleImage(self.address, SystemParameters(**vars(self.system)),
                            tuple(Program(**vars(program)) for program in self.programs))
        return ModuleState(image, self.mode, self.active_program, self.fault, self.referenced,
                           self.read_messages,
                           self.f2_messages)


class _StateFile(BaseModel):
    """The state file's models are built when one is first read (`LATER`): an emulator that starts from
    factory modules reads none — building them cost 3.5 ms of CPU of every command on `emulator://`."""

    model_config = LATER

    modules: list[_Module] = Field(default_factory=list)


def _generation(path: Path) -> str | None:
    """The "generation" of the state file `path`, if it has one (for the next save's "replaces")."""
    try:
        data = read_json(path)
    except FileProblem:
        return None
    generation = data.get("generation") if isinstance(data, dict) else None
    return str(generation) if generation is not None else None


def state_document(modules: Mapping[int, ModuleState], generation: str | None = None,
                   replaces: str | None = None) -> dict:
    """The state file of `modules`; with the `generation` its journal names, and the one it `replaces`."""
    bond = ({"generation": generation, **({"replaces": replaces} if replaces is not None else {})}
            if generation is not None else {})
    return {"format": FORMAT, **bond, "modules": [modules[a].to_json() for a in sorted(modules)]}


def save_state(path: Path, modules: Mapping[int, ModuleState], *, replaces: str | None = None) -> str:
    """Write the state file atomically, of a new generation (returned) that replaces `replaces`;
    OSError when it cannot be written."""
    generation = uuid.uuid4().hex
    write_atomically(path, json.dumps(state_document(modules, generation, replaces), indent=1))
    return generation


class Store:
    """The state file and the journal of one running emulator. Not thread-safe: the emulator
    serialises every call. Each saving call is given every module (served and kept) by address."""

    def __init__(self, path: Path, *, compact_every: int = COMPACT_EVERY) -> None:
        self.path = path
        self.journal = journal_path(path)
        self.compact_every = compact_every
        self._fd: int | None = None  # the journal being appended to; None: the next write compacts
        # the state file and journal as last written
        self._files: tuple[tuple[int, ...], tuple[int, ...]] | None = None
        self._entries = 0  # lines in the journal
        self._size = 0  # bytes in the journal
        self._without_journal = False  # a journal could not be begun (logged once)
        self._closed = False  # after `close`, nothing more is saved
        self._owner: int | None = None  # the locked `owner_path`, while this store owns the state file
        self._generation: str | None = None  # of the state file as this store last saved it (or found it)

    def start(self, modules: Mapping[int, ModuleState]) -> None:
        """Own the state file (UserError naming the emulator that does), then compact when there
        is no state file yet or a journal was left behind (a killed emulator's, replayed by
        `load_state`); OSError when the state file cannot be written."""
        self._own()
        self._generation = _generation(self.path)
        try:
            if self._taken_in():  # removed first: the next save's "replaces" will no longer name it
                self.journal.unlink()
                _sync_folder(self.path.parent)
            if not self.path.exists() or self.journal.exists():
                self.compact(modules)
        except BaseException:
            self._disown()
            raise

    def _taken_in(self) -> bool:
        """Whether the journal is one the state file took in (its generation is the one the state file
        replaces)."""
        try:
            data = read_json(self.path)
            lines = _journal_lines(self.path)
        except (FileProblem, UserError):
            return False
        replaces = data.get("replaces") if isinstance(data, dict) else None
        return (lines is not None and lines[:1] == [f"{JOURNAL_FORMAT} {replaces}".encode()]
                and replaces is not None)

    def _own(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)  # as the state file's first save would
        fd = os.open(owner_path(self.path), os.O_RDWR | os.O_CREAT | platform.NO_INHERIT | platform.NO_FOLLOW,
                     0o644)
        if not platform.try_lock(fd):
            try:
                record = json.loads(platform.read_at(fd, 4096, 0))
                holder = f"pid {record['pid']}, since {record['since']}"
            except (OSError, ValueError, KeyError, TypeError):
                holder = "starting"
            finally:
                os.close(fd)
            raise UserError(f"{self.path}: the state file is in use by another emulator ({holder}) — "
                            "stop that "
                            "emulator first, or give this one another state file") from None
        record = {"pid": os.getpid(), "since": datetime.now(UTC).isoformat(timespec="seconds")}
        with contextlib.suppress(OSError):  # the details only name the owner to a second emulator
            os.ftruncate(fd, 0)
            platform.write_at(fd, json.dumps(record).encode(), 0)
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
            platform.sync_data(self._fd)
        except OSError:
            with contextlib.suppress(OSError):  # take back what reached the file, as the modules are put back
                os.ftruncate(self._fd, self._size)
            # and never append after a line that may be cut short: the next write compacts
            self._close_journal()
            raise
        self._entries += len(writes)
        self._size += len(lines)

    def compact(self, modules: Mapping[int, ModuleState]) -> None:
        """Write every module into the state file, then begin a fresh journal; OSError when the
        state file cannot be written. A journal that cannot be begun leaves every later write to
        compaction (logged), the state file holding them."""
        if self._closed:
            raise OSError(errno.ESHUTDOWN, "the emulator has closed its state file")
        self._generation = save_state(self.path, modules, replaces=self._generation)
        self._close_journal()
        header = f"{JOURNAL_FORMAT} {self._generation}\n"
        try:
            # The fresh journal takes the old one's place whole, header and all: killed before, the old
            # journal is the one the state file replaces (nothing to replay); never an empty journal.
            write_atomically(self.journal, header)
            fd = os.open(self.journal, os.O_WRONLY | os.O_APPEND | platform.NO_INHERIT)
            try:
                self._files = (_identity(os.stat(self.path)), _identity(os.fstat(fd))[:2])
            except OSError:
                os.close(fd)
                raise
        except OSError as error:
            with contextlib.suppress(OSError):  # an old journal must not outlive the state file it follows
                self.journal.unlink(missing_ok=True)
            if not self._without_journal:
                log.warning("%s: cannot keep a journal (%s) — every write rewrites the state file",
                            self.journal, error.strerror or error)
                self._without_journal = True
            return
        if self._without_journal:
            log.warning("%s: keeping a journal again", self.journal)
            self._without_journal = False
        self._fd, self._entries, self._size = fd, 0, len(header.encode())

    def close(self, modules: Mapping[int, ModuleState]) -> None:
        """On exit: the state file takes everything, and the journal is removed. OSError when
        the state file cannot be written; the journal is then kept for the next start. A write
        that comes later (a connection that outlived the emulator's close) is refused."""
        self._closed = True
        try:
            if self._fd is None and not self.journal.exists():
                return
            # after a failed append the journal holds lines
            if self._fd is None or self._entries or not self._unchanged():
                self._generation = save_state(self.path, modules, replaces=self._generation)
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
    platform.sync_folder(folder)


def cannot_save(path: Path, error: OSError) -> str:
    """What went wrong saving the state file `path`, in a few words (for logs and errors)."""
    reason = error.strerror or str(error)
    if error.filename is not None and Path(error.filename) in path.parents:  # its folder is the trouble
        reason = f"{reason}: {error.filename}"
    return f"{path}: cannot save the emulator state file ({reason})"
