"""The platform seam (`prc3cfg.shell.platform`): what differs between POSIX and Windows lives
there and nowhere else, and the package imports — and validates a plant file — without the
POSIX-only modules. mypy checks the other systems' branches (`mypy --platform win32`, `darwin`:
.ci/run); these tests check what can be checked on Linux.
"""

from __future__ import annotations

import ast
import os
import re
import socket
import stat
import subprocess
import sys
from pathlib import Path

import pytest
from emulated import emulated_plant, run_cli

from prc3cfg.shell import platform

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "prc3cfg"
SEAM = PACKAGE / "shell" / "platform.py"

#: Modules that exist on one system only: only the seam imports them.
SYSTEM_MODULES = {"fcntl", "termios", "tty", "pty", "grp", "pwd", "resource", "msvcrt", "winreg", "_winapi",
                  "winsound"}

#: Imports every module of prc3cfg, then validates the demo plant, in an interpreter that looks
#: like Windows to prc3cfg: sys.platform is "win32", the POSIX-only modules cannot be imported,
#: msvcrt is a stand-in and os has Windows' open flags. What prc3cfg imports from outside
#: (pydantic, typer, serial, …) is imported first, as this system has it. Not Windows: a check that
#: nothing at import time reaches for what Windows lacks.
AS_ON_WINDOWS = """
import ctypes, getpass, importlib, importlib.abc, os, select, selectors, signal, socket, subprocess, sys
import sysconfig, tempfile, types, zoneinfo
import pydantic, pydantic.main, pydantic.type_adapter, rich, rich.console, rich.live, rich.progress
import typer, yaml
import serial, serial.rfc2217, serial.tools.list_ports, serial.urlhandler.protocol_socket
from pathlib import Path
sysconfig.get_config_vars()
POSIX_ONLY = {"fcntl", "termios", "tty", "pty", "grp", "pwd", "resource"}
# C modules only Windows' Python has, which a third-party library imports there (asyncio's proactor, for
# asyncua: `prc3cfg status serve`) — the real Windows tier imports them; this pretence cannot
WINDOWS_ONLY = {"_overlapped", "_winapi"}

class Refuse(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in POSIX_ONLY:
            raise ModuleNotFoundError(f"No module named {name!r}")
        return None

for name in [name for name in sys.modules if name.split(".")[0] in POSIX_ONLY]:
    del sys.modules[name]
sys.meta_path.insert(0, Refuse())
msvcrt = types.ModuleType("msvcrt")
msvcrt.LK_NBLCK, msvcrt.LK_UNLCK, msvcrt.locking = 2, 0, lambda *args: None
sys.modules["msvcrt"] = msvcrt
ctypes.windll = types.SimpleNamespace()
os.O_NOINHERIT, os.O_BINARY = 0x80, 0x8000
sys.platform = "win32"

import prc3cfg
root = Path(prc3cfg.__file__).parent
failed = []
for file in sorted(root.rglob("*.py")):
    name = ".".join(("prc3cfg", *file.relative_to(root).with_suffix("").parts)).removesuffix(".__init__")
    try:
        importlib.import_module(name)
    except ModuleNotFoundError as error:
        # the standard library's own Windows modules: not here to pretend with
        if error.name not in WINDOWS_ONLY:
            failed.append(f"{name}: {type(error).__name__}: {error}")
    except Exception as error:
        failed.append(f"{name}: {type(error).__name__}: {error}")
print("\\n".join(failed) or "imported", flush=True)
from prc3cfg.shell import locks
# no owners to check, one file for every user
with locks.line_lock(locks.line_keys("COM3"), "bus a") as (path,):
    print("locked", path.name, flush=True)
sys.argv = ["prc3cfg", "validate", sys.argv[1]]
from prc3cfg.cli import main
main()
"""


def system_imports(path: Path) -> set[str]:
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add(node.module.split(".")[0])
    return found & SYSTEM_MODULES


def test_only_the_seam_imports_what_one_system_has():
    wrong = {f"{path.relative_to(ROOT)} imports {', '.join(sorted(names))}"
             for path in PACKAGE.rglob("*.py") if path != SEAM and (names := system_imports(path))}
    assert not wrong, sorted(wrong)
    assert system_imports(SEAM) >= {"fcntl", "termios", "msvcrt"}  # the check can see an import


def test_only_the_seam_reads_proc():
    """Linux's /proc (a file's pid, its kernel locks, an unnamed file's link) is asked of the seam."""
    wrong = {f"{path.relative_to(ROOT)}:{node.lineno}"
             for path in PACKAGE.rglob("*.py") if path != SEAM
             for node in ast.walk(ast.parse(path.read_text()))
             if isinstance(node, ast.Constant) and isinstance(node.value, str)
             and node.value.startswith("/proc")}
    assert not wrong, sorted(wrong)


def test_every_module_imports_and_a_plant_validates_as_on_windows():
    done = subprocess.run([sys.executable, "-c", AS_ON_WINDOWS, str(ROOT / "plants" / "demo-line.yaml")],
                          capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert done.stdout.splitlines()[:1] == ["imported"], done.stdout + done.stderr
    assert re.fullmatch(r"locked [0-9a-f]{24}\.lock", done.stdout.splitlines()[1]), done.stdout + done.stderr
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Traceback" not in done.stderr


def test_linux_keeps_its_folders():
    assert platform.LOCK_FOLDERS == ((Path("/run/lock"), "prc3cfg"), (Path("/var/lock"), "prc3cfg"),
                                     (Path("/tmp"), "prc3cfg-locks"))
    assert platform.SYSTEM_STATE_DIR == Path("/var/lib/prc3cfg")


def test_the_user_s_state_folder_is_xdg_s(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    assert platform.user_state_dir() == tmp_path / "prc3cfg"
    monkeypatch.delenv("XDG_STATE_HOME")
    assert platform.user_state_dir() == Path.home() / ".local" / "state" / "prc3cfg"


def test_a_process_is_alive_while_it_runs():
    assert platform.process_alive(os.getpid())
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    assert not platform.process_alive(child.pid)
    assert not platform.process_alive(2**70)


def test_a_lock_is_exclusive_until_released(tmp_path):
    path = tmp_path / "a.lock"
    first, second = os.open(path, os.O_RDWR | os.O_CREAT), os.open(path, os.O_RDWR)
    try:
        assert platform.try_lock(first)
        assert not platform.try_lock(second)
        platform.unlock(first)
        assert platform.try_lock(second)
    finally:
        os.close(first)
        os.close(second)


def test_bytes_at_an_offset_are_read_and_written_in_place(tmp_path):
    fd = os.open(tmp_path / "f", os.O_RDWR | os.O_CREAT)
    try:
        platform.write_at(fd, b"holder", 0)
        platform.write_at(fd, b"H", 0)
        assert platform.read_at(fd, 100, 0) == b"Holder"
        assert platform.read_at(fd, 3, 3) == b"der"
    finally:
        os.close(fd)


def test_a_socket_says_what_waits_and_when_its_peer_hangs_up():
    ours, theirs = socket.socketpair()
    try:
        assert platform.bytes_waiting(ours) == 0 and not platform.hung_up(ours)
        theirs.sendall(b"abc")
        for _ in range(100):
            if platform.bytes_waiting(ours) == 3:
                break
        assert platform.bytes_waiting(ours) == 3
        assert not platform.hung_up(ours)
        theirs.close()
        assert platform.hung_up(ours)
    finally:
        ours.close()
        theirs.close()


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full here")
def test_a_device_s_numbers_are_its_major_and_minor():
    assert platform.device_number(os.stat("/dev/full")) == (1, 7)
    assert platform.device_number(os.stat(ROOT / "README.md")) is None


def test_a_pseudo_terminal_is_known_by_its_device():
    master, slave, path = platform.open_pty()
    try:
        assert platform.is_pseudo_terminal(path)
        assert path == platform.terminal_path(slave)
        assert not platform.is_pseudo_terminal(str(ROOT / "README.md"))
        assert not platform.is_pseudo_terminal("/no/such/device")
    finally:
        os.close(master)
        os.close(slave)


def test_a_lock_held_elsewhere_is_seen_without_being_taken(tmp_path):
    path = tmp_path / "x.lock"
    path.write_text("")
    holder, looker = os.open(path, os.O_RDWR), os.open(path, os.O_RDONLY)
    try:
        assert not platform.is_locked(looker)
        assert platform.try_lock(holder)  # the look let go of what it tried
        assert platform.is_locked(looker)
        platform.unlock(holder)
        assert not platform.is_locked(looker)
    finally:
        os.close(holder)
        os.close(looker)


def test_a_shared_folder_is_made_sticky_whatever_the_umask_and_never_through_a_link(tmp_path):
    previous = os.umask(0o077)
    try:
        platform.make_shared_folder(tmp_path / "locks", 0o1777)
    finally:
        os.umask(previous)
    assert stat.S_IMODE((tmp_path / "locks").stat().st_mode) == 0o1777
    (tmp_path / "elsewhere").mkdir(mode=0o700)
    (tmp_path / "link").symlink_to(tmp_path / "elsewhere")
    with pytest.raises(FileExistsError):
        platform.make_shared_folder(tmp_path / "link", 0o1777)
    assert stat.S_IMODE((tmp_path / "elsewhere").stat().st_mode) == 0o700


# -- Windows' serial ports: COM3, COM10, \\.\COM10 -----------------------------------------

COM_PORTS = [("COM3", "COM3"), ("COM10", "COM10"), ("com10", "COM10"), (r"\\.\COM10", "COM10"),
             (r"\\.\com255", "COM255"),
             ("COM0", None), ("COM", None), ("/dev/ttyUSB0", None), ("socket://localhost:4001", None),
             ("COM3:", None)]


@pytest.mark.parametrize(("port", "name"), COM_PORTS)
def test_a_com_port_is_known_by_its_name(port, name):
    assert platform.com_port_name(port) == name


@pytest.mark.parametrize("port", ["COM3", "COM10", r"\\.\COM10"])
def test_a_com_port_is_a_valid_port(port):
    from prc3cfg.plant.messages import port_error

    assert port_error("--port", port) is None


def test_a_plant_on_com_ports_validates(tmp_path):
    """A plant file written for a Windows laptop validates anywhere (here: on Linux)."""
    text = (ROOT / "plants" / "demo-line.yaml").read_text()
    assert "emulator://demo-a" in text and "emulator://demo-b" in text
    plant = tmp_path / "demo-line.yaml"
    plant.write_text(text.replace("emulator://demo-a", "COM3").replace("emulator://demo-b", "'\\\\.\\COM10'"))
    done = subprocess.run([sys.executable, "-m", "prc3cfg", "validate", str(plant)], capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stdout + done.stderr


@pytest.mark.parametrize("port", ["COM3", r"\\.\COM10"])
def test_a_com_port_is_a_local_device_for_its_lock(port):
    """Locked as a local serial device (one key, `dev/…`; the serial-port lock applies to it), not as a TCP
    line."""
    from prc3cfg.shell.locks import device_path, line_keys

    assert device_path(port) == port
    keys = line_keys(port)
    assert len(keys) == 1 and keys[0].startswith("dev/")
    # a TCP line keeps the machine-wide key
    assert line_keys("socket://127.0.0.1:4001") == ("tcp/127.0.0.1/4001",)


def test_on_windows_two_spellings_of_a_com_port_are_one_line(monkeypatch):
    """`device_identity` asks sys.platform when it is called: here it is told it runs on Windows."""
    from prc3cfg.shell.locks import line_keys

    monkeypatch.setattr(sys, "platform", "win32")
    assert line_keys("COM10") == line_keys("com10") == line_keys(r"\\.\COM10") == ("dev/COM10",)


@pytest.mark.parametrize(("parity", "byte_size", "stop_bits", "said"), [
    (0, 8, 0, ("none", 8, False)),
    (2, 8, 0, ("even", 8, False)),
    (1, 7, 2, ("odd", 7, True)),
    (154, 8, 0, ("code 154", 8, False)),  # Wine 8 on a pty asked for odd parity: no line's parity
])
def test_a_com_port_s_dcb_is_read_as_a_character_format(parity, byte_size, stop_bits, said):
    """Windows' read-back of the format a COM port keeps (GetCommState): a port that dropped the
    parity it was given (Wine's COMn on a pty, given even) is refused as a pty is on Linux."""
    assert platform.dcb_format(parity, byte_size, stop_bits) == said


def test_the_registry_s_com_ports_are_windows_only():
    assert platform.registered_serial_ports() == []


def test_no_wait_without_a_timeout_outside_the_seam():
    """`Event.wait()`, `Future.result()`, `Thread.join()`, `Queue.get()` without a timeout: on Windows no
    Ctrl-C handler runs inside them (an apply answered Ctrl-C only when its lines were done; `emulator serve`
    never). They are `platform.wait_for`, `platform.result_of` and `platform.next_of`."""
    wrong = {f"{path.relative_to(ROOT)}:{node.lineno}: .{node.func.attr}()"
             for path in PACKAGE.rglob("*.py") if path != SEAM
             for node in ast.walk(ast.parse(path.read_text()))
             if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
             and node.func.attr in ("wait", "result", "join", "get")
             and not node.args and not node.keywords
             and not (isinstance(node.func.value, ast.Name) and node.func.value.id in ("os", "str"))}
    assert not wrong, sorted(wrong)


def test_a_wait_ends_when_its_event_is_set_and_a_result_is_the_future_s():
    import threading
    from concurrent.futures import ThreadPoolExecutor

    event = threading.Event()
    threading.Timer(0.05, event.set).start()
    platform.wait_for(event)
    assert event.is_set()
    with ThreadPoolExecutor(1) as pool:
        assert platform.result_of(pool.submit(lambda: 42)) == 42
        with pytest.raises(ZeroDivisionError):
            platform.result_of(pool.submit(lambda: 1 / 0))


@pytest.mark.parametrize("system", ["linux", "win32"])
def test_the_next_item_is_the_queue_s_as_it_comes(system, monkeypatch):
    """`platform.next_of`: each item in order, one put by another thread while it waits — on Windows too (in
    slices)."""
    import queue
    import threading

    monkeypatch.setattr(sys, "platform", system)
    items: queue.SimpleQueue[int] = queue.SimpleQueue()
    items.put(1)
    assert platform.next_of(items) == 1
    threading.Timer(0.25, items.put, (2,)).start()  # later than a slice: Windows' waits more than once
    assert platform.next_of(items) == 2


def test_text_is_written_as_given_in_utf_8(tmp_path):
    """A CRLF plant file rewritten by adopt keeps its CRLF (Windows' text mode made it \\r\\r\\n), and
    ✓ ⚠ → are written in UTF-8 (not the locale's code page)."""
    path = tmp_path / "plant.yaml"
    with platform.open_text(path) as handle:
        handle.write("a: 1\r\nb: 2 ✓\n")
    with platform.open_text(path, "a") as handle:
        handle.write("c: ⚠ →\r\n")
    assert path.read_bytes() == "a: 1\r\nb: 2 ✓\nc: ⚠ →\r\n".encode()


def test_paths_are_resolved_through_the_seam():
    """`Path.resolve()` and `os.path.realpath()` raise on Windows for a path over 260 characters (WinError
    234): outside the seam they are called only through `platform.resolved` / `real_path`, which fall back to
    the absolute path."""
    wrong = {f"{path.relative_to(ROOT)}:{node.lineno}"
             for path in PACKAGE.rglob("*.py") if path != SEAM
             for node in ast.walk(ast.parse(path.read_text()))
             if (isinstance(node, ast.Call) and not node.args
                 and getattr(node.func, "attr", None) == "resolve")
             # PyYAML's resolve(node, …) is no path's
             or (isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "realpath")}
    assert not wrong, sorted(wrong)


def test_a_plant_under_a_path_windows_will_not_resolve_is_planned_and_applied(tmp_path, capsys, monkeypatch):
    """Where the system refuses to resolve a path (Windows without long paths, over 260 characters: OSError
    234), plan and apply go on with the absolute path: no traceback, the records name it."""
    with emulated_plant(tmp_path) as plant:
        def refused(self, strict=False):
            raise OSError(234, "More data is available")

        monkeypatch.setattr(Path, "resolve", refused)
        monkeypatch.setattr(os.path, "realpath", lambda path, **_: refused(path))
        assert run_cli(capsys, "plan", plant.path).code == 0
        applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert applied.code == 0 and "Traceback" not in applied.err, applied.err
        assert plant.matches_plant()


def test_text_files_are_opened_through_the_seam():
    """Writing text with `open(…, "w"/"a")` outside the seam takes Windows' newline translation and code
    page."""
    wrong = {f"{path.relative_to(ROOT)}:{node.lineno}"
             for path in PACKAGE.rglob("*.py") if path != SEAM
             for node in ast.walk(ast.parse(path.read_text()))
             if isinstance(node, ast.Call)
             and (getattr(node.func, "id", None) == "open"
                  or getattr(node.func, "attr", None) in ("open", "fdopen"))
             and any(isinstance(a, ast.Constant) and a.value in ("w", "a", "wt", "at")
                     for a in [*node.args, *(k.value for k in node.keywords)])}
    assert not wrong, sorted(wrong)
@pytest.mark.parametrize(("system", "words", "command"), [
    ("linux", ["prc3cfg", "restore", "/home/jörg/Anlage Süd – Linie 3/s.json"],
     "prc3cfg restore '/home/jörg/Anlage Süd – Linie 3/s.json'"),
    ("linux", ["prc3cfg", "apply", "--plan", "it's.json"], "prc3cfg apply --plan 'it'\"'\"'s.json'"),
    ("win32", ["prc3cfg", "restore", r"C:\Users\Jörg Müller\Anlage Süd – Linie 3\s.json"],
     r'prc3cfg restore "C:\Users\Jörg Müller\Anlage Süd – Linie 3\s.json"'),
    ("win32", ["prc3cfg", "doctor", "--port", "COM10"], "prc3cfg doctor --port COM10"),
    # the closing quote not escaped
    ("win32", ["prc3cfg", "restore", "D:\\a&b (1)\\"], 'prc3cfg restore "D:\\a&b (1)\\\\"'),
])
def test_a_command_printed_for_a_person_is_quoted_for_the_system_s_shell(monkeypatch, system, words, command):
    monkeypatch.setattr(sys, "platform", system)
    assert platform.command_line(*words) == command


@pytest.mark.parametrize(("system", "executable", "command"), [
    ("linux", "/usr/bin/python3", "/usr/bin/python3"),
    ("linux", "/opt/my python/bin/python3", "'/opt/my python/bin/python3'"),
    ("win32", r"C:\Python311\python.exe", r"C:\Python311\python.exe"),
    ("win32", r"C:\Program Files\Python311\python.exe", r'"C:\Program Files\Python311\python.exe"'),
])
def test_this_python_is_a_command_to_paste_into_the_system_s_shell(monkeypatch, system, executable, command):
    """What the plot hint names (`python -m pip install matplotlib` into the Python that runs prc3cfg)."""
    monkeypatch.setattr(sys, "platform", system)
    monkeypatch.setattr(sys, "executable", executable)
    assert platform.python_command() == command
