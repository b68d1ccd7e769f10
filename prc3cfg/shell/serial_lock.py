"""A local serial device as every program on the machine locks it, not only prc3cfg.

Owns two conventions of Linux serial programs. The UUCP lock file: `LCK..NAME` in the system's
lock folder (`uucp_lock_dir`: `PRC3CFG_UUCP_LOCK_DIR` when set, else /var/lock), holding its
owner's pid in HDB form (ASCII, right-aligned in 10 characters, a newline). Its NAME is spelled
three ways (`NAMINGS`): the UUCP convention (cu, HDB UUCP) takes the path's last part — /dev/pts/0
is LCK..0 —, minicom and picocom built with UUCP locks the path below /dev with its / as _ —
LCK..pts_0 —, and outside /dev minicom the last part, picocom all but the first part. Each names
the path it was given, so a symlink (/dev/serial/by-id/…) and its real path are more names still:
every spelling of both is checked and taken. And the kernel lock (`flock`) on the device itself, which
picocom as Debian builds it and pyserial's `exclusive=True` take: its holder is found in
/proc/locks by the device's inode, to be named. Windows has neither convention — it opens a COM port
for one program at a time — and there `take` takes nothing (`platform.UUCP_LOCKS`); what differs
between the systems (pids, /proc) is asked of `prc3cfg.shell.platform`.

`take` refuses a device another live process holds either way (`InUse`, naming the program
and its pid), takes over a lock file whose pid is dead — or, holding no pid, that has not been
written for `GARBAGE_AGE` s (younger, its owner may still be writing it) — and writes ours;
`release` removes only a lock file that still holds our pid. A lock folder that is missing or
that this user cannot write (not root, not in the group that owns it) is passed over in
silence: the line lock (`prc3cfg.shell.locks`) and the exclusive open still hold, and a foreign
lock file is still honoured.

Does not own which port names a device (`prc3cfg.shell.locks.device_path`), nor the wait for a
busy line (`prc3cfg.shell.locks.line_lock`), nor opening the device (`prc3cfg.shell.link.ports`).
"""

from __future__ import annotations

import contextlib
import os
import stat
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from prc3cfg.shell import platform

SYSTEM_LOCK_DIR = Path("/var/lock")
GARBAGE_AGE = 5.0  # s a lock file holding no pid is left to its writer
TAKE_ATTEMPTS = 3  # tries at a lock file that other programs keep taking and dropping


@dataclass(frozen=True)
class InUse:
    """A device another program holds: the path as it is named, and the holder in words."""

    device: str
    holder: str


def uucp_lock_dir() -> Path:
    return Path(os.environ.get("PRC3CFG_UUCP_LOCK_DIR") or SYSTEM_LOCK_DIR)


def _below_dev(path: str) -> str:
    """minicom's `mbasename`: a path in /dev without /dev/ and with its / as _; elsewhere the last part."""
    return (path.removeprefix("/dev/").replace("/", "_") if path.startswith("/dev/")
            else os.path.basename(path))


def _all_but_first(path: str) -> str:
    """picocom's `uucp_lockname`: the path from after the first / past its first character (/dev/, or any
    first folder), its / as _ — a path with no such / whole."""
    cut = path.find("/", 1)
    return (path[cut + 1 :] if cut >= 0 else path).replace("/", "_")


#: What NAME in `LCK..NAME` is for a device path, by the programs that write it.
NAMINGS: dict[str, Callable[[str], str]] = {
    "UUCP": os.path.basename,  # cu, HDB UUCP: the last part
    "minicom": _below_dev,
    "picocom": _all_but_first,
}


def lock_names(device: str) -> tuple[str, ...]:
    """`LCK..NAME` in every spelling of `NAMINGS`, for the device as given and for its real path (each name
    once)."""
    return tuple(dict.fromkeys(f"LCK..{naming(path)}" for path in (device, platform.real_path(device))
                               for naming in NAMINGS.values()))


def _is_device(path: str) -> bool:
    try:
        return stat.S_ISCHR(os.stat(path).st_mode)
    except (OSError, ValueError):  # missing, or no path at all: the open says so
        return False


def take(devices: Iterable[str]) -> tuple[list[Path], InUse | None]:
    """Take the lock files of every device, or none: the files written, or none and who holds
    the first device in use."""
    taken: list[Path] = []
    if not platform.UUCP_LOCKS:  # Windows: the system opens a COM port for one program only
        return taken, None
    try:
        for device in devices:
            if not _is_device(device):
                continue
            if (holder := _flock_holder(device)) is not None:
                release(taken)
                return [], InUse(device, holder)
            for name in lock_names(device):
                path, holder = _take_file(uucp_lock_dir() / name)
                if holder is not None:
                    release(taken)
                    return [], InUse(device, holder)
                if path is not None:
                    taken.append(path)
    except BaseException:
        release(taken)
        raise
    return taken, None


def release(paths: Iterable[Path]) -> None:
    """Remove the lock files that still hold our pid; leave any other program's."""
    for path in paths:
        if _pid_in(path) == os.getpid():
            with contextlib.suppress(OSError):
                path.unlink()


def _take_file(path: Path) -> tuple[Path | None, str | None]:
    """Our lock file at `path` (None where the folder cannot be written), or the live holder."""
    record = f"{os.getpid():10d}\n".encode()
    for _ in range(TAKE_ATTEMPTS):
        try:
            os.link(_written(path.parent, record), path)  # whole, at once: no one reads it half-written
            return path, None
        except FileExistsError:
            pass
        except OSError:  # no lock folder, or not ours to write: rely on the line lock and the exclusive open
            return None, _live_holder(path)
        finally:
            with contextlib.suppress(OSError):
                (path.parent / f"LTMP.{os.getpid()}").unlink()
        if (holder := _live_holder(path)) is not None:
            return None, holder
        with contextlib.suppress(OSError):  # stale: its owner is gone
            path.unlink()
    return None, _live_holder(path) or f"another program (it keeps taking {path})"


def _written(folder: Path, record: bytes) -> Path:
    """A file in `folder` holding `record`, readable by every user, to be linked to a lock name."""
    temporary = folder / f"LTMP.{os.getpid()}"
    fd = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | platform.NO_FOLLOW | platform.NO_INHERIT,
                 0o644)
    try:
        platform.set_mode(fd, 0o644)  # umask aside: other programs read the pid
        os.write(fd, record)
    finally:
        os.close(fd)
    return temporary


def _pid_in(path: Path) -> int | None:
    """The pid a lock file holds (HDB's ASCII form, any spacing), None when it holds none."""
    try:
        text = path.read_bytes()[:64].decode("ascii").strip()
    except (OSError, UnicodeDecodeError):
        return None
    return int(text) if text.isdigit() and int(text) > 0 else None


def _live_holder(path: Path) -> str | None:
    """Who holds the lock file at `path` in words, or None when it is stale or absent.

    Stale: its pid is dead or ours (left by an earlier process that had our pid); or it holds
    no pid and was last written `GARBAGE_AGE` s ago or more."""
    try:
        written = path.stat().st_mtime
    except OSError:
        return None
    pid = _pid_in(path)
    if pid is None:
        if time.time() - written >= GARBAGE_AGE:
            return None
        return f"another program (its lock file {path} names no process yet)"
    if pid == os.getpid() or not platform.process_alive(pid):
        return None
    return _named(pid)


def _named(pid: int) -> str:
    """"picocom (pid 1234)", or "a process (pid 1234)" where /proc does not say its program."""
    program = platform.program_name(pid)
    return f"{program or 'a process'} (pid {pid})"


def _flock_holder(device: str) -> str | None:
    """Who else holds a kernel lock on the device (from /proc/locks), or None."""
    for pid in platform.kernel_lock_holders(device):
        if pid is None:
            return "another program"  # an open-file-description lock names no process
        if pid != os.getpid():
            return _named(pid)
    return None
