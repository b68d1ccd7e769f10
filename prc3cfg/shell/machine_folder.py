r"""rThe machine's folder: where records every user of a line must see are kept, and how an administrator
rmakes it.

A line's records that another user's command must see — axis releases nobody was told of and E12/fault claims
(`prc3cfg.shell.pending_records`), what the modules hold (`prc3cfg.shell.line_record`) — live in the machine's
folder (`machine_dir`: /var/lib/prc3cfg; Windows: %ProgramData%\prc3cfg), a folder each (`RELEASES`, `LINES`).
An administrator makes it once with the serial ports' group (`setup_machine`, `prc3cfg setup-machine`): every
user of the lines writes there, none removes another's file. Until it is there each user keeps them in their
own state folder, which no other user sees (`unshared` is the hint that says so); `PRC3CFG_STATE_DIR` chooses
one folder for everything (`state_dirs`), and `folder` is where this process writes a kind of record.

Does not own what the records hold nor how they are read (`pending_records`, `line_record`).
"""

from __future__ import annotations

import os
import stat
import sys
from pathlib import Path

from prc3cfg.errors import UserError
from prc3cfg.shell import platform

#: The machine's folder (it lasts across a reboot, unlike /run: /var/lib/prc3cfg; Windows:
#: %ProgramData%\prc3cfg): an administrator makes it once for every user of the lines (`setup_machine`);
#: `PRC3CFG_MACHINE_STATE_DIR` names another. Until it is there, each user keeps the records in their own
#: state folder — which no other user sees: `unshared` says so.
SYSTEM_STATE_DIR = platform.SYSTEM_STATE_DIR
#: What the machine's folder holds, a folder each: axis releases not yet told, the lines' records
#: (`prc3cfg.shell.line_record`).
RELEASES, LINES = "releases", "lines"


def machine_dir() -> Path:
    return Path(os.environ.get("PRC3CFG_MACHINE_STATE_DIR") or SYSTEM_STATE_DIR)


def state_dirs() -> list[Path]:
    """Where records are looked for: `PRC3CFG_STATE_DIR` alone, else the machine's folder and the user's."""
    if (chosen := os.environ.get("PRC3CFG_STATE_DIR")):
        return [Path(chosen)]
    return [machine_dir(), platform.user_state_dir()]


def _machine_problem(kind: str) -> str | None:
    """Why this user cannot keep records of `kind` in the machine's folder (None: it can). The folder
    and its `kind` folder are made by an administrator, never on the way; one another user (not root)
    owns, or a link in their place, is not used: that user could remove or forge what is in it."""
    for folder in (machine_dir(), machine_dir() / kind):
        try:
            status = folder.lstat()
        except FileNotFoundError:
            return f"{folder} is not there"
        except OSError as error:
            return f"{folder}: {error.strerror}"
        if not stat.S_ISDIR(status.st_mode):
            return f"{folder} is not a folder"
        if not platform.trusted_owner(status.st_uid):
            return f"{folder} belongs to {platform.uid_name(status.st_uid)}, not to root"
    if not os.access(machine_dir() / kind, os.W_OK):
        return f"{machine_dir() / kind} is not writable by {platform.user_name()}"
    return None


def folder(kind: str = RELEASES, what: str = "the record of an axis release") -> Path:
    """The folder this process writes its records of `kind` into: the first of `state_dirs` it can write
    (the machine's folder only once an administrator made it)."""
    problems = []
    for directory in state_dirs():
        folder = directory / kind
        if directory == machine_dir() and not os.environ.get("PRC3CFG_STATE_DIR"):
            if (problem := _machine_problem(kind)) is None:
                return folder
            problems.append(problem)
            continue
        try:
            folder.mkdir(parents=True, exist_ok=True)
            if os.access(folder, os.W_OK):
                return folder
            problems.append(f"{folder}: not writable")
        except OSError as error:
            problems.append(f"{folder}: {error.strerror}")
    raise UserError(f"cannot keep {what} ({'; '.join(problems)}) — nothing was written; "
                    "set PRC3CFG_STATE_DIR to a folder this user can write")


def unshared() -> str | None:
    """The hint for a user whose records of axis releases and of what the modules hold go to their own
    state folder, which the machine's other users do not see (None: they go to the machine's folder,
    or `PRC3CFG_STATE_DIR` chose where)."""
    if os.environ.get("PRC3CFG_STATE_DIR"):
        return None
    problems = [problem for kind in (RELEASES, LINES) if (problem := _machine_problem(kind)) is not None]
    if not problems:
        return None
    return ("this machine's records of axis releases and of what the modules hold are kept in "
            f"{platform.user_state_dir()}, "
            f"which its other users do not see ({problems[0]}) — an administrator makes the shared folder "
            f"once: {_AS_ADMINISTRATOR}")


#: How an administrator runs setup-machine, in the system's own words.
_AS_ADMINISTRATOR = ("prc3cfg setup-machine from a prompt opened with Run as administrator"
                     if sys.platform == "win32"
                     else "sudo prc3cfg setup-machine")


def setup_machine(group: str | None = None) -> tuple[Path, str | None]:
    """The machine's folder and its `RELEASES` and `LINES` folders, for every user of the lines: owned
    by this user (an administrator) and the serial ports' group (`group`, else dialout or uucp), which
    writes in them and whose files none of them may remove or replace but their maker (mode 3775).
    Made or put right; the folder and the group."""
    if group is not None and not platform.OWNERS:
        raise UserError(f"--group {group}: this system shares the folder by its rights, not by a group — "
                        "run setup-machine without "
                        "--group; every user of the machine may then keep records there, each file "
                        "its maker's")
    found = platform.serial_group(group)
    if platform.OWNERS and found is None:
        raise UserError((f"there is no group {group} on this machine" if group
                         else "this machine has no dialout or uucp group")
                        + " — name the group of the lines' users with --group (ls -l on a serial port "
                          "shows it)")
    directory = machine_dir()
    try:
        directory.parent.mkdir(parents=True, exist_ok=True)
        for folder in (directory, directory / RELEASES, directory / LINES):
            platform.make_group_folder(folder, None if found is None else found[1])
    except OSError as error:
        raise UserError(f"cannot make {error.filename or directory} ({error.strerror}) — prc3cfg "
                        "setup-machine is run by an "
                        f"administrator: {_AS_ADMINISTRATOR}") from None
    return directory, None if found is None else found[0]
