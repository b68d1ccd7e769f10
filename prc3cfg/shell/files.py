"""Files prc3cfg reads and writes: bounded reads of regular files, atomic writes.

`read_regular` reads a file that must be a regular file (never a FIFO that would block, a
device such as `/dev/zero` that never ends, a directory) and at most `limit` bytes of it;
`FileProblem` says why not, in words the caller completes with what to do. Plant files,
plan files, snapshots and saved images are read this way. `read_owned` reads so what another
user may have put in a folder all users share (the machine's records): never through a link, and
with the owner of the very file read. `parse_json` is `read_json`'s parsing of bytes already read.

`read_json` reads a JSON document so, and refuses — in a `FileProblem`, never a Python
error — a key given twice in one object (JSON readers keep one of the two, most the last: a
reviewer reading the other would approve what is not applied), and what would cost far more to
parse than any file prc3cfg writes: more than
`MAX_CONTAINERS` objects and lists (counted as the `{` and `[` bytes, an upper bound found
before parsing: 63 MB of `[{},{},…]` took 1.6 GB and seconds to parse), more than
`MAX_VALUES` values (counted as its `,` bytes: 64 MiB of `[1e1,1e1,…]` took 0.8 GB), an integer
of more than `MAX_DIGITS` digits (whatever PYTHONINTMAXSTRDIGITS says), nesting deeper than
Python's recursion. Its size is bounded by `JSON_LIMIT`.

`write_atomically` writes a file without a name beside the target, flushes it to disk, links it
in (over the target through a temporary name) and flushes the directory: a process killed at any
point leaves either the previous file (or none) or the complete new one, never a truncated one,
and — where the file is new — no temporary file either. Snapshots,
plan files (`plan --out`) and the emulator's state file are written this way; adopted plant
files by `replace_unless_changed`, which keeps a file another writer (an editor) saved meanwhile.
"""

from __future__ import annotations

import enum
import errno
import json
import os
import secrets
import stat
import sys
import tempfile
from pathlib import Path
from typing import Any, TextIO

from prc3cfg.shell import platform

#: The largest JSON file prc3cfg reads: a plan file, a snapshot, saved images (a plan of
#: 8 buses × 30 fully changed modules is 11–17 MB).
JSON_LIMIT = 64 * 2**20
#: The most objects and lists (`{` and `[` bytes, strings included) a JSON file prc3cfg reads
#: may hold. The largest inputs prc3cfg writes, 8 buses × 30 modules × 64 programs all
#: changed (bench/plan_time_bench.py): a plan file of position, speed, dwell and relative
#: speed, 10.9 MB, 66,448; of every field (F1, F2, next too), 17.1 MB, 100,504; the `read
#: --json` images, 1.1 MB, 16,081; an emulator's state file, 30 modules, about 2,000. Five
#: times the largest: 500,000 empty objects parse in under 0.1 s and 40 MB.
MAX_CONTAINERS = 500_000
#: Values a JSON document may hold (counted as its `,` bytes, an upper bound less one): the
#: largest plan file has about 505,000; five times that, so that numbers and texts cannot make
#: a 64 MiB file cost 0.8 GB.
MAX_VALUES = 2_500_000
#: Digits a JSON integer may have: Python's own default limit, kept when the environment lifts it.
MAX_DIGITS = 4300
#: What a path is when it is not a regular file, by its `stat` file type.
NOT_FILES = {
    stat.S_IFIFO: "a named pipe (FIFO)", stat.S_IFCHR: "a device", stat.S_IFBLK: "a device",
    stat.S_IFSOCK: "a socket",
}


class Why(enum.Enum):
    """Why a file cannot be read — each caller says what to do about it."""

    MISSING = "missing"
    DIRECTORY = "directory"
    NOT_A_FILE = "not a file"
    UNREADABLE = "unreadable"
    TOO_LARGE = "too large"
    NOT_JSON = "not JSON"


class FileProblem(Exception):
    """`str()` is what is wrong ("is a directory", "is a device, not a file", …); `why` its kind;
    `at` the line and column in the file, where there is one."""

    def __init__(self, why: Why, text: str, at: tuple[int, int] | None = None) -> None:
        super().__init__(text)
        self.why = why
        self.at = at

    def where(self, path: Path) -> str:
        """`path`, with the line and column when there are some: "plan.json:1:7"."""
        return f"{path}:{self.at[0]}:{self.at[1]}" if self.at else str(path)


def read_regular(path: Path, limit: int) -> bytes:
    """The bytes of the regular file `path`, at most `limit`; opened so that a FIFO cannot block."""
    try:
        _regular(os.stat(path).st_mode)
        return _bounded(os.open(path, os.O_RDONLY | platform.NON_BLOCKING), limit)[0]
    except FileNotFoundError:
        raise FileProblem(Why.MISSING, "no such file") from None
    except (OSError, ValueError) as error:  # ValueError: a NUL in the path
        raise _unreadable(error) from None


def read_owned(path: Path, limit: int) -> tuple[bytes, int]:
    """The bytes of the regular file `path` — not a link, opened without blocking
    (`platform.open_unfollowed`), at most `limit` — and its owner's uid as the open file says (Windows: 0):
    what another user may have put in a folder all users share is read so, and its owner judged on the very
    file read."""
    try:
        return _bounded(platform.open_unfollowed(path), limit)
    except FileNotFoundError:
        raise FileProblem(Why.MISSING, "no such file") from None
    except IsADirectoryError:
        raise FileProblem(Why.DIRECTORY, "is a directory") from None
    except OSError as error:
        if error.errno == errno.ELOOP:
            raise FileProblem(Why.NOT_A_FILE, "is a symbolic link, not a file") from None
        raise _unreadable(error) from None


def _bounded(fd: int, limit: int) -> tuple[bytes, int]:
    """At most `limit` bytes of the regular file open in `fd` (closed after), and its owner; `FileProblem` for
    more, or for no regular file."""
    with open(fd, "rb") as file:
        status = os.fstat(file.fileno())
        _regular(status.st_mode)  # checked on the file opened: it may have changed since any look by name
        data = file.read(limit + 1)
    if len(data) > limit:
        raise FileProblem(Why.TOO_LARGE, f"larger than {_size(limit)}")
    return data, status.st_uid


def _unreadable(error: OSError | ValueError) -> FileProblem:
    return FileProblem(Why.UNREADABLE, f"cannot read it ({getattr(error, 'strerror', None) or error})")


def read_json(path: Path, limit: int = JSON_LIMIT) -> Any:
    """The JSON document in the regular file `path` (at most `limit` bytes); `FileProblem` otherwise,
    with line and column where the JSON breaks."""
    return parse_json(read_regular(path, limit))


def parse_json(data: bytes) -> Any:
    """The JSON document `data` holds, within the bounds above; `FileProblem` otherwise."""
    if data.count(b"{") + data.count(b"[") > MAX_CONTAINERS:
        raise FileProblem(Why.TOO_LARGE,
                          f"more than {MAX_CONTAINERS:,} objects and lists (counting '{{' and '['), "
                                         "more than any file prc3cfg writes holds")
    if data.count(b",") >= MAX_VALUES:
        raise FileProblem(Why.TOO_LARGE,
                          f"more than {MAX_VALUES:,} values (counting ','), more than any file prc3cfg "
                          "writes holds")
    # int() refuses as many digits itself where Python's limit is MAX_DIGITS or lower: the hook, a call an
    # integer (110,000 in the images of 8 × 30 modules: 17 ms), is needed only where the environment lifts it
    parse_int = None if 0 < sys.get_int_max_str_digits() <= MAX_DIGITS else _integer
    try:
        return json.loads(data, parse_int=parse_int, object_pairs_hook=_object)
    except _KeyTwice as twice:
        raise FileProblem(Why.NOT_JSON,
                          f"the key {json.dumps(twice.key)} is given twice in one object") from None
    except json.JSONDecodeError as error:
        raise FileProblem(Why.NOT_JSON, f"not valid JSON ({error.msg})",
                          (error.lineno, error.colno)) from None
    except UnicodeDecodeError:
        raise FileProblem(Why.NOT_JSON, "not UTF-8 text") from None
    except RecursionError:
        raise FileProblem(Why.NOT_JSON, "nested too deeply for any file prc3cfg writes") from None
    except ValueError:  # the only other ValueError: an integer longer than `_integer` converts
        raise FileProblem(Why.NOT_JSON,
                          f"a number of more than {MAX_DIGITS} digits, which no file prc3cfg "
                          "writes holds") from None


class _KeyTwice(Exception):
    def __init__(self, key: str) -> None:
        super().__init__(key)
        self.key = key


def _object(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object, refused (`_KeyTwice`) when it gives a key twice."""
    result = dict(pairs)
    if len(result) != len(pairs):
        seen: set[str] = set()
        raise _KeyTwice(next(key for key, _ in pairs if key in seen or seen.add(key)))  # type: ignore[func-returns-value]
    return result


def _integer(text: str) -> int:
    """A JSON integer, refused past `MAX_DIGITS` digits whatever PYTHONINTMAXSTRDIGITS says (the
    conversion takes time quadratic in the digits)."""
    if len(text) > MAX_DIGITS + 1:
        raise ValueError(text[:20])
    return int(text)


def _regular(mode: int) -> None:
    if stat.S_ISDIR(mode):
        raise FileProblem(Why.DIRECTORY, "is a directory")
    if not stat.S_ISREG(mode):
        raise FileProblem(Why.NOT_A_FILE,
                          f"is {NOT_FILES.get(stat.S_IFMT(mode), 'not a regular file')}, not a file")


def _size(limit: int) -> str:
    return f"{limit // 2**20} MiB" if limit % 2**20 == 0 else f"{limit} bytes"


def write_atomically(path: Path, text: str, mode: int | None = None) -> None:
    """Replace `path` with `text` atomically (written beside it, fsync, put in place, fsync of the
    folder): a new file (a snapshot) is linked in as itself, an existing one replaced by a rename
    (`_written_beside` says what a process killed on the way leaves). Its permissions `mode`, else 0600."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _written_beside(path, text, mode, new=True)
    if tmp is not None:
        try:
            os.replace(tmp, path)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
    _sync_folder(path.parent)


def replace_unless_changed(path: Path, text: str, expected: bytes) -> bool:
    """Replace `path` with `text` atomically, as `write_atomically` does, keeping its permissions, unless
    `path` no longer holds `expected`: then False, and `path` is as the other writer left it.

    Checked as late as can be: once `text` is on disk, the file is linked to a second name and compared, then
    the new file renamed over it, then the file it replaced compared once more through that name — a save in
    place that came between the two puts that file back. What this cannot see (docs/commands.md, adopt): a
    save that renames its own file into place between the first comparison and the rename, and one that keeps
    writing into the file it opened before the rename after the second.
    """
    tmp = _written_beside(path, text, stat.S_IMODE(os.stat(path).st_mode))
    assert tmp is not None  # not `new`: always a name to rename
    was = path.with_name(f"{tmp.name.removesuffix('.tmp')}.was")
    try:
        try:
            os.link(path, was)
            linked = True
        except OSError:  # a file system without hard links: compared before the rename only
            linked = False
        seen = was if linked else path
        same = os.stat(path).st_ino == os.stat(seen).st_ino and seen.read_bytes() == expected
        if same:
            os.replace(tmp, path)
            # written into in place around the rename: it goes back
            if linked and was.read_bytes() != expected:
                os.replace(was, path)
                same = False
    finally:
        tmp.unlink(missing_ok=True)
        was.unlink(missing_ok=True)
    _sync_folder(path.parent)
    return same


def _written_beside(path: Path, text: str, mode: int | None, *, new: bool = False) -> Path | None:
    """A temporary name beside `path` for a file holding `text` (permissions `mode`, if given), on
    disk; with `new`, where `path` does not exist yet, the file is linked in as `path` itself: None.

    The text goes into a file without a name (Linux's O_TMPFILE), which the kernel removes if the
    process dies before it is linked: a name appears only once the text is on disk, so a killed
    writer leaves no temporary file — but for one between the link to the temporary name and its
    caller's rename. Where the folder's file system has no unnamed files (or /proc is not
    mounted), a named temporary file is written (a kill while writing leaves it)."""
    unnamed = platform.unnamed_file(path.parent)
    if unnamed is None:  # no O_TMPFILE here, or not on this file system
        return _named_beside(path, text, mode)
    fd, link_path = unnamed
    with platform.open_text(fd) as handle:
        _put_on_disk(handle, text, mode)
        # A directory handle given makes Python call linkat(…, AT_SYMLINK_FOLLOW) — without one it
        # calls link(), which links the /proc entry itself and fails (EXDEV).
        folder = os.open(path.parent, os.O_RDONLY)
        try:
            return _linked(link_path, folder, path, new)
        except OSError:  # no /proc: the text is written again, to a named file
            pass
        finally:
            os.close(folder)
    return _named_beside(path, text, mode)


def _linked(unnamed: str, folder: int, path: Path, new: bool) -> Path | None:
    """Link the file `unnamed` names as `path` where `new` and `path` does not exist — None — or
    as a new temporary name beside it, returned."""
    if new:
        try:
            os.link(unnamed, path, src_dir_fd=folder)
            return None
        except FileExistsError:
            pass
    while True:
        tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
        try:
            os.link(unnamed, tmp, src_dir_fd=folder)
            return tmp
        except FileExistsError:
            continue


def _named_beside(path: Path, text: str, mode: int | None) -> Path:
    """`_written_beside` where there are no unnamed files: a named temporary file, removed if writing
    fails."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with platform.open_text(fd) as handle:
            _put_on_disk(handle, text, mode)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return Path(tmp)


def _put_on_disk(handle: TextIO, text: str, mode: int | None) -> None:
    handle.write(text)
    handle.flush()
    if mode is not None:
        platform.set_mode(handle.fileno(), mode)
    os.fsync(handle.fileno())


def _sync_folder(folder: Path) -> None:
    platform.sync_folder(folder)
