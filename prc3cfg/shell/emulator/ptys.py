"""The pseudo-terminals `prc3cfg emulator serve --pty` serves, where `prc3cfg ports` finds them.

The system lists no pseudo-terminal among its serial ports, yet an emulator's is the port a person
tries prc3cfg on without hardware. While one serves, a file `ptys/PID.json` (`{"path", "pid",
"modules"}`) in this user's state folder (`PRC3CFG_STATE_DIR`, else `platform.user_state_dir`) says
so; it goes when the emulator stops. A file whose process is gone (a killed emulator), whose
pseudo-terminal is gone, or that is no such record is left out — and removed.

Does not own the pseudo-terminal (`prc3cfg.shell.emulator.server`) nor the listing
(`prc3cfg.shell.link.ports`).
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Iterable, Iterator
from pathlib import Path

from prc3cfg.shell import platform
from prc3cfg.shell.files import FileProblem, read_json, write_atomically
from prc3cfg.shell.machine_folder import state_dirs


def folder() -> Path:
    return state_dirs()[-1] / "ptys"  # the user's own, or the one PRC3CFG_STATE_DIR chose


@contextlib.contextmanager
def served(path: str, modules: Iterable[int]) -> Iterator[None]:
    """While the block runs, `path` is a pseudo-terminal this process serves `modules` on (best effort:
    a folder that cannot be written only leaves it out of `prc3cfg ports`)."""
    record = folder() / f"{os.getpid()}.json"
    with contextlib.suppress(OSError):
        record.parent.mkdir(parents=True, exist_ok=True)
        write_atomically(record, json.dumps({"path": path, "pid": os.getpid(), "modules": sorted(modules)}))
    try:
        yield
    finally:
        with contextlib.suppress(OSError):
            record.unlink(missing_ok=True)


def serving() -> list[tuple[str, int, list[int]]]:
    """The pseudo-terminals emulators of this user serve now: path, process, modules."""
    found = []
    try:
        records = sorted(folder().glob("*.json"))
    except OSError:
        return []
    for record in records:
        try:
            entry = read_json(record)
            path, pid, modules = entry["path"], entry["pid"], entry["modules"]
            usable = (isinstance(path, str) and type(pid) is int and isinstance(modules, list)
                      and all(type(m) is int for m in modules)
                      and platform.process_alive(pid) and Path(path).exists())
        except (FileProblem, KeyError, TypeError):
            usable = False
        if usable:
            found.append((path, pid, modules))
        else:
            with contextlib.suppress(OSError):
                record.unlink()
    return found
