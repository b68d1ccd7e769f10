r"""What differs between POSIX and Windows, in one place: every other module calls this one.

Owns the calls that exist on one system only, each behind a function or a constant that
means the same everywhere:

- open flags: `NO_INHERIT` (O_CLOEXEC; Windows: O_NOINHERIT | O_BINARY), `NO_FOLLOW` (O_NOFOLLOW; Windows has
  no symbolic-link open flag: 0), `NON_BLOCKING` (O_NONBLOCK, so a FIFO cannot block an open; Windows: 0),
  `open_unfollowed` (a file opened neither through a link nor blocking: O_NOFOLLOW | O_NONBLOCK; Windows: a
  reparse point refused), `unnamed_file` (Linux's O_TMPFILE and the /proc link that names it later; elsewhere
  None: a named temporary file is written instead);
- folders: `make_shared_folder` (mkdir, then the mode set on the folder opened without following a
  symbolic link; Windows: mkdir);
- file contents and durability: `open_text` (UTF-8, no newline translation: Windows' text mode
  makes \n \r\n), `read_at`/`write_at` (pread/pwrite; Windows: seek, then read or write),
  `set_mode` (fchmod; Windows keeps no POSIX permissions: nothing), `sync_data`
  (fdatasync; fsync where there is none), `sync_folder` (fsync of a directory; Windows cannot
  open one: nothing);
- file locks: `try_lock`/`unlock` (flock; Windows: msvcrt.locking of one byte far past the end,
  so the holder's details at the start stay readable) — both released with the last descriptor —
  and `is_locked` (a lock someone else holds, seen without holding it);
- the machine's folders: `LOCK_FOLDERS` (the lock folder's candidates, `prc3cfg.shell.locks`),
  `SYSTEM_STATE_DIR` and `user_state_dir` (axis releases and the lines' records,
  `prc3cfg.shell.machine_folder`) — POSIX's /run/lock, /var/lock, /tmp, /var/lib, XDG; Windows'
  %ProgramData%\prc3cfg and %LOCALAPPDATA%; `serial_group` and `make_group_folder` (the machine's
  folder an administrator makes once for the users of the lines: POSIX's dialout or uucp group, mode
  3775; `SHARED_READ`, its records' mode), `user_tag` (this user's files in it);
- who and what: `user_name` (a login name, else `uid N`), `trusted_owner`, `own_file`, `OWNERS` and
  `user_id`/`uid_name` (whether files have a uid owner: POSIX; Windows has ACLs instead),
  `process_alive` (kill(pid, 0); Windows: OpenProcess — kill(pid, 0) there is no test: signal 0 is
  CTRL_C_EVENT, a Ctrl-C sent to the process's console group), `program_name` (Linux's /proc/PID/comm);
- terminals and serial devices: `TERMINAL_ERRORS`, `character_format` (termios; Windows: the port's DCB,
  `dcb_format`), `is_pseudo_terminal` (Linux's pty majors), `device_number` (major and minor of a device),
  `terminal_path` (ttyname; Windows: the console, CONOUT$), `open_pty` (POSIX only: `HAS_PTY`), `pty_line`
  (the baud rate and stop bits a client set on a pty), `kernel_lock_holders` (Linux's /proc/locks),
  `registered_serial_ports` (Windows' registry of COM ports), `UUCP_LOCKS` (whether the `LCK..` convention
  exists here: not on Windows, where a COM port is exclusive), `device_identity` (the name two spellings of
  one device share: on Windows a COM port's, `com_port_name`: `COM10`, `com10`, `\\.\COM10`), `check_parity`
  (INPCK and IGNPAR: a character of bad parity refused; Windows: not possible, False);
- sockets and threads: `bytes_waiting` (FIONREAD; Windows: a peek), `hung_up` (poll's RDHUP where there is
  one, else a peek), `block_signals` (pthread_sigmask; Windows delivers signals to the main thread anyway:
  nothing), `wait_for`, `result_of` and `next_of` (an event's wait, a future's result and a queue's next item
  that let a Ctrl-C handler run meanwhile: Windows never runs one inside a wait without a timeout);
- paths: `resolved` and `real_path` (links followed; where Windows refuses a long path, absolute as
  written);
- commands a person pastes into the system's shell: `command_line` and `python_command` (POSIX
  shell quoting; Windows: double quotes cmd and PowerShell both read).

Branches are `sys.platform` tests, which mypy follows: `mypy --platform win32` and `--platform
darwin` check the other systems' branches. Does not own what any of it is used for.

It is long because it is the one seam (tests/test_platform.py checks that no other module imports
a module one system lacks): each function is short, but every difference between the systems is
here, where a reader porting prc3cfg finds them all. The `# --` rulers group it as the list above.
"""

from __future__ import annotations

import contextlib
import errno
import os
import queue
import select
import shlex
import signal
import stat
import sys
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Literal, TextIO, TypeVar

if TYPE_CHECKING:  # the rest where a call needs it: every command imports this module first, `--help` too
    import socket
    from concurrent.futures import Future

T = TypeVar("T")

if sys.platform == "win32":
    import ctypes
    import msvcrt
else:
    import fcntl
    import grp
    import pwd
    import termios
    import tty

# -- open flags ------------------------------------------------------------------------

if sys.platform == "win32":
    NO_INHERIT = os.O_NOINHERIT | os.O_BINARY
    NO_FOLLOW = 0
    NON_BLOCKING = 0
else:
    NO_INHERIT = os.O_CLOEXEC
    NO_FOLLOW = os.O_NOFOLLOW
    NON_BLOCKING = os.O_NONBLOCK


def open_unfollowed(path: Path) -> int:
    """`path` opened for reading where it is not a symbolic link, without blocking on a FIFO (POSIX:
    O_NOFOLLOW | O_NONBLOCK — a link fails with ELOOP; Windows, which has no such open flag: a reparse
    point, a link or a junction, is refused before the open — another user there cannot swap one in
    between, since %ProgramData%'s ACL lets only a file's maker change it)."""
    if sys.platform == "win32":
        if os.lstat(path).st_file_attributes & stat.FILE_ATTRIBUTE_REPARSE_POINT:
            raise OSError(errno.ELOOP, "is a link", str(path))
        return os.open(path, os.O_RDONLY | NO_INHERIT)
    return os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)


def unnamed_file(folder: Path) -> tuple[int, str] | None:
    """A file without a name in `folder`, open for writing (mode 0600), and the path that links it
    in (`os.link(path, name, src_dir_fd=…)`); None where the system or its file system has none."""
    if sys.platform == "linux":
        try:
            fd = os.open(folder, os.O_TMPFILE | os.O_WRONLY, 0o600)
        except OSError:  # not on this file system
            return None
        return fd, f"/proc/self/fd/{fd}"
    return None


def make_shared_folder(folder: Path, mode: int) -> None:
    """Make `folder` (FileExistsError when there is one) and set its `mode` whatever the umask, on
    the folder made — never through a symbolic link put in its place meanwhile (Windows: mkdir)."""
    folder.mkdir(mode=mode)
    if sys.platform != "win32":
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
        try:
            os.fchmod(fd, mode)
        finally:
            os.close(fd)


# -- file contents and durability --------------------------------------------------------


def read_at(fd: int, size: int, offset: int) -> bytes:
    if sys.platform == "win32":
        os.lseek(fd, offset, os.SEEK_SET)
        return os.read(fd, size)
    return os.pread(fd, size, offset)


def write_at(fd: int, data: bytes, offset: int) -> int:
    if sys.platform == "win32":
        os.lseek(fd, offset, os.SEEK_SET)
        return os.write(fd, data)
    return os.pwrite(fd, data, offset)


def open_text(file: int | str | Path, mode: Literal["w", "a"] = "w") -> TextIO:
    r"""A file (a path, or an open descriptor it takes over) for writing text as given, on every system:
    UTF-8, and its own line endings — Windows' text mode writes each \n as \r\n (a CRLF plant file
    rewritten came out \r\r\n) and in the locale's code page (cp1252 has no ✓ ⚠ →)."""
    return open(file, mode, encoding="utf-8", newline="")


def set_mode(fd: int, mode: int) -> None:
    """The permissions of an open file, whatever the umask (Windows: no POSIX permissions)."""
    if sys.platform != "win32":
        os.fchmod(fd, mode)


def sync_data(fd: int) -> None:
    """A file's data on disk (fdatasync: its size too, not its times)."""
    if sys.platform == "win32" or sys.platform == "darwin":
        os.fsync(fd)
    else:
        os.fdatasync(fd)


def sync_folder(folder: Path) -> None:
    """A folder's entries on disk (a name just linked or renamed). Windows cannot open a folder
    as a file; its file system writes a rename's metadata through its own log."""
    if sys.platform == "win32":
        return
    handle = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(handle)
    finally:
        os.close(handle)


# -- file locks --------------------------------------------------------------------------

#: Windows: the byte locked, far past any text a lock file holds (reads of the holder's details
#: at the start would fail on a locked byte).
_LOCKED_BYTE = 2**31 - 2


def try_lock(fd: int) -> bool:
    """Take the exclusive lock of the open file `fd` without waiting: whether it was taken."""
    if sys.platform == "win32":
        os.lseek(fd, _LOCKED_BYTE, os.SEEK_SET)
        try:
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
        except OSError:
            return False
        return True
    else:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return False
        return True


def is_locked(fd: int) -> bool:
    """Whether another open file holds the exclusive lock of the file open in `fd` now (POSIX: a shared
    lock tried and let go at once; Windows, no shared locks: the exclusive one)."""
    if sys.platform == "win32":
        if not try_lock(fd):
            return True
        unlock(fd)
        return False
    else:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        fcntl.flock(fd, fcntl.LOCK_UN)
        return False


def unlock(fd: int) -> None:
    if sys.platform == "win32":
        os.lseek(fd, _LOCKED_BYTE, os.SEEK_SET)
        with contextlib.suppress(OSError):
            msvcrt.locking(fd, msvcrt.LK_UNLCK, 1)
    else:
        fcntl.flock(fd, fcntl.LOCK_UN)


# -- the machine's folders ---------------------------------------------------------------

if sys.platform == "win32":
    _PROGRAM_DATA = Path(os.environ.get("PROGRAMDATA") or r"C:\ProgramData") / "prc3cfg"
    #: Where the lock folder may be, in order: (parent, name).
    LOCK_FOLDERS = ((_PROGRAM_DATA, "locks"),)
    #: The machine's folder of records that last across a restart.
    SYSTEM_STATE_DIR = _PROGRAM_DATA
else:
    LOCK_FOLDERS = ((Path("/run/lock"), "prc3cfg"), (Path("/var/lock"), "prc3cfg"),
                    (Path("/tmp"), "prc3cfg-locks"))
    SYSTEM_STATE_DIR = Path("/var/lib/prc3cfg")


#: The groups that own serial ports, by distribution (Debian's dialout, Arch's and Fedora's uucp): the
#: users of a line are in one, so the machine's folder is theirs.
SERIAL_GROUPS = ("dialout", "uucp")


def serial_group(name: str | None = None) -> tuple[str, int] | None:
    """The group `name`, else the first of `SERIAL_GROUPS` this machine has, with its gid; None where
    there is none (Windows: its folders' rights are ACLs — None)."""
    if sys.platform != "win32":
        for candidate in [name] if name else SERIAL_GROUPS:
            with contextlib.suppress(KeyError):
                return candidate, grp.getgrnam(candidate).gr_gid
    return None


#: The permissions of a record in the machine's folder that every user of the line reads and only its maker
#: writes (a line's record, `prc3cfg.shell.line_record`): 0640, its group the folder's (`make_group_folder`:
#: setgid) — the serial ports' group. Windows keeps no POSIX permissions: the ACL a file inherits from
#: %ProgramData%\prc3cfg gives every user read and its maker (CREATOR OWNER) alone the right to change it.
SHARED_READ = 0o640


def make_group_folder(folder: Path, gid: int | None) -> None:
    """`folder` (made if missing) owned by this user and group `gid`, mode 3775: the group writes in it,
    files made there take its group (every user of the line reads them, `SHARED_READ`), and none removes
    or replaces another user's (the sticky bit) — set on the folder opened without following a symbolic
    link (Windows: mkdir; %ProgramData%'s rights let every user make files there that every user reads
    and only their maker may change)."""
    folder.mkdir(exist_ok=True)
    if sys.platform != "win32":
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
        try:
            if gid is not None:
                os.fchown(fd, os.getuid(), gid)
            os.fchmod(fd, 0o3775)
        finally:
            os.close(fd)


def user_tag() -> str:
    """What tells this user's files from others' in a folder all users share: the uid (Windows: a
    digest of the user name)."""
    if sys.platform == "win32":
        import hashlib

        return hashlib.sha256(user_name().encode()).hexdigest()[:12]
    return str(os.getuid())


def user_state_dir() -> Path:
    """This user's own folder of records (XDG_STATE_HOME; Windows: %LOCALAPPDATA%)."""
    if sys.platform == "win32":
        return Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local") / "prc3cfg"
    return Path(os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state") / "prc3cfg"


# -- who and what ------------------------------------------------------------------------


def user_name() -> str:
    """The login name of this process's user, else `uid N` (no login name and no passwd entry: a
    container)."""
    import getpass

    try:
        return getpass.getuser()
    # ImportError: Windows without USERNAME, before Python 3.13 (getpass imports pwd)
    except (KeyError, OSError, ImportError):
        if sys.platform == "win32":
            return "an unnamed user"
        return f"uid {os.getuid()}"


#: Whether files have an owner uid the kernel keeps (POSIX). Windows keeps owners and rights in ACLs,
#: which prc3cfg does not read: there `user_id` is None and no ownership is checked.
OWNERS = sys.platform != "win32"


def user_id() -> int | None:
    """This process's uid (Windows: None — see `OWNERS`)."""
    if sys.platform == "win32":
        return None
    return os.getuid()


def uid_name(uid: int) -> str:
    """"alice (uid 1001)", or "uid 1001" where the uid has no passwd entry."""
    if sys.platform != "win32":
        with contextlib.suppress(KeyError):
            return f"{pwd.getpwuid(uid).pw_name} (uid {uid})"
    return f"uid {uid}"


def trusted_owner(uid: int) -> bool:
    """Whether a file or folder of owner `uid` may be believed: root's or this user's (Windows: not
    checked — its owners and rights are ACLs, `OWNERS`)."""
    if sys.platform == "win32":
        return True
    return uid in (0, os.getuid())


def own_file(path: Path) -> bool:
    """Whether `path` is this user's own regular file, not a link (Windows: a regular file, not a link —
    its owners are not uids; in %ProgramData% only a file's maker may change it)."""
    try:
        status = path.lstat()
    except OSError:
        return False
    return stat.S_ISREG(status.st_mode) and (sys.platform == "win32" or status.st_uid == os.getuid())


def process_alive(pid: int) -> bool:
    """Whether a process `pid` runs (another user's included)."""
    if sys.platform == "win32":
        if not 0 < pid < 2**32:
            return False
        kernel32 = ctypes.windll.kernel32
        handle = kernel32.OpenProcess(0x1000, False, pid)  # PROCESS_QUERY_LIMITED_INFORMATION
        if not handle:
            return ctypes.GetLastError() == 5  # ERROR_ACCESS_DENIED: another user's, alive
        try:
            code = ctypes.c_ulong()
            if not kernel32.GetExitCodeProcess(handle, ctypes.byref(code)):
                return True
            return code.value == 259  # STILL_ACTIVE
        finally:
            kernel32.CloseHandle(handle)
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's: alive
        return True
    except OverflowError:  # no pid can be that large
        return False
    return True


def program_name(pid: int) -> str:
    """The program a process runs ("picocom"), or "" where the system does not say (Linux's /proc)."""
    try:
        return Path(f"/proc/{pid}/comm").read_text().strip() if sys.platform == "linux" else ""
    except OSError:
        return ""


# -- terminals and serial devices --------------------------------------------------------

#: What a terminal's settings raise when a device refuses them (POSIX: termios.error).
TERMINAL_ERRORS: tuple[type[Exception], ...]
#: termios speed codes → baud rates
BAUDS: dict[int, int]
if sys.platform == "win32":
    TERMINAL_ERRORS, BAUDS = (), {}
else:
    TERMINAL_ERRORS = (termios.error,)
    BAUDS = {getattr(termios, f"B{baud}"): baud
             for baud in (50, 75, 110, 134, 150, 200, 300, 600, 1200, 1800, 2400, 4800, 9600, 19200,
                                                             38400, 57600, 115200, 230400)
             if hasattr(termios, f"B{baud}")}
#: Whether this system has pseudo-terminals (`emulator serve --pty`).
HAS_PTY = sys.platform != "win32"
#: Whether serial programs here lock a device with a `LCK..NAME` file (`prc3cfg.shell.serial_lock`):
#: POSIX; on Windows the system opens a COM port for one program only.
UUCP_LOCKS = sys.platform != "win32"
#: Linux's pseudo-terminals (/dev/pts/N): character devices of majors 136..143.
PTY_MAJORS = range(136, 144)


#: A Windows DCB's Parity codes (NOPARITY, ODDPARITY, EVENPARITY, MARKPARITY, SPACEPARITY).
DCB_PARITY = {0: "none", 1: "odd", 2: "even", 3: "mark", 4: "space"}


def dcb_format(parity: int, byte_size: int, stop_bits: int) -> tuple[str, int, bool]:
    """A Windows DCB's character format as `character_format` says it (stop-bit code 2 is TWOSTOPBITS;
    a parity code of none of the five is said as `code N`, which no line's parity matches)."""
    return DCB_PARITY.get(parity, f"code {parity}"), byte_size, stop_bits == 2


def character_format(port: object) -> tuple[str, int, bool] | None:
    """The parity, data bits and whether two stop bits, as the serial device open in `port` (a
    pyserial port) keeps them now — termios; Windows: the port's DCB (GetCommState), as the driver kept
    it — None where there is nothing to read back (not a terminal or COM port)."""
    if sys.platform == "win32":
        handle = getattr(port, "_port_handle", None)
        if handle is None:
            return None
        from serial import win32

        dcb = win32.DCB()
        if not win32.GetCommState(handle, ctypes.byref(dcb)):
            return None
        return dcb_format(dcb.Parity, dcb.ByteSize, dcb.StopBits)
    else:
        try:
            cflag = termios.tcgetattr(port.fileno())[2]  # type: ignore[attr-defined]
        except (termios.error, OSError, AttributeError):
            return None
        parity = "none" if not cflag & termios.PARENB else "odd" if cflag & termios.PARODD else "even"
        sizes = {termios.CS5: 5, termios.CS6: 6, termios.CS7: 7, termios.CS8: 8}
        return parity, sizes[cflag & termios.CSIZE], bool(cflag & termios.CSTOPB)


def device_number(status: os.stat_result) -> tuple[int, int] | None:
    """A character device's major and minor numbers; None for anything else or where there are none."""
    if sys.platform == "win32" or not stat.S_ISCHR(status.st_mode):
        return None
    return os.major(status.st_rdev), os.minor(status.st_rdev)


def is_pseudo_terminal(port: str) -> bool:
    """Whether the port `port` is a device path of Linux's pseudo-terminal (/dev/pts/N: `emulator serve
    --pty`, socat's pty), which carries no parity — looked up by stat, never opened; a URL (`socket://…`) is
    none."""
    if "://" in port:
        return False
    try:
        number = device_number(os.stat(port))
    except (OSError, ValueError):
        return False
    return number is not None and number[0] in PTY_MAJORS


def com_port_name(port: str) -> str | None:
    r"""The Windows serial port `port` names, in capitals (`com10`, `\\.\COM10`: COM10); None for any other
    port."""
    from prc3cfg.core.line import COM_PORT

    named = COM_PORT.fullmatch(port)
    return named.group(1).upper() if named else None


def device_identity(path: str) -> str:
    """What two spellings of one local device share: its real path; on Windows a COM port's
    name (`com_port_name`)."""
    if sys.platform == "win32" and (name := com_port_name(path)) is not None:
        return name
    return os.path.realpath(path)


def terminal_path(fd: int) -> str:
    """The terminal `fd` reads from, to be opened for writing (Windows: the console's output)."""
    if sys.platform == "win32":
        return "CONOUT$"
    return os.ttyname(fd)


def open_pty() -> tuple[int, int, str]:
    """A new pseudo-terminal in raw mode: its master and slave descriptors and the slave's path."""
    if sys.platform == "win32":
        raise OSError("Windows has no pseudo-terminals")
    else:
        master, slave = os.openpty()
        tty.setraw(slave)
        return master, slave, os.ttyname(slave)


def pty_line(master: int) -> tuple[int, bool] | None:
    """The baud rate a client set on the pty of `master` and whether two stop bits; None when unknown."""
    if sys.platform != "win32":
        with contextlib.suppress(termios.error, ValueError):
            attributes = termios.tcgetattr(master)  # the slave's, on Linux
            baud = BAUDS.get(attributes[5])
            if baud is not None:
                return baud, bool(attributes[2] & termios.CSTOPB)
    return None


def registered_serial_ports() -> list[str]:
    r"""Windows' serial ports as its registry names them (HKLM\HARDWARE\DEVICEMAP\SERIALCOMM: COM3, COM10),
    in no order; nothing elsewhere. What is left where pyserial's listing, which asks SetupAPI and
    cfgmgr32, cannot load (Wine 8's cfgmgr32 has no CM_MapCrToWin32Err)."""
    if sys.platform != "win32":
        return []
    import winreg

    try:
        key = winreg.OpenKey(winreg.HKEY_LOCAL_MACHINE, r"HARDWARE\DEVICEMAP\SERIALCOMM")
    except OSError:
        return []
    names: list[str] = []
    with key:
        for index in range(winreg.QueryInfoKey(key)[1]):
            with contextlib.suppress(OSError):
                names.append(str(winreg.EnumValue(key, index)[1]))
    return names


def kernel_lock_holders(device: str) -> Iterator[int | None]:
    """The pids holding a kernel lock (flock, fcntl) on `device` (Linux's /proc/locks), in its order;
    None for a lock that names no process (open-file-description locks). Nothing where unknown."""
    if sys.platform != "linux":
        return
    try:
        info = os.stat(device)
        locks = Path("/proc/locks").read_text().splitlines()
    except OSError:
        return
    for line in locks:
        fields = line.split()
        if len(fields) < 6 or fields[1] == "->":  # a waiter, not a holder
            continue
        pid, where = fields[4], fields[5].split(":")
        try:
            major, minor, inode = int(where[0], 16), int(where[1], 16), int(where[2])
        except (ValueError, IndexError):
            continue
        if (major, minor, inode) != (os.major(info.st_dev), os.minor(info.st_dev), info.st_ino):
            continue
        yield int(pid) if pid.lstrip("-").isdigit() and int(pid) > 0 else None


# -- sockets and threads -----------------------------------------------------------------


def bytes_waiting(sock: socket.socket) -> int:
    """How many bytes have arrived on `sock` and not been read (Windows: as many as one peek sees)."""
    if sys.platform == "win32":
        import socket

        try:
            return len(sock.recv(65536, socket.MSG_PEEK))
        except BlockingIOError:
            return 0
    else:
        return int.from_bytes(fcntl.ioctl(sock, termios.FIONREAD, bytes(4)), sys.byteorder)


def hung_up(conn: socket.socket) -> bool:
    """Whether the peer of `conn` has closed or reset it."""
    if sys.platform == "linux":
        poll = select.poll()
        poll.register(conn, select.POLLRDHUP)
        return any(events & (select.POLLRDHUP | select.POLLHUP | select.POLLERR | select.POLLNVAL)
                   for _, events in poll.poll(0))
    import socket

    try:
        readable, _, _ = select.select([conn], [], [], 0)
        return bool(readable) and conn.recv(1, socket.MSG_PEEK) == b""
    except (BlockingIOError, InterruptedError):
        return False
    except (OSError, ValueError):  # reset, or closed here
        return True


#: s: the longest a wait lasts before a signal handler may run (Windows).
SIGNAL_SLICE = 0.1


def wait_for(event: threading.Event) -> None:
    """Wait until `event` is set, a signal handler running meanwhile. Windows runs a Python handler
    (Ctrl-C's) only between the main thread's bytecodes, never inside a wait on a lock without a
    timeout — which every `Event.wait()`, `Future.result()` and `Thread.join()` is: there the wait is
    taken in slices of `SIGNAL_SLICE`."""
    if sys.platform == "win32":
        while not event.wait(SIGNAL_SLICE):
            pass
    else:
        event.wait()


def result_of(future: Future[T]) -> T:
    """`future.result()`, a signal handler running meanwhile (Windows: in slices, as `wait_for`)."""
    if sys.platform == "win32":
        while True:
            with contextlib.suppress(TimeoutError):
                return future.result(timeout=SIGNAL_SLICE)
    return future.result()


def next_of(items: queue.SimpleQueue[T]) -> T:
    """`items.get()`, a signal handler running meanwhile (Windows: in slices, as `wait_for`)."""
    if sys.platform == "win32":
        while True:
            with contextlib.suppress(queue.Empty):
                return items.get(timeout=SIGNAL_SLICE)
    return items.get()


def block_signals(signals: Iterable[signal.Signals]) -> None:
    """Signals `signals` are not delivered to the calling thread (Windows gives every signal to
    the main thread anyway: nothing to do)."""
    if sys.platform != "win32":
        signal.pthread_sigmask(signal.SIG_BLOCK, signals)


# -- this Python -------------------------------------------------------------------------


def resolved(path: Path) -> Path:
    """`path` absolute, its links followed where the system can (`Path.resolve`) — else absolute as written:
    Windows refuses to resolve a path over 260 characters without long paths enabled (WinError 234), and
    a folder named by such a path is still a folder prc3cfg can name in its records and messages."""
    try:
        return path.resolve()
    except OSError:
        return Path(os.path.abspath(path))


def real_path(path: str | os.PathLike[str]) -> str:
    """`os.path.realpath`, with `resolved`'s fallback to the absolute path where the system refuses."""
    try:
        return os.path.realpath(path)
    except OSError:
        return os.path.abspath(path)


def python_command() -> str:
    """The Python running prc3cfg, as a command to paste into this system's shell (a hint to install
    something into it): its path quoted as the shell needs (`command_line`; PowerShell runs a quoted
    command after `&`)."""
    return command_line(sys.executable or ("python" if sys.platform == "win32" else "python3"))


#: What an argument may hold and still be read as one word, unquoted, by cmd and PowerShell alike.
_WINDOWS_PLAIN = frozenset("_-.:\\/=+")


def command_line(*words: str) -> str:
    """A command prc3cfg prints for a person to run (`prc3cfg restore SNAPSHOT`), each word quoted as this
    system's shell reads it back as that one word — POSIX: shlex's quoting; Windows: double quotes around a
    word with anything but letters, digits and `_-.:\\/=+` (a space, `&`, `(`, a quote …), which cmd and
    PowerShell both read as one word (a path holds no double quote; backslashes before the closing quote
    doubled, as the C runtime wants)."""
    if sys.platform == "win32":
        return " ".join(w if w and all(c.isalnum() or c in _WINDOWS_PLAIN for c in w)
                        else f'"{w}{w[len(w.rstrip(chr(92))):]}"'
                        for w in words)
    return shlex.join(words)


def check_parity(port: object) -> bool:
    """Whether the serial device open in `port` (a pyserial port) now refuses a received character whose
    parity is wrong — POSIX: INPCK and IGNPAR set where the line has parity (pyserial clears INPCK, and a
    character kept as NUL would pass on a framing without a checksum: dropped, its frame is too short to
    decode), PARMRK cleared; to be called after anything that makes pyserial set the port up again (its
    `timeout` does). Windows: False — pyserial sets the DCB's fParity, but the driver hands a bad character
    over all the same, and a read cannot tell it. False too for a port with no parity or no device (TCP)."""
    if sys.platform == "win32":
        return False
    else:
        try:
            fd = port.fileno()  # type: ignore[attr-defined]
            attributes = termios.tcgetattr(fd)
            if not attributes[2] & termios.PARENB:
                return False
            attributes[0] = (attributes[0] | termios.INPCK | termios.IGNPAR) & ~termios.PARMRK
            termios.tcsetattr(fd, termios.TCSANOW, attributes)
            held = termios.tcgetattr(fd)[0]
        except (termios.error, OSError, AttributeError, ValueError):
            return False
        return bool(held & termios.INPCK and held & termios.IGNPAR)
