"""One apply per line at a time: a kernel lock (`flock`) on a file per identity of the line.

Owns the identities of a line (`line_keys`: each address a `socket://` or `rfc2217://` host
resolves to, a device's real path, an emulator's state file — so two spellings of one line
share a key), the lock files in a folder every user of the machine shares, and the wait
for a busy line — also for a local device that another serial program holds (the device is
locked the way every serial program locks it, `prc3cfg.shell.serial_lock`).

The folder is the machine's, whatever the environment or the user of the process
(`lock_dir`): `PRC3CFG_LOCK_DIR` when set, else `/run/lock/prc3cfg` (the system's lock
folder, as for serial tools' `LCK..` files), `/var/lock/prc3cfg`, then `/tmp/prc3cfg-locks` —
the first that exists, or else whose parent every user may make folders in (sticky and
writable by all), so every user's prc3cfg picks the same one; on Windows
`%ProgramData%\\prc3cfg\\locks` (`prc3cfg.shell.platform.LOCK_FOLDERS`). It is made sticky and
writable by all. Each user locks a lock file of its own per key, `HASH.UID.lock`, readable by all
(`lock_path`), and looks at every other user's of that key (`_others_holder`): one another user
holds is a busy line. A user never holds another's file — its owner may remove it from the
sticky folder while someone else holds it, and the owner's next prc3cfg would lock a new file of
that name — so another user's prc3cfg sees a lock, names its holder and waits for it, and cannot
remove it. Two users taking one line at the same instant both see the other: the higher uid
lets go, and never both hold it. (Windows: every user locks `HASH.lock`; there are no uids.)

The lock is the kernel's: it dies with the process that holds it, so there is no stale lock to
guess at, and prc3cfg never deletes a lock file (a process could be holding the deleted file
while a third locks a new one of the same name); a lock taken on a file that was removed or
replaced between its open and its lock is let go and the path opened again (`_same_file`).

Nothing in the folder is trusted that another user could have put there to take the line or to
have prc3cfg write elsewhere (`_make_lock_dir`, `_open`): the folder must be a folder — not a
symbolic link — of root or of this user (its owner may remove any lock in it, even in a sticky
folder), else it is refused in one line and an administrator removes it; a lock file is opened
without following a symbolic link, made with O_EXCL, and must be a plain file with one name (a
hard link to another file, a FIFO: refused) of this user. On Windows owners are ACLs and are not
checked. The holder's details written inside (`holder`, `host`, `pid`, `since`, `purpose`, `line`) are
what anyone who may write the file says: the holder is named "as its lock file says", with whose
file it is where that is another user than the one it names; an empty or half-written file, as a
holder leaves it between taking the lock and writing, names "another process".

Does not own what a bus's line is (the caller passes its port and, for `emulator://`, the
state file) nor where a message goes (`waiting` is the caller's).
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import ipaddress
import json
import os
import socket
import stat
import time
from collections.abc import Callable, Iterable, Iterator
from datetime import UTC, datetime
from pathlib import Path
from urllib.parse import urlsplit

from prc3cfg.core import text
from prc3cfg.core.line import TCP_SCHEMES
from prc3cfg.errors import UserError
from prc3cfg.shell import platform, serial_lock

POLL = 0.1  # s between attempts on a busy line
REOPENS = 10  # opens of a lock file removed or replaced between its open and its lock
RACE_WAIT = 0.05  # s the lower uid of two users taking a line at one instant waits for the other to let go
#: Where the lock folder may be, in order: (parent, name) — `lock_dir`.
LOCK_FOLDERS = platform.LOCK_FOLDERS
#: Never through a symbolic link; a FIFO planted in place of a lock file cannot block the open.
_OPEN_FLAGS = platform.NO_FOLLOW | platform.NO_INHERIT | platform.NON_BLOCKING


class LineBusy(UserError):
    pass


def line_keys(port: str, *, emulator_state: Path | None = None) -> tuple[str, ...]:
    """The identities of the line `port` names; two spellings of one line share at least one.

    `socket://HOST:PORT` and `rfc2217://HOST:PORT`: `tcp/ADDRESS/PORT` for every address HOST
    resolves to, as a connection reaches it (`::ffff:127.0.0.1` and `0.0.0.0` are 127.0.0.1; a
    host that does not resolve: its name); a device path: `dev/REALPATH`; `emulator://NAME`:
    `emulator/REALPATH` of its state file `emulator_state`; any other URL: the URL, and
    `dev/REALPATH` of the device it names by an absolute path (pyserial's `spy://`, `alt://`)."""
    scheme, sep, _ = port.partition("://")
    if not sep:
        return (_device_key(port),)
    if scheme == "emulator":
        if emulator_state is None:
            raise ValueError(f"{port}: an emulator line is known by its state file — pass emulator_state")
        return (f"emulator/{platform.real_path(emulator_state)}",)
    if scheme in TCP_SCHEMES:
        parts = urlsplit(port)
        try:
            host, tcp_port = parts.hostname, parts.port
        except ValueError:  # a port that is no number: the open says so
            return (port,)
        if host is None or tcp_port is None:
            return (port,)
        try:
            addresses = socket.getaddrinfo(host, tcp_port, type=socket.SOCK_STREAM, proto=socket.IPPROTO_TCP)
        except (OSError, UnicodeError):  # does not resolve: the open fails with its own message
            return (f"tcp/{host}/{tcp_port}",)
        return tuple(sorted({f"tcp/{_reached(str(sockaddr[0]))}/{tcp_port}" for *_, sockaddr in addresses}))
    path = device_path(port)
    if path is not None:  # a pyserial wrapper of a device (spy:///dev/ttyUSB0?file=…): the device's line too
        return (port, _device_key(path))
    return (port,)


def device_path(port: str) -> str | None:
    """The local device `port` names, as written: the port itself when it is a path, the absolute
    path of a pyserial URL wrapping one (`spy:///dev/ttyUSB0?file=…`); None for any other."""
    scheme, sep, _ = port.partition("://")
    if not sep:
        return port
    if scheme == "emulator" or scheme in TCP_SCHEMES:
        return None
    path = urlsplit(port).path
    return path if path.startswith("/") else None


def _device_key(path: str) -> str:
    try:
        return f"dev/{platform.device_identity(path)}"
    except ValueError:  # a NUL in the path: no device has it, and the open says so
        return f"dev/{path!r}"


def _reached(address: str) -> str:
    """The address a connection to `address` reaches: an IPv4 address written as IPv6
    (`::ffff:127.0.0.1`) is that IPv4 address; the unspecified one (`0.0.0.0`, `::`) is this host's
    loopback, where Linux connects it."""
    try:
        ip = ipaddress.ip_address(address.partition("%")[0])
    except ValueError:
        return address
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        ip = ip.ipv4_mapped
    if ip.is_unspecified:
        ip = ipaddress.ip_address("127.0.0.1" if ip.version == 4 else "::1")
    return str(ip)


def lock_dir() -> Path:
    """`PRC3CFG_LOCK_DIR`, else the first of `LOCK_FOLDERS` that exists or that any user may
    make (its parent sticky and writable by all); the last when none."""
    if override := os.environ.get("PRC3CFG_LOCK_DIR"):
        return Path(override)
    for parent, name in LOCK_FOLDERS:
        folder = parent / name
        if folder.is_dir() or _shared(parent):
            return folder
    return folder


def _shared(folder: Path) -> bool:
    """Whether every user may make files in `folder` and none may remove another's: a sticky
    folder writable by all (/tmp, and /run/lock on most distributions)."""
    try:
        mode = os.stat(folder).st_mode
    except OSError:
        return False
    return stat.S_ISDIR(mode) and mode & (stat.S_ISVTX | stat.S_IWOTH) == stat.S_ISVTX | stat.S_IWOTH


def lock_path(key: str) -> Path:
    """This user's lock file of `key`: `HASH.UID.lock` (Windows: `HASH.lock`, every user's)."""
    uid = platform.user_id()
    return lock_dir() / f"{_stem(key)}{'' if uid is None else f'.{uid}'}.lock"


def _stem(key: str) -> str:
    return hashlib.sha256(key.encode()).hexdigest()[:24]


def _make_lock_dir(description: str) -> Path:
    """The lock folder, made sticky and writable by every user when this process makes it; refused
    (`UserError`, one line) when it is a symbolic link, no folder, or another non-root user's — its
    owner could remove the locks in it, whoever made them."""
    directory = lock_dir()
    try:
        directory.parent.mkdir(parents=True, exist_ok=True)
        platform.make_shared_folder(directory, 0o1777)
    except FileExistsError:
        pass
    except OSError as error:
        raise UserError(f"{description}: cannot make the lock directory {directory} ({error.strerror}) — "
                        "set PRC3CFG_LOCK_DIR") from None
    try:
        status = os.lstat(directory)
    except OSError as error:
        raise UserError(f"{description}: cannot read the lock directory {directory} ({error.strerror}) — "
                        "set PRC3CFG_LOCK_DIR") from None
    if stat.S_ISLNK(status.st_mode):
        raise UserError(f"{description}: the lock directory {directory} is a symbolic link, not used — "
                        "an administrator removes it, or set PRC3CFG_LOCK_DIR")
    if not stat.S_ISDIR(status.st_mode):
        raise UserError(f"{description}: the lock directory {directory} is no directory — "
                        "an administrator removes it, or set PRC3CFG_LOCK_DIR")
    if not platform.trusted_owner(status.st_uid):
        raise UserError(f"{description}: the lock directory {directory} belongs to "
                        f"{platform.uid_name(status.st_uid)}, "
                        "who could remove the locks in it, so it is not used — an administrator removes it, "
                        "or set PRC3CFG_LOCK_DIR")
    return directory


def _open(path: Path, description: str) -> tuple[int, bool]:
    """A descriptor of this user's lock file (made readable by all if this call makes it), and
    whether it is open for writing — a read-only lock is locked all the same.

    Never through a symbolic link, and never anything but a plain file with one name (a hard link
    to another file would have prc3cfg write its details into that file) of this user (another
    could remove it while this process holds it): refused, one line."""
    try:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL | _OPEN_FLAGS, 0o644)
            platform.set_mode(fd, 0o644)  # umask aside: every user reads who holds it
            return fd, True
        except FileExistsError:
            pass
        try:
            fd, writable = os.open(path, os.O_RDWR | _OPEN_FLAGS), True
        except PermissionError:
            fd, writable = os.open(path, os.O_RDONLY | _OPEN_FLAGS), False
    except OSError as error:
        raise UserError(f"{description}: cannot open the line lock {path} ({error.strerror}) — "
                        "check the lock directory or set PRC3CFG_LOCK_DIR") from None
    status = os.fstat(fd)
    if not stat.S_ISREG(status.st_mode) or status.st_nlink != 1:
        os.close(fd)
        what = "a second name of another file" if stat.S_ISREG(status.st_mode) else "no plain file"
        raise UserError(f"{description}: the line lock {path} is {what}, not used — "
                        "an administrator removes it, or set PRC3CFG_LOCK_DIR")
    if platform.OWNERS and status.st_uid != platform.user_id():
        os.close(fd)
        raise UserError(f"{description}: the line lock {path} belongs to "
                        f"{platform.uid_name(status.st_uid)}, who could remove it "
                        "while this process holds it, so it is not used — an administrator removes it, or "
                        "set PRC3CFG_LOCK_DIR")
    return fd, writable


def _others_holder(path: Path) -> str | None:
    """Who holds the line in another user's lock file of it (`HASH.UID.lock` beside this user's
    `path`, or an older prc3cfg's `HASH.lock`), or None; this user's `path` is held. Such a file is
    only looked at — its owner may remove it whoever holds it — and one this user may not read
    counts as held. Two users taking the line at one instant each hold their own and see the
    other's: the lower uid waits up to `RACE_WAIT` s for the other to let go, the higher lets go at
    once, so one of them takes the line. Windows: every user locks one file (`lock_path`), there is no other.
    """
    if not platform.OWNERS:
        return None
    deadline = time.monotonic() + RACE_WAIT
    while True:
        found = _other_holder_now(path)
        if found is None:
            return None
        holder, uid = found
        if uid <= (platform.user_id() or 0) or time.monotonic() >= deadline:
            return holder
        time.sleep(RACE_WAIT / 10)


def _other_holder_now(path: Path) -> tuple[str, int] | None:
    """The first other user's lock file of `path`'s key held now: its holder and its owner's uid. A lock file
    that cannot be read counts as held: another user's apply may be behind it."""
    try:
        for other, opened in _lock_files(path.parent, path.name.partition(".")[0], but=path.name):
            if isinstance(opened, OSError):
                with contextlib.suppress(OSError):
                    owner = os.lstat(other).st_uid
                    return (f"a process of {platform.uid_name(owner)} (its lock file {other} "
                            "cannot be read)"), owner
            elif (held := _held(opened)) is not None:
                return held, os.fstat(opened).st_uid
    except OSError:
        return "another process (the lock directory cannot be read)", 0
    return None


def _lock_files(directory: Path, stem: str, but: str = "") -> Iterator[tuple[Path, int | OSError]]:
    """Each lock file of the line `stem` in `directory` but `but`, opened to be looked at: its descriptor
    (closed when the caller asks for the next), or why it could not be opened. A link, a folder or a file gone
    meanwhile is passed over: prc3cfg makes none. OSError when `directory` cannot be listed."""
    for name in sorted(os.listdir(directory)):
        if name == but or not (name.startswith(f"{stem}.") and name.endswith(".lock")):
            continue
        try:
            fd = os.open(directory / name, os.O_RDONLY | _OPEN_FLAGS)
        except (FileNotFoundError, IsADirectoryError):
            continue
        except OSError as error:
            if error.errno != errno.ELOOP:  # a symbolic link: no prc3cfg locks one
                yield directory / name, error
            continue
        try:
            yield directory / name, fd
        finally:
            os.close(fd)


def _held(fd: int) -> str | None:
    """The holder a lock file names, where it is a plain file some process holds now; else None."""
    return _holder(fd) if stat.S_ISREG(os.fstat(fd).st_mode) and platform.is_locked(fd) else None


def _same_file(fd: int, path: Path) -> bool:
    """Whether `path` still names the file open in `fd` — not removed, nor replaced, since it was
    opened (a lock taken on a file no longer there locks nothing)."""
    try:
        named, held = os.lstat(path), os.fstat(fd)
    except OSError:
        return False
    return (named.st_dev, named.st_ino) == (held.st_dev, held.st_ino)


def _holder(fd: int) -> str:
    """Who holds the lock, as its file says, "alice@host (pid 123, apply since …) as its lock file
    says" — anyone who may write the file may write that — and, where its owner is not the user it
    names, whose file it is: the uid the kernel keeps ("…, a file of mallory (uid 1002)");
    "another process" when it names no one (a holder between its lock and its details)."""
    try:
        record = json.loads(platform.read_at(fd, 4096, 0))
        claim = (f"{record['holder']} (pid {record['pid']}, {record['purpose']} since {record['since']}) as "
                 "its lock file says")
        claimed_user = str(record["holder"]).rpartition("@")[0]
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return "another process"
    if platform.OWNERS:
        with contextlib.suppress(OSError):
            owner = platform.uid_name(os.fstat(fd).st_uid)
            if owner.partition(" (uid")[0] != claimed_user:
                claim += f", a file of {owner}"
    return text.shown(claim)


def _take_all(paths: list[Path], description: str) -> tuple[list[tuple[int, bool]], str | None]:
    """Lock every path or none: the descriptors taken, or none and the holder of the first busy one.

    A file locked is kept only if its path still names it (`_same_file`): one removed or replaced
    between the open and the lock is let go and the path opened again, up to `REOPENS` times."""
    taken: list[tuple[int, bool]] = []
    try:
        for path in paths:
            for _ in range(REOPENS):
                fd, writable = _open(path, description)
                if not platform.try_lock(fd):
                    holder = _holder(fd)
                    os.close(fd)
                    _release(taken)
                    return [], holder
                if _same_file(fd, path):
                    taken.append((fd, writable))
                    if (other := _others_holder(path)) is not None:
                        _release(taken)
                        return [], other
                    break
                platform.unlock(fd)
                os.close(fd)
            else:
                raise UserError(f"{description}: the line lock {path} keeps being removed or replaced — "
                                "find what removes it, or set PRC3CFG_LOCK_DIR")
    except BaseException:
        _release(taken)
        raise
    return taken, None


def _release(taken: list[tuple[int, bool]]) -> None:
    for fd, writable in taken:
        if writable:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)  # no details of a holder that is gone
        platform.unlock(fd)  # also for a child forked while the lock was held
        os.close(fd)


@contextlib.contextmanager
def line_lock(
    keys: Iterable[str],
    description: str,
    *,
    port: str | None = None,
    timeout: float = 0.0,
    purpose: str = "apply",
    waiting: Callable[[str], None] | None = None,
) -> Iterator[tuple[Path, ...]]:
    """Hold the lock of one line (all of its `keys`, from `line_keys`) for the block; yields the lock files.

    When `port` names a local device (`device_path`), the device is locked as other serial
    programs lock it too, once the line lock is held (`prc3cfg.shell.serial_lock`).
    A busy line is tried again every `POLL` s for up to `timeout` s, then refused with
    `LineBusy` naming the holder; `waiting` is told once, with the holder, when a wait begins.
    (Ctrl-C while waiting: the CLI's signal handler interrupts the sleep, `prc3cfg.shell.cancel`.)"""
    if isinstance(keys, str):
        raise TypeError("line_lock takes the keys of a line (line_keys(port)), not one string")
    paths = sorted({lock_path(key) for key in keys})
    device = device_path(port) if port is not None else None
    _make_lock_dir(description)
    deadline = time.monotonic() + timeout
    told = False
    while True:
        taken, holder = _take_all(paths, description)
        if holder is None:
            try:
                serial_taken, in_use = serial_lock.take([device] if device is not None else [])
            except BaseException:
                _release(taken)
                raise
            if in_use is None:
                break
            _release(taken)
            busy = f"the serial port {in_use.device} is in use by {in_use.holder}"
            advice = wait_advice = "close it and run again"
            waited_for = f"the serial port {in_use.device}, in use by {in_use.holder}"
        else:
            busy = f"the line is locked by {holder}"
            advice = "wait for it to finish, or pass --lock-timeout SECONDS to wait"
            wait_advice = "wait for it to finish, or pass a longer --lock-timeout"
            waited_for = f"the line lock held by {holder}"
        left = deadline - time.monotonic()
        if left <= 0:
            if timeout > 0:
                raise LineBusy(f"{description}: {busy} after waiting {timeout:g} s — {wait_advice}")
            raise LineBusy(f"{description}: {busy} — {advice}")
        if waiting is not None and not told:
            waiting(f"{description}: waiting for {waited_for} — up to {timeout:g} s")
            told = True
        time.sleep(min(POLL, left))
    record = json.dumps({
        "holder": f"{platform.user_name()}@{socket.gethostname()}",
        "host": socket.gethostname(),
        "pid": os.getpid(),
        "since": datetime.now(UTC).isoformat(timespec="seconds"),
        "purpose": purpose,
        "line": description,
    }).encode()
    try:
        for fd, writable in taken:
            if writable:
                with contextlib.suppress(OSError):  # the details only name the holder to others
                    os.ftruncate(fd, 0)
                    platform.write_at(fd, record, 0)
        yield tuple(paths)
    finally:
        serial_lock.release(serial_taken)
        _release(taken)


def held_by(keys: Iterable[str]) -> str | None:
    """Who holds the line with these identities now — any user's lock file of it, looked at only, never
    taken (a status must not refuse an apply the line) — or None: no prc3cfg command holds it. A lock file
    that cannot be read is passed over: a status says what it sees (the lock code counts it as held)."""
    try:
        for key in keys:
            for _, opened in _lock_files(lock_dir(), _stem(key)):
                if not isinstance(opened, OSError) and (held := _held(opened)) is not None:
                    return held
    except OSError:
        pass  # no lock folder: nobody has held a line yet
    return None
