"""One apply per line at a time: a lock file per line, with holder, pid and time.

The lock for a line lives in a directory every user of the machine shares (the system's
temporary directory), named after the line: the port, or for `emulator://` the emulator's
state file, so two plant files that name the same port still exclude each other. A lock
whose holder process is gone (same host, pid not running) is stale and taken over; a live
holder is waited for up to `timeout` seconds, then refused with who holds it since when.
"""

from __future__ import annotations

import contextlib
import getpass
import hashlib
import json
import os
import socket
import tempfile
import time
from collections.abc import Iterator
from datetime import datetime, timezone
from pathlib import Path

from prc3cfg.errors import UserError

POLL = 0.2


def lock_dir() -> Path:
    return Path(os.environ.get("PRC3CFG_LOCK_DIR") or Path(tempfile.gettempdir()) / "prc3cfg-locks")


def lock_path(line_key: str) -> Path:
    return lock_dir() / f"{hashlib.sha256(line_key.encode()).hexdigest()[:24]}.lock"


class LineBusy(UserError):
    pass


def _holder_alive(holder: dict) -> bool:
    if holder.get("host") != socket.gethostname():
        return True  # cannot tell for another host: assume it is alive
    try:
        os.kill(int(holder["pid"]), 0)
    except ProcessLookupError:
        return False
    except (PermissionError, KeyError, ValueError, TypeError):
        return True
    return True


def _try_acquire(path: Path, record: dict) -> dict | None:
    """Take the lock; None on success, else the current holder's record."""
    try:
        fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except FileExistsError:
        try:
            holder = json.loads(path.read_text())
        except (OSError, ValueError):
            holder = {}
        if holder and _holder_alive(holder):
            return holder
        path.unlink(missing_ok=True)  # stale (or unreadable half-written): recover it and try again
        return _try_acquire(path, record)
    with os.fdopen(fd, "w") as handle:
        json.dump(record, handle)
    return None


@contextlib.contextmanager
def line_lock(line_key: str, description: str, *, timeout: float = 0.0, purpose: str = "apply") -> Iterator[Path]:
    """Hold the lock of one line for the duration of the block."""
    path = lock_path(line_key)
    path.parent.mkdir(parents=True, exist_ok=True)
    record = {
        "line": line_key,
        "holder": f"{getpass.getuser()}@{socket.gethostname()}",
        "host": socket.gethostname(),
        "pid": os.getpid(),
        "since": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "purpose": purpose,
    }
    deadline = time.monotonic() + timeout
    while (holder := _try_acquire(path, record)) is not None:
        if time.monotonic() >= deadline:
            raise LineBusy(
                f"{description}: the line is locked by {holder.get('holder', '?')} (pid {holder.get('pid', '?')}, "
                f"{holder.get('purpose', 'apply')} since {holder.get('since', '?')}) — wait for it to finish, "
                f"or pass --lock-timeout SECONDS to wait; a lock whose process is gone is recovered by itself"
            )
        time.sleep(POLL)
    try:
        yield path
    finally:
        path.unlink(missing_ok=True)
