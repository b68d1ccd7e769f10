"""The record of each line: what prc3cfg last read or verified its modules to hold, for every plant
file, checkout and user of the line on this machine — the base of a targeted read-back
(`prc3cfg.core.what_to_read`).

Every read updates it with what it saw (`saw`: drift included, so the next plan writes it back);
before an apply's first write on a line the modules it writes are dropped from it (`forget`,
durably), and once a module verified, what it was verified to hold goes back in (`saw` again). A
module's entry holds its image (a program not known: null), since when the oldest value in it is
known, by which command of which plant file and which user on which host, and when the entry was
written; a dropped module's entry holds no image, so that an older copy elsewhere cannot bring it
back.

One file per identity of the line (`prc3cfg.shell.locks.line_keys`: two spellings of one line share
a record) and user (`platform.user_tag`: in the machine's folder, which every user of the line
writes, none may replace another's file) in `lines/` of the state folder
(`prc3cfg.shell.releases.state_dirs`), written atomically under the line's lock. The newest entry
of a module across the files is the one taken — if it is this user's or root's: another user's
file vouches for nothing (it could say anything), but its newer entry still means the module
changed since, so it is not known (`read` says by whose claim). A file another tool
damaged, or a link, is read as no record (the modules are then read in full).

Does not own what is read (`prc3cfg.core.what_to_read`) nor when (`prc3cfg.api`).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import socket
import stat
from collections.abc import Iterable, Mapping
from datetime import UTC, datetime
from pathlib import Path

from prc3cfg.core.image import ModuleImage
from prc3cfg.core.what_to_read import Known
from prc3cfg.errors import UserError
from prc3cfg.shell import platform
from prc3cfg.shell.files import FileProblem, read_json, write_atomically
from prc3cfg.shell.releases import LINES, folder, state_dirs

FORMAT = "prc3cfg-line-record/1"
KIND = LINES
WHAT = "the line's record of what its modules hold"


def now() -> str:
    """The time of a record entry: UTC, to the microsecond (entries are ordered by it)."""
    return datetime.now(UTC).isoformat(timespec="microseconds")


def who(command: str, plant_path: Path) -> str:
    """`by` of a record: "apply of /plants/a.yaml by ana@laptop-3"."""
    return f"{command} of {plant_path.resolve()} by {platform.user_name()}@{socket.gethostname()}"


def _stem(key: str) -> str:
    return hashlib.sha256(key.encode()).hexdigest()[:32]


def _own_file(directory: Path, key: str) -> Path:
    return directory / KIND / f"{_stem(key)}.{platform.user_tag()}.json"


def _entries(path: Path) -> dict[str, dict]:
    """The entries of one record file by address; none where it is missing, not a record, or a link."""
    try:
        if not stat.S_ISREG(path.lstat().st_mode):
            return {}
        data = read_json(path)
    except (OSError, FileProblem):
        return {}
    modules = data.get("modules") if isinstance(data, dict) and data.get("format") == FORMAT else None
    return {a: e for a, e in modules.items() if isinstance(e, dict) and isinstance(e.get("at"), str)} if isinstance(modules, dict) else {}


def _newest(keys: Iterable[str]) -> tuple[dict[str, dict], dict[str, dict]]:
    """Per module, the newest entry of a file this user may believe (its own, root's) and the newest of
    any other user's, across the line's files in every state folder."""
    trusted: dict[str, dict] = {}
    claimed: dict[str, dict] = {}
    for directory in state_dirs():
        for key in keys:
            try:
                paths = sorted((directory / KIND).glob(f"{_stem(key)}*.json"))
            except OSError:
                continue
            for path in paths:
                newest = trusted if platform.trusted_file(path) else claimed
                for address, entry in _entries(path).items():
                    if address not in newest or entry["at"] > newest[address]["at"]:
                        newest[address] = entry
    return trusted, claimed


def load(keys: Iterable[str]) -> dict[int, Known]:
    """What the record of the line with these identities says of each module it knows (`read`)."""
    return read(keys)[0]


def read(keys: Iterable[str]) -> tuple[dict[int, Known], dict[int, str]]:
    """What the record of the line with these identities says of each module it knows — and the
    modules another user's file has a newer entry for than this user's and root's, with what that
    entry claims: not known (it changed since), and why each is read in full."""
    trusted, claimed = _newest(keys)
    known, overruled = {}, {}
    for address, entry in claimed.items():
        if address not in trusted or entry["at"] > trusted[address]["at"]:
            by = entry.get("by") if isinstance(entry.get("by"), str) else "a command"
            with contextlib.suppress(ValueError):
                overruled[int(address)] = f"another user's record is newer (it claims: {by}, {entry['at']})"
    for address, entry in trusted.items():
        if address in claimed and claimed[address]["at"] > entry["at"]:
            continue
        try:
            if entry.get("image") is not None and isinstance(entry.get("since"), str) and isinstance(entry.get("by"), str):
                if datetime.fromisoformat(entry["since"]).tzinfo is None:
                    continue  # a time without its zone (another tool's): its age cannot be told
                known[int(address)] = Known(ModuleImage.from_json(entry["image"]), entry["since"], entry["by"])
        except ValueError:
            continue  # an entry this prc3cfg cannot read: the module is not known
    return known, overruled


def update(keys: Iterable[str], changes: Mapping[int, Known | None]) -> None:
    """Set these modules' entries (None: the module is no longer known) in this user's file of each of the
    line's identities, in the state folder it writes (`releases.folder`); `UserError` when it cannot."""
    if not changes:
        return
    keys, at = tuple(keys), now()
    entries = {str(address): {"at": at} | ({} if k is None else {"since": k.since, "by": k.by, "image": k.image.to_json()})
               for address, k in changes.items()}  # fmt: skip
    directory = folder(KIND, WHAT).parent  # the machine's, once an administrator made it; else this user's
    try:
        for key in keys:
            path = _own_file(directory, key)
            modules = dict(sorted((_entries(path) | entries).items(), key=lambda entry: int(entry[0])))
            write_atomically(path, json.dumps({"format": FORMAT, "key": key, "modules": modules}))
    except OSError as error:
        raise UserError(f"cannot keep {WHAT} ({error.filename or directory}: {error.strerror}) — set PRC3CFG_STATE_DIR to a "
                        "folder this user can write") from None  # fmt: skip


def forget(keys: Iterable[str], addresses: Iterable[int]) -> None:
    """These modules are about to be written: not known until they verify (durably, before the first frame)."""
    update(tuple(keys), dict.fromkeys(addresses))
