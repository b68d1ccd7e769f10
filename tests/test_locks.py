"""One apply per line: the lock file, its holder, waiting, and recovery of a stale lock."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from prc3cfg.locks import LineBusy, line_lock, lock_path


@pytest.fixture(autouse=True)
def lock_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("PRC3CFG_LOCK_DIR", str(tmp_path / "locks"))


def test_a_held_line_is_refused_naming_the_holder():
    with line_lock("socket://x:1", "bus a") as path:
        holder = json.loads(path.read_text())
        with pytest.raises(LineBusy, match=rf"^bus a: the line is locked by .* \(pid {holder['pid']}, apply since"):
            with line_lock("socket://x:1", "bus a"):
                pass
    assert not path.exists()


def test_other_lines_are_independent():
    with line_lock("/dev/ttyUSB0", "bus a"), line_lock("/dev/ttyUSB1", "bus b"):
        assert lock_path("/dev/ttyUSB0") != lock_path("/dev/ttyUSB1")


def test_a_stale_lock_is_recovered():
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    path = lock_path("/dev/ttyUSB0")
    path.parent.mkdir(parents=True)
    import socket

    path.write_text(json.dumps({"holder": "x@y", "host": socket.gethostname(), "pid": int(dead.stdout), "since": "then"}))
    with line_lock("/dev/ttyUSB0", "bus a") as held:
        assert json.loads(held.read_text())["pid"] != int(dead.stdout)


def test_the_lock_is_released_on_error():
    with pytest.raises(RuntimeError):
        with line_lock("/dev/ttyS0", "bus a"):
            raise RuntimeError("boom")
    with line_lock("/dev/ttyS0", "bus a"):
        pass
