"""A serial device is one line for every program: prc3cfg against other serial programs' locks.

The ports are real pseudo-terminals (`os.openpty`, or socat's `pty` joined to an emulator over
TCP) and the other programs real ones: picocom (Debian's holds a `flock` on the device),
minicom (writes `LCK..NAME` in /var/lock), `sleep` as the live pid of a lock file written by
hand. Every test but the last keeps its lock files in its own folder (`PRC3CFG_UUCP_LOCK_DIR`,
tests/conftest.py); the last uses the machine's /var/lock, as a user meets it. Processes are
followed by what they print, never by sleeping.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import string
import subprocess
import sys
import uuid
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from tools import needs, which

from prc3cfg.shell import serial_lock
from prc3cfg.shell.locks import device_path, line_keys, line_lock

SOCAT, PICOCOM, MINICOM = which("socat"), which("picocom"), which("minicom")


def prc3cfg(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prc3cfg", *args], capture_output=True, text=True)


def scan(port: str) -> subprocess.CompletedProcess:
    """`prc3cfg scan` of a pty: the 28 silent addresses of an emulator with modules 1 and 2 waited at
    0.1 s each (its default 0.2 s doubles the test's time, and the locks are what it is about)."""
    return prc3cfg("scan", "--port", port, "--parity", "none", "--timeout", "0.1")


@contextlib.contextmanager
def started(argv: list[str], ready: str, *, stream: str = "stdout"):
    """A process, once it has printed a line containing `ready` on `stream`; the line with it."""
    process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = []
        while not lines or ready not in lines[-1]:
            line = getattr(process, stream).readline()
            assert line, f"{argv[0]} ended before saying {ready!r}: {''.join(lines)}"
            lines.append(line)
        yield process, lines[-1]
    finally:
        process.terminate()
        process.communicate()


@contextlib.contextmanager
def emulator_pty():
    """`prc3cfg emulator serve --pty` (modules 1 and 2): the path of its pty."""
    argv = [sys.executable, "-m", "prc3cfg", "emulator", "serve", "--pty", "--parity", "none", "--modules",
            "1,2"]
    with started(argv, "pty: ") as (_, line):
        yield line.removeprefix("pty: ").strip()


@contextlib.contextmanager
def socat_port(link: Path):
    """A pty made by socat at `link` (a symlink to /dev/pts/N), joined to an emulator over TCP."""
    argv = [sys.executable, "-m", "prc3cfg", "emulator", "serve", "--listen", "127.0.0.1:0", "--parity",
            "none", "--modules", "1,2"]
    with started(argv, "listening on ") as (_, line):
        address = line.split()[2]
        with started([SOCAT, "-d", "-d", f"pty,raw,echo=0,link={link}", f"tcp:{address}"],
                     "starting data transfer loop", stream="stderr"):
            yield str(link)


@contextlib.contextmanager
def on_a_terminal(argv: list[str], ready: bytes):
    """A terminal program (picocom, minicom) with a pty as its terminal, once it has shown `ready`; the
    terminal one it can draw on whatever TERM the tests run under (minicom ends at once on a "dumb" one)."""
    master, terminal = os.openpty()
    process = subprocess.Popen(argv, stdin=terminal, stdout=terminal, stderr=terminal, start_new_session=True,
                               env={**os.environ, "TERM": "xterm"})
    os.close(terminal)
    try:
        shown = b""
        while ready not in shown:
            chunk = os.read(master, 4096)
            assert chunk, f"{argv[0]} ended before showing {ready!r}: {shown!r}"
            shown += chunk
        yield process
    finally:
        process.kill()
        process.wait()
        os.close(master)


@pytest.fixture
def sleeper():
    """A live process that is no serial program."""
    process = subprocess.Popen(["sleep", "infinity"])
    yield process
    process.kill()
    process.wait()


def lock_file(name: str) -> Path:
    return serial_lock.uucp_lock_dir() / f"LCK..{name}"


def hdb(pid: int) -> bytes:
    return f"{pid:10d}\n".encode()


def dead_pid() -> int:
    process = subprocess.Popen(["true"])
    process.wait()
    return process.pid


@pytest.mark.parametrize(("port", "device"), [
    ("/dev/ttyUSB0", "/dev/ttyUSB0"),
    ("spy:///dev/ttyUSB0?file=trace.txt", "/dev/ttyUSB0"),
    ("socket://gateway:7001", None),
    ("rfc2217://gateway:7001", None),
    ("emulator://booth-a", None),
    ("loop://", None),
])
def test_the_device_a_port_names(port, device):
    assert device_path(port) == device


@pytest.mark.parametrize(("path", "uucp", "minicom", "picocom"), [
    ("/dev/ttyUSB0", "ttyUSB0", "ttyUSB0", "ttyUSB0"),  # every convention agrees on a device directly in /dev
    ("/dev/pts/0", "0", "pts_0", "pts_0"),  # minicom and picocom: the path below /dev with its / as _
    ("/dev/serial/by-id/usb-FTDI-if00", "usb-FTDI-if00", "serial_by-id_usb-FTDI-if00",
     "serial_by-id_usb-FTDI-if00"),
    # outside /dev: minicom the last part, picocom all but the first
    ("/srv/lines/booth-a", "booth-a", "booth-a", "lines_booth-a"),
])
def test_lock_names_are_written_as_uucp_minicom_and_picocom_write_them(path, uucp, minicom, picocom):
    """The UUCP convention (cu, HDB) names a lock file after the path's last part, minicom (`mbasename`)
    and picocom built with UUCP locks (`uucp_lockname`) after the path below /dev with its / as _:
    each spelling is checked and written."""
    assert {name: naming(path) for name, naming in serial_lock.NAMINGS.items()} == {"UUCP": uucp,
                                                                                    "minicom": minicom,
                                                                                    "picocom": picocom}
    assert serial_lock.lock_names(path) == tuple(f"LCK..{name}"
                                                 for name in dict.fromkeys((uucp, minicom, picocom)))


names = st.text(string.ascii_letters + string.digits + "-_.", min_size=1, max_size=12)
device_paths = st.lists(names.filter(lambda p: p not in (".", "..")), min_size=1, max_size=4).map(
    lambda parts: "/dev/" + "/".join(parts))


def names_of(path: str) -> None:
    """Every spelling of a device path below /dev is a name of its own (no /), once: the UUCP one and
    minicom's, which picocom's equals."""
    names = serial_lock.lock_names(path)
    assert len(set(names)) == len(names) and all(name.startswith("LCK..") and "/" not in name
                                                 for name in names)
    assert {f"LCK..{os.path.basename(path)}",
            f"LCK..{path.removeprefix('/dev/').replace('/', '_')}"} <= set(names)
    assert serial_lock.NAMINGS["minicom"](path) == serial_lock.NAMINGS["picocom"](path)


@settings(max_examples=50)
@given(device_paths)
def test_every_spelling_of_a_device_below_dev_is_a_lock_name(path):
    names_of(path)


@pytest.mark.soak
@given(device_paths)
def test_every_spelling_of_a_device_below_dev_is_a_lock_name_soak(path):
    names_of(path)


@pytest.mark.parametrize("named", ["given", "real"])
def test_a_lock_file_of_a_live_process_refuses_naming_it_and_is_left(tmp_path, sleeper, named):
    with emulator_pty() as pty:
        link = tmp_path / "booth-a"
        link.symlink_to(pty)
        held = lock_file(link.name if named == "given" else Path(pty).name)
        held.write_bytes(hdb(sleeper.pid))
        refused = scan(str(link))
    assert refused.returncode != 0
    assert refused.stderr == (f"error: {link}: the serial port {link} is in use by sleep (pid "
                              f"{sleeper.pid}) — close it and run again\n")
    assert held.read_bytes() == hdb(sleeper.pid)
    assert sorted(p.name for p in serial_lock.uucp_lock_dir().iterdir()) == [held.name]


def test_a_plant_bus_on_a_device_another_program_holds_is_refused(tmp_path, sleeper):
    with emulator_pty() as pty:
        plant = tmp_path / "plant.yaml"
        plant.write_text(f"plant: t\nbuses:\n  - name: booth-a\n    port: {pty}\n    parity: none\n"
                         "    modules:\n      - {address: 1, name: left}\n")
        lock_file(Path(pty).name).write_bytes(hdb(sleeper.pid))
        refused = prc3cfg("plan", str(plant))
    assert refused.returncode != 0
    assert refused.stderr == (f"error: bus booth-a ({pty}): the serial port {pty} is in use by sleep (pid "
                              f"{sleeper.pid}) — close it and run again\n")


@pytest.mark.parametrize("left", ["dead pid", "old garbage"])
def test_a_stale_lock_file_is_taken_over(tmp_path, left):
    with emulator_pty() as pty:
        link = tmp_path / "booth-a"
        link.symlink_to(pty)
        stale = lock_file(Path(pty).name)
        stale.write_bytes(hdb(dead_pid()) if left == "dead pid" else b"\x00garbage")
        if left == "old garbage":
            os.utime(stale, (0, os.stat(stale).st_mtime - serial_lock.GARBAGE_AGE))
        scanned = scan(str(link))
    assert scanned.returncode == 0, scanned.stderr
    assert "2 modules answered" in scanned.stdout
    assert list(serial_lock.uucp_lock_dir().iterdir()) == []


def test_a_lock_file_without_a_pid_is_left_to_its_writer_while_young(tmp_path):
    with emulator_pty() as pty:
        young = lock_file(Path(pty).name)
        young.write_bytes(b"")  # another program between making its lock file and writing its pid
        refused = scan(pty)
    assert refused.returncode != 0
    assert (f"the serial port {pty} is in use by another program (its lock file {young} names no "
            "process yet)") in refused.stderr
    assert young.exists()


def test_its_own_lock_files_hold_its_pid_while_it_runs_and_go_after(tmp_path):
    master, terminal = os.openpty()
    try:
        link = tmp_path / "booth-a"
        link.symlink_to(os.ttyname(terminal))
        argv = [sys.executable, "-m", "prc3cfg", "scan", "--port", str(link), "--parity", "none", "--timeout",
                "0.5", "--retries", "0"]
        process = subprocess.Popen(argv, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
        while not select.select([master], [], [], 1)[0]:  # its first request: the line is held
            assert process.poll() is None, process.stderr.read()
        os.read(master, 4096)
        names = {name.removeprefix("LCK..") for name in serial_lock.lock_names(str(link))}
        assert {link.name, Path(os.ttyname(terminal)).name,
                os.ttyname(terminal).removeprefix("/dev/").replace("/", "_")} <= names
        lock_bytes = {name: lock_file(name).read_bytes() for name in names}
        assert lock_bytes == dict.fromkeys(names, hdb(process.pid))
        process.send_signal(signal.SIGINT)  # stopped mid-scan: the lock files go all the same
        process.communicate()
    finally:
        os.close(master)
        os.close(terminal)
    assert list(serial_lock.uucp_lock_dir().iterdir()) == []


def test_a_lock_file_another_program_wrote_over_ours_is_never_removed(tmp_path, sleeper):
    master, terminal = os.openpty()
    try:
        link = tmp_path / "booth-a"
        link.symlink_to(os.ttyname(terminal))
        given, real = lock_file(link.name), lock_file(Path(os.ttyname(terminal)).name)
        with line_lock(line_keys(str(link)), "bus a", port=str(link)):
            assert given.read_bytes() == real.read_bytes() == hdb(os.getpid())
            given.write_bytes(hdb(sleeper.pid))
    finally:
        os.close(master)
        os.close(terminal)
    assert given.read_bytes() == hdb(sleeper.pid)
    assert not real.exists()


def test_a_lock_folder_that_is_missing_is_passed_over_in_silence(tmp_path, monkeypatch):
    monkeypatch.setenv("PRC3CFG_UUCP_LOCK_DIR", str(tmp_path / "no-such-folder"))
    master, terminal = os.openpty()
    try:
        with line_lock(line_keys(os.ttyname(terminal)), "bus a", port=os.ttyname(terminal)):
            assert not (tmp_path / "no-such-folder").exists()
    finally:
        os.close(master)
        os.close(terminal)


@needs("socat", "picocom")
def test_picocom_holding_the_port_is_named(tmp_path):
    with socat_port(tmp_path / "booth-a") as port, on_a_terminal([PICOCOM, "-b", "9600", port],
                                                                 b"Terminal ready") as picocom:
        refused = {spelling: scan(spelling) for spelling in (port, os.path.realpath(port))}
    for spelling, result in refused.items():
        assert result.returncode != 0
        assert result.stderr == (f"error: {spelling}: the serial port {spelling} is in use by picocom (pid "
                                 f"{picocom.pid}) — close it and run again\n")


def writable_system_lock_dir() -> bool:
    return os.access(serial_lock.SYSTEM_LOCK_DIR, os.W_OK)


@needs("socat", "minicom")
@pytest.mark.skipif(not writable_system_lock_dir(),
                    reason=f"{serial_lock.SYSTEM_LOCK_DIR} cannot be written by this user")
def test_minicom_in_the_system_lock_folder_is_honoured_and_its_stale_lock_taken_over(tmp_path, monkeypatch):
    monkeypatch.delenv("PRC3CFG_UUCP_LOCK_DIR")
    # /var/lock is the machine's: a name no one else has
    link = tmp_path / f"prc3cfg-test-{uuid.uuid4().hex[:12]}"
    held, pid = serial_lock.SYSTEM_LOCK_DIR / f"LCK..{link.name}", None
    try:
        with socat_port(link) as port:
            with on_a_terminal([MINICOM, "-D", port], b"Press CTRL-A Z") as minicom:
                pid = minicom.pid
                assert held.read_bytes() == hdb(pid)
                refused = scan(port)
            assert refused.returncode != 0
            assert (f"the serial port {port} is in use by minicom (pid {pid}) — close it and "
                    "run again") in refused.stderr
            assert held.read_bytes() == hdb(pid)  # killed: its lock file is left, stale
            scanned = scan(port)
        assert scanned.returncode == 0, scanned.stderr
        assert not held.exists()
    finally:
        # a failure above: not left to the machine
        if pid is not None and held.exists() and held.read_bytes() == hdb(pid):
            held.unlink()


def shown_until_it_ends(argv: list[str]) -> tuple[int, bytes]:
    """A terminal program (minicom, picocom) run on a pty as its terminal until it ends by itself: its exit
    code and what it showed (a program that does not end within 30 s fails the test)."""
    master, terminal = os.openpty()
    process = subprocess.Popen(argv, stdin=terminal, stdout=terminal, stderr=terminal, start_new_session=True)
    os.close(terminal)
    shown = b""
    try:
        while select.select([master], [], [], 30)[0]:
            try:
                chunk = os.read(master, 4096)
            except OSError:  # EIO: the program ended and its terminal closed
                break
            if not chunk:
                break
            shown += chunk
        else:
            raise AssertionError(f"{argv[0]} is still running, having shown {shown[-300:]!r}")
        return process.wait(), shown
    finally:
        process.kill()
        process.wait()
        os.close(master)


@contextlib.contextmanager
def system_lock_folder(monkeypatch, device: str):
    """The machine's /var/lock, where minicom looks, for the test's lock files; afterwards no lock file of
    `device` is left that names a process of this test (a killed minicom leaves its own)."""
    monkeypatch.delenv("PRC3CFG_UUCP_LOCK_DIR")
    ours: set[int] = {os.getpid()}
    try:
        yield ours
    finally:
        minicoms = f"LCK..{device.removeprefix('/dev/').replace('/', '_')}"
        for name in {*serial_lock.lock_names(device), minicoms}:
            path = serial_lock.SYSTEM_LOCK_DIR / name
            if path.exists() and path.read_bytes() in {hdb(pid) for pid in ours}:
                path.unlink()


@needs("socat", "minicom")
@pytest.mark.skipif(not writable_system_lock_dir(),
                    reason=f"{serial_lock.SYSTEM_LOCK_DIR} cannot be written by this user")
def test_minicom_holding_a_nested_device_path_is_named(tmp_path, monkeypatch):
    """minicom on /dev/pts/N writes LCK..pts_N (the path below /dev, / as _), where the UUCP convention
    writes LCK..N: prc3cfg checks both, by the path as minicom was given it and through a link to it."""
    with socat_port(tmp_path / "booth-a") as link:
        device = os.path.realpath(link)
        with system_lock_folder(monkeypatch, device) as ours:
            with on_a_terminal([MINICOM, "-D", device], b"Press CTRL-A Z") as minicom:
                ours.add(minicom.pid)
                held = serial_lock.SYSTEM_LOCK_DIR / f"LCK..{device.removeprefix('/dev/').replace('/', '_')}"
                assert held.read_bytes() == hdb(minicom.pid)
                refused = {spelling: scan(spelling) for spelling in (device, link)}
    for spelling, result in refused.items():
        assert result.returncode != 0
        assert (f"the serial port {spelling} is in use by minicom (pid {minicom.pid}) — close it and "
                "run again") in result.stderr


@needs("picocom", "minicom")
@pytest.mark.skipif(not writable_system_lock_dir(),
                    reason=f"{serial_lock.SYSTEM_LOCK_DIR} cannot be written by this user")
def test_minicom_and_picocom_refuse_a_device_prc3cfg_holds(monkeypatch):
    """A real `prc3cfg scan` holding /dev/pts/N (nothing answers it; it waits 10 s at each address): minicom
    finds prc3cfg's LCK..pts_N and refuses, picocom as Debian builds it finds the device's flock and refuses.
    """
    master, terminal = os.openpty()
    device = os.ttyname(terminal)
    try:
        with system_lock_folder(monkeypatch, device) as ours:
            argv = [sys.executable, "-m", "prc3cfg", "scan", "--port", device, "--parity", "none",
                    "--timeout", "10", "--retries", "0"]
            process = subprocess.Popen(argv, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
            ours.add(process.pid)
            try:
                while not select.select([master], [], [], 1)[0]:  # its first request: the line is held
                    assert process.poll() is None, process.stderr.read()
                minicom = shown_until_it_ends([MINICOM, "-D", device])
                picocom = shown_until_it_ends([PICOCOM, "-b", "9600", device])
                assert process.poll() is None  # still holding the line throughout
            finally:
                process.send_signal(signal.SIGINT)
                process.communicate()
    finally:
        os.close(master)
        os.close(terminal)
    assert minicom == (1, f"Device {device} is locked.\r\n".encode())
    assert (picocom[0] == 1
            and f"FATAL: cannot lock {device}: Resource temporarily unavailable".encode() in picocom[1])
