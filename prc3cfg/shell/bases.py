"""The record of each line: what prc3cfg last read or verified its modules to hold, for every plant
file, checkout and user of the line on this machine — the base of a targeted read-back
(`prc3cfg.core.targeting`).

Every read updates it with what it saw (`saw`: drift included, so the next plan writes it back);
before an apply's first write on a line the modules it writes are dropped from it (`forget`,
durably), and once a module verified, what it was verified to hold goes back in (`saw` again). A
module's entry holds its image (a program not known: null), since when the oldest value in it is
known, by which command of which plant file and which user on which host, and when the entry was
written; a dropped module's entry holds no image, so that an older copy elsewhere cannot bring it
back.

One file per identity of the line (`prc3cfg.shell.locks.line_keys`: two spellings of one line share
a record) in `lines/` of the machine's state folder (`prc3cfg.shell.releases.state_dirs`), written
atomically under the line's lock; the newest entry of a module across the files is the one taken.
A file another tool damaged, a link, or a file another user (not root) owns is read as no record
(the modules are then read in full).

Does not own what is read (`prc3cfg.core.targeting`) nor when (`prc3cfg.api`).
"""

from __future__ import annotations

import hashlib
import json
import socket
from collections.abc import Iterable, Mapping
from datetime import UTC, datetime
from pathlib import Path

from prc3cfg.core.image import ModuleImage
from prc3cfg.core.targeting import Known
from prc3cfg.errors import UserError
from prc3cfg.shell import platform
from prc3cfg.shell.files import FileProblem, read_json, write_atomically
from prc3cfg.shell.releases import folder, state_dirs

FORMAT = "prc3cfg-line-record/1"
KIND = "lines"
WHAT = "the line's record of what its modules hold"


def now() -> str:
    """The time of a record entry: UTC, to the microsecond (entries are ordered by it)."""
    return datetime.now(UTC).isoformat(timespec="microseconds")


def who(command: str, plant_path: Path) -> str:
    """`by` of a record: "apply of /plants/a.yaml by ana@laptop-3"."""
    return f"{command} of {plant_path.resolve()} by {platform.user_name()}@{socket.gethostname()}"


def _file(directory: Path, key: str) -> Path:
    return directory / KIND / f"{hashlib.sha256(key.encode()).hexdigest()[:32]}.json"


def _entries(path: Path) -> dict[str, dict]:
    """The entries of one record file by address; none where it is missing, not a record, a link, or
    another user's (in the machine's folder anyone may make a file: it is not believed)."""
    if not platform.trusted_file(path):
        return {}
    try:
        data = read_json(path)
    except FileProblem:
        return {}
    modules = data.get("modules") if isinstance(data, dict) and data.get("format") == FORMAT else None
    return {a: e for a, e in modules.items() if isinstance(e, dict) and isinstance(e.get("at"), str)} if isinstance(modules, dict) else {}


def load(keys: Iterable[str]) -> dict[int, Known]:
    """What the record of the line with these identities says of each module it knows."""
    newest: dict[str, dict] = {}
    for directory in state_dirs():
        for key in keys:
            for address, entry in _entries(_file(directory, key)).items():
                if address not in newest or entry["at"] > newest[address]["at"]:
                    newest[address] = entry
    known = {}
    for address, entry in newest.items():
        try:
            if entry.get("image") is not None and isinstance(entry.get("since"), str) and isinstance(entry.get("by"), str):
                if datetime.fromisoformat(entry["since"]).tzinfo is None:
                    continue  # a time without its zone (another tool's): its age cannot be told
                known[int(address)] = Known(ModuleImage.from_json(entry["image"]), entry["since"], entry["by"])
        except ValueError:
            continue  # an entry this prc3cfg cannot read: the module is not known
    return known


def update(keys: Iterable[str], changes: Mapping[int, Known | None]) -> None:
    """Set these modules' entries (None: the module is no longer known) in every file of the line, in
    the first state folder where this user can write them all (in the machine's sticky folder
    another user's file cannot be replaced: then the user's own, whose newer entries win for this
    user); `UserError` when none can be."""
    if not changes:
        return
    keys, at = tuple(keys), now()
    entries = {str(address): {"at": at} | ({} if k is None else {"since": k.since, "by": k.by, "image": k.image.to_json()})
               for address, k in changes.items()}  # fmt: skip
    problems = []
    for directory in state_dirs():
        try:
            for key in keys:
                path = _file(directory, key)
                modules = dict(sorted((_entries(path) | entries).items(), key=lambda entry: int(entry[0])))
                write_atomically(path, json.dumps({"format": FORMAT, "key": key, "modules": modules}))
            return
        except OSError as error:
            problems.append(f"{error.filename or directory}: {error.strerror}")
    folder(KIND, WHAT)  # says why no folder can be written
    raise UserError(f"cannot keep {WHAT} ({'; '.join(problems)}) — set PRC3CFG_STATE_DIR to a folder this user can write")


def forget(keys: Iterable[str], addresses: Iterable[int]) -> None:
    """These modules are about to be written: not known until they verify (durably, before the first frame)."""
    update(tuple(keys), dict.fromkeys(addresses))
