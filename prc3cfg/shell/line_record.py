"""The record of each line: what prc3cfg last read or verified its modules to hold, for every plant
file, checkout and user of the line on this machine — the base of a targeted read-back
(`prc3cfg.core.what_to_read`).

A command holding the line's lock reads it once (`LineRecord`). Every read updates it with what it
saw (`LineRecord.saw`: drift included, so the next plan writes it back); before an apply's first
write on a line the modules it writes are dropped from it (`forget`, durably, with what was seen),
and once a module verified, what it was verified to hold goes back in — two writes for a line an
apply changes, one for a line it only read. A
module's entry holds its image (a program not known: null), since when the oldest value in it is
known (and when each program read later than that was: `read_at`, what rolling evidence orders by),
by which command of which plant file and which user on which host, and when the entry was written; a
dropped module's entry holds no image, so that an older copy elsewhere cannot bring it back.

One file per identity of the line (`prc3cfg.shell.locks.line_keys`: two spellings of one line share
a record) and user (`platform.user_tag`: in the machine's folder, which every user of the line
writes, none may replace another's file) in `lines/` of the state folder
(`prc3cfg.shell.machine_folder.state_dirs`), written atomically under the line's lock, readable by every
user of the line (`platform.SHARED_READ`) and written by its maker alone. The newest entry of a
module across the files is the one taken — if it is this user's or root's: another user's file
vouches for nothing (it could say anything), but its newer entry still means the module changed
since, so it is not known (`read` says by whose claim, its words escaped). Every file is read as
another user may have made it: a regular file only, never through a link, never blocking, at most
`LIMIT` bytes, of this line (its `key`), each entry checked — what is not so is passed over
(`passed_over` says which, once per command) and the modules are read in full. Whatever stands at
this user's own name and is not this user's file (a link, a folder, a FIFO, another owner's file)
is moved aside, or where the folder does not allow it this user's record goes to the next free
name (`settle`): nobody can lock a user out of their record.

Does not own what is read (`prc3cfg.core.what_to_read`) nor when (`prc3cfg.api`).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import socket
import stat
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from prc3cfg.core.image import ModuleImage
from prc3cfg.core.text import shown
from prc3cfg.core.what_to_read import Known
from prc3cfg.errors import UserError
from prc3cfg.shell import platform
from prc3cfg.shell.files import NOT_FILES, FileProblem, Why, parse_json, read_owned, write_atomically
from prc3cfg.shell.machine_folder import LINES, folder, state_dirs

FORMAT = "prc3cfg-line-record/1"
KIND = LINES
WHAT = "the line's record of what its modules hold"
#: The largest record file read: one entry of a module with all 64 programs is about 5 KB, a line of
#: 30 such modules 150 KB — a tenth of this.
LIMIT = 2 * 2**20
#: The most names one user's record of a line may take: its own, then one free name after each that
#: another user's file holds (`_own_file`).
NAMES = 8


def now() -> str:
    """The time of a record entry: UTC, to the microsecond (entries are ordered by it)."""
    return datetime.now(UTC).isoformat(timespec="microseconds")


def who(command: str, plant_path: Path) -> str:
    """`by` of a record: "apply of /plants/a.yaml by ana@laptop-3"."""
    return f"{command} of {platform.resolved(plant_path)} by {platform.user_name()}@{socket.gethostname()}"


def _stem(key: str) -> str:
    return hashlib.sha256(key.encode()).hexdigest()[:32]


def _names(directory: Path, key: str) -> Iterator[Path]:
    """This user's names for the record of line `key`, in the order taken (`_own_file`)."""
    base = f"{_stem(key)}.{platform.user_tag()}"
    yield directory / KIND / f"{base}.json"
    for n in range(1, NAMES):
        yield directory / KIND / f"{base}.{n}.json"


def _own_file(directory: Path, key: str) -> Path:
    """Where this user keeps the record of line `key`: the first of its names where nothing stands or
    this user's own file does — never a name another user's file, a link or a folder holds."""
    for path in _names(directory, key):
        if not os.path.lexists(path) or platform.own_file(path):
            return path
    raise UserError(f"{directory / KIND}: every name this user may keep the record of line {shown(key)} "
                    "under holds another "
                    "user's file — remove them, or set PRC3CFG_STATE_DIR to a folder this user can write")


@dataclass(frozen=True, slots=True)
class _Entry:
    """A module's entry as a record file says it: when it was written, and the rest as written."""

    at: datetime
    fields: dict


def _parsed(key: str, data: bytes) -> dict[str, _Entry]:
    """The entries of a record file of line `key` by address: `FileProblem` where it is not one — not
    JSON, not a line record, another line's — and an entry whose address or time is no such is left out."""
    document = parse_json(data)
    if (not isinstance(document, dict) or document.get("format") != FORMAT
        or not isinstance(document.get("modules"), dict)):
        raise FileProblem(Why.NOT_JSON, "not a line record prc3cfg wrote")
    if document.get("key") != key:
        raise FileProblem(Why.NOT_JSON, "the record of another line (its key is not this line's)")
    entries = {}
    for address, entry in document["modules"].items():
        with contextlib.suppress(TypeError, ValueError):
            if (isinstance(entry, dict) and address.isdigit() and 1 <= int(address) <= 30
                and (at := datetime.fromisoformat(entry["at"])).tzinfo):
                entries[str(int(address))] = _Entry(at, entry)
    return entries


def _read(path: Path, key: str) -> tuple[dict[str, _Entry], int]:
    """The entries of the record file `path` of line `key`, and its owner; `FileProblem` where it is none."""
    data, owner = read_owned(path, LIMIT)
    return _parsed(key, data), owner


def _files(keys: Iterable[str]) -> Iterator[tuple[Path, str]]:
    """Every record file of the line with these identities, in every state folder, with its key."""
    for directory in state_dirs():
        for key in keys:
            with contextlib.suppress(OSError):
                yield from ((path, key) for path in sorted((directory / KIND).glob(f"{_stem(key)}.*.json")))


def _of_whom(path: Path) -> str:
    with contextlib.suppress(OSError):
        return f", made by {platform.uid_name(path.lstat().st_uid)}" if platform.OWNERS else ""
    return ""


class LineRecord:
    """The record of one line as one command holding the line's lock uses it. Its files are read once,
    when it is made: every prc3cfg command on the line holds that lock while it uses the record, so
    nothing writes this user's file meanwhile, and what another user's file said then is what the
    command goes by. The command's changes are known at once (`saw`) and written to this user's file
    where safety needs it (`write`): before a line's first frame of writes, after its verification, and
    at the end of the command for what was only read."""

    def __init__(self, keys: Iterable[str]) -> None:
        self.keys = tuple(keys)
        self._files: list[tuple[Path, dict[str, _Entry], int]] = []
        self._problems: list[tuple[Path, FileProblem]] = []
        for path, key in _files(self.keys):
            try:
                entries, owner = _read(path, key)
            except FileProblem as problem:
                self._problems.append((path, problem))
                continue
            self._files.append((path, entries, owner))
        # this command's entries, by address (an entry without an image: not known)
        self._changed: dict[str, dict] = {}
        self._waiting: set[str] = set()  # those not written yet

    def passed_over(self) -> list[str]:
        """One line for each file among the line's records that is not one: what it is, and that it was passed
        over."""
        return [f"{shown(str(path))}: {problem}{_of_whom(path)} — passed over as no record of the line (its "
                "modules are read in "
                "full); remove it" for path, problem in self._problems if problem.why is not Why.MISSING]

    def known(self) -> dict[int, Known]:
        """What the record says of each module it knows (`entries`)."""
        return self.entries()[0]

    def entries(self) -> tuple[dict[int, Known], dict[int, str]]:
        """What the record says of each module it knows — and the modules another user's file has a newer
        entry for than this user's and root's, with what that entry claims (escaped): not known (it changed
        since), and why each is read in full. This command's own changes are the newest."""
        trusted, claimed = self._newest()
        known, overruled = {}, {}
        for address, (entry, owner) in claimed.items():
            if address not in trusted or entry.at > trusted[address].at:
                by = entry.fields.get("by")
                overruled[int(address)] = ("another user's record is newer (it claims: "
                                           f"{shown(by) if isinstance(by, str) else 'a command'}, "
                                           f"{entry.at.isoformat()}; written by {platform.uid_name(owner)})")
        for address, entry in trusted.items():
            if int(address) not in overruled and (k := _known(entry.fields)) is not None:
                known[int(address)] = k
        return known, overruled

    def _newest(self) -> tuple[dict[str, _Entry], dict[str, tuple[_Entry, int]]]:
        """Per module, the newest entry of a file this user may believe (its own, root's, this command's) and
        the newest of any other user's with its owner, across the line's files in every state folder."""
        trusted: dict[str, _Entry] = {}
        claimed: dict[str, tuple[_Entry, int]] = {}
        for _, entries, owner in self._files:
            for address, entry in entries.items():
                if platform.trusted_owner(owner):
                    if address not in trusted or entry.at > trusted[address].at:
                        trusted[address] = entry
                elif address not in claimed or entry.at > claimed[address][0].at:
                    claimed[address] = (entry, owner)
        for address, fields in self._changed.items():
            trusted[address] = _Entry(datetime.fromisoformat(fields["at"]), fields)
            claimed.pop(address, None)
        return trusted, claimed

    def saw(self, changes: Mapping[int, Known | None]) -> None:
        """Set these modules' entries (None: the module is no longer known), to be written by `write`."""
        at = now()
        for address, k in changes.items():
            change: dict[str, Any] = {"at": at}
            if k is not None:
                change |= {"since": k.since, "by": k.by, "image": k.image.to_json()}
                if k.read_at:
                    change["read_at"] = {str(n): when for n, when in sorted(k.read_at.items())}
            self._changed[str(address)] = change
            self._waiting.add(str(address))

    def update(self, changes: Mapping[int, Known | None]) -> None:
        """`saw` these changes and `write` them."""
        self.saw(changes)
        self.write()

    def forget(self, addresses: Iterable[int]) -> None:
        """These modules are about to be written: not known until they verify (durably, before the first
        frame)."""
        self.update(dict.fromkeys(addresses))

    def write(self) -> None:
        """The changes not written yet into this user's file of each of the line's identities, in the state
        folder it writes (`machine_folder.folder`), with what that file held; `UserError` when it cannot."""
        if not self._waiting:
            return
        # the machine's, once an administrator made it; else this user's
        directory = folder(KIND, WHAT).parent
        held = {path: entries for path, entries, _ in self._files}
        try:
            for key in self.keys:
                path = _own_file(directory, key)
                kept = {address: entry.fields for address, entry in held.get(path, {}).items()}
                modules = dict(sorted((kept | self._changed).items(), key=lambda entry: int(entry[0])))
                write_atomically(path, json.dumps({"format": FORMAT, "key": key, "modules": modules}),
                                 platform.SHARED_READ)
        except OSError as error:
            raise UserError(f"cannot keep {WHAT} ({error.filename or directory}: {error.strerror}) — set "
                            "PRC3CFG_STATE_DIR to a "
                            "folder this user can write") from None
        self._waiting.clear()


def _known(fields: dict) -> Known | None:
    """What an entry says a module holds; None where it says nothing this prc3cfg can read."""
    try:
        if (fields.get("image") is not None and isinstance(fields.get("since"), str)
            and isinstance(fields.get("by"), str)):
            if datetime.fromisoformat(fields["since"]).tzinfo is None:
                return None  # a time without its zone (another tool's): its age cannot be told
            return Known(ModuleImage.from_json(fields["image"]), fields["since"], fields["by"],
                         _read_at(fields))
    except (TypeError, ValueError, KeyError, AttributeError):
        pass  # an entry this prc3cfg cannot read: the module is not known
    return None


def _read_at(fields: dict) -> dict[int, str]:
    """An entry's `read_at` (program → when, later than `since`): what is not one — not a program, not a
    time with its zone, not later than `since` — is left out, its program as old as `since` (never newer)."""
    since, said = datetime.fromisoformat(fields["since"]), fields.get("read_at")
    read_at = {}
    for number, when in (said.items() if isinstance(said, dict) else ()):
        with contextlib.suppress(TypeError, ValueError):
            if (number.isdigit() and 1 <= int(number) <= 64
                and (at := datetime.fromisoformat(when)).tzinfo and at > since):
                read_at[int(number)] = when
    return read_at


def settle(keys: Iterable[str]) -> list[str]:
    """This user's record names of the line with these identities made theirs again, under the line's lock:
    whatever stands at one and is not this user's file is moved aside (renamed `NAME.planted-TIME`) —
    where the folder does not let this user do that, the record goes to the next free name
    (`_own_file`). One line for each, naming both."""
    try:
        directory = folder(KIND, WHAT).parent
    except UserError:
        return []  # no record is kept: `LineRecord.write` says so
    said = []
    for key in keys:
        path = next(_names(directory, key))
        if not os.path.lexists(path) or platform.own_file(path):
            continue
        what = _what(path)
        aside = path.with_name(f"{path.name}.planted-{datetime.now(UTC):%Y%m%dT%H%M%S.%fZ}")
        try:
            os.rename(path, aside)
            said.append(f"{shown(str(path))} was not this user's record of the line ({what}) — moved aside "
                        f"to {shown(aside.name)}; "
                        "the record is written afresh")
        except OSError as error:
            with contextlib.suppress(UserError):
                said.append(f"{shown(str(path))} is not this user's record of the line ({what}) and cannot "
                            "be moved aside "
                            f"({error.strerror}) — this user's record is kept in "
                            f"{shown(_own_file(directory, key).name)} instead")
    return said


def _what(path: Path) -> str:
    """What stands at `path`: "a symbolic link", "a folder", "a named pipe (FIFO)", "a file of alice (uid
    1001)"."""
    status = path.lstat()
    if stat.S_ISLNK(status.st_mode):
        return "a symbolic link"
    if stat.S_ISDIR(status.st_mode):
        return "a folder"
    kind = NOT_FILES.get(stat.S_IFMT(status.st_mode), "a file")
    return f"{kind} of {platform.uid_name(status.st_uid)}" if platform.OWNERS else kind
