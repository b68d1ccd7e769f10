"""Atomic writes: a process killed at any point of `write_atomically` (or of
`replace_unless_changed`, adopt's) leaves the old file or the new one — and, where the file is
new, no other name in its folder (a snapshot folder filled with temporary files by applies killed
mid-write is a folder an engineer must clean by hand)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

#: Runs `write_atomically(target, text)` (or, with a fifth argument, `replace_unless_changed(target,
#: text, expected)`) in a fresh process that SIGKILLs itself at the n-th call of `os.<point>` —
#: after the text is written into a file, before (fsync) or after (link, rename) it is put in place.
#: Patched is the standard library, not prc3cfg: the kill lands exactly there.
KILLED_AT = """
import os, signal, sys
from pathlib import Path
from prc3cfg.shell.files import replace_unless_changed, write_atomically
point, nth, target, text = sys.argv[1], int(sys.argv[2]), Path(sys.argv[3]), sys.argv[4]
expected = sys.argv[5:]
real, calls = getattr(os, point), 0
def dying(*args, **kwargs):
    global calls
    calls += 1
    if calls == nth:
        os.kill(os.getpid(), signal.SIGKILL)
    return real(*args, **kwargs)
setattr(os, point, dying)
if expected:
    replace_unless_changed(target, text, expected[0].encode())
else:
    write_atomically(target, text)
"""


@pytest.fixture
def folder(tmp_path):
    """A folder of its own (the test's tmp_path also holds the lock folders conftest gives it)."""
    made = tmp_path / "files"
    made.mkdir()
    return made


@pytest.fixture
def unnamed(folder):
    """`folder`, where its file system holds files without a name that can be linked in (else
    `write_atomically` falls back to a named temporary file, and these tests do not apply)."""
    try:
        fd = os.open(folder, os.O_TMPFILE | os.O_WRONLY, 0o600)
    except (AttributeError, OSError) as error:
        pytest.skip(f"no unnamed files here ({error}): write_atomically writes a named temporary file")
    directory = os.open(folder, os.O_RDONLY)
    try:
        os.link(f"/proc/self/fd/{fd}", folder / "probe", src_dir_fd=directory)
    except OSError as error:
        pytest.skip(f"an unnamed file cannot be linked in here ({error}): write_atomically writes a named "
                    "temporary file")
    finally:
        os.close(fd)
        os.close(directory)
    (folder / "probe").unlink()
    return folder


def killed_writing(target, text, point, nth=1, expected=None):
    done = subprocess.run([sys.executable, "-c", KILLED_AT, point, str(nth), str(target), text,
                           *([expected] if expected else [])])
    return done.returncode


@pytest.mark.parametrize("point", ["fsync", "link", "replace"])
def test_a_new_file_killed_mid_write_leaves_no_name_behind(unnamed, point):
    folder = unnamed
    target = folder / "20261124T033258.352875Z-plant.json"
    code = killed_writing(target, '{"whole": true}', point)
    left = sorted(path.name for path in folder.iterdir())
    assert left in ([], [target.name]), f"killed at os.{point} (exit {code}), left: {left}"
    if left:
        assert target.read_text() == '{"whole": true}'


@pytest.mark.parametrize("point", ["fsync", "link", "replace"])
def test_a_replaced_file_killed_mid_write_is_the_old_or_the_new(unnamed, point):
    folder = unnamed
    target = folder / "state.json"
    target.write_text("old")
    killed_writing(target, "new", point)
    assert target.read_text() in ("old", "new")
    stray = [path.name for path in folder.iterdir() if path != target]
    # The one window left: between the link to a temporary name and the rename over the target.
    assert len(stray) <= (1 if point == "replace" else 0), stray


@pytest.mark.parametrize("point", ["fsync", "link"])
def test_an_adopted_file_killed_mid_write_leaves_no_temporary_name(unnamed, point):
    """`replace_unless_changed` writes its text as `write_atomically` does: killed before the text
    has a name (at its fsync, at the link that names it), the plant file is untouched and alone."""
    folder = unnamed
    target = folder / "plant.yaml"
    target.write_text("old")
    assert killed_writing(target, "new", point, expected="old") == -signal.SIGKILL
    assert target.read_text() == "old"
    assert [path.name for path in folder.iterdir()] == ["plant.yaml"]


def test_a_write_that_completes_leaves_the_file_alone_with_its_text(folder):
    from prc3cfg.shell.files import write_atomically

    target = folder / "plan.json"
    write_atomically(target, "one")
    write_atomically(target, "two")
    assert [path.name for path in folder.iterdir()] == ["plan.json"]
    assert target.read_text() == "two"
    assert target.stat().st_mode & 0o777 == 0o600


def test_the_kill_lands_where_the_test_says(folder):
    """The harness itself: a kill at the first fsync ends the process with SIGKILL."""
    assert killed_writing(folder / "x.json", "x", "fsync") == -signal.SIGKILL
