"""The ports a plant file may name (issue 39, item 1): a serial device, `socket://`, `rfc2217://` and
`emulator://` — nothing else. A plant file is reviewed text, yet pyserial turns any other `xxx://` into a
handler of its own (`spy://…?file=` writes a file, `alt://` picks a class, `hwgrep://` searches); those are
refused at `validate` in one line naming file:line:col, and again by `open_port` before pyserial sees a port
that reached it another way (an API user's bus). A command line's port stays the operator's own choice.
"""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import jsonschema
import pytest
import serial.urlhandler
from emulated import run_cli
from hypothesis import given, settings
from hypothesis import strategies as st

from prc3cfg import api
from prc3cfg.core.line import LineSettings
from prc3cfg.errors import UserError
from prc3cfg.plant import PlantError, plant_schema
from prc3cfg.shell.link.ports import open_port
from prc3cfg.shell.plant_files import load_plant

ROOT = Path(__file__).resolve().parents[1]

#: The bus's `port:` is on line 4 of `plant_with`'s file, its value at column 11.
PLANT = ('plant: p\nbuses:\n  - name: a\n    port: "{port}"\n    parity: none\n    modules:\n      - '
         '{{address: 1, name: m1}}\n')
AT = "4:11"

HANDLER = ("uses pyserial's {scheme}:// handler, which a plant file may not name — write a device path, "
           "socket://HOST:PORT, "
           "rfc2217://HOST:PORT or emulator://NAME (trace a line with prc3cfg's --trace)")
NOT_DEVICE = ("is not a serial device's full path — write the device's path under /dev (/dev/ttyUSB0, "
              "/dev/serial/by-id/…), COMn or \\\\.\\COMn, socket://HOST:PORT, rfc2217://HOST:PORT or "
              "emulator://NAME")
NOT_A_LINE = ("is this machine's own terminal, console or files, not a serial line — write the path of the "
              "line's adapter, e.g. /dev/ttyUSB0")

#: Hostile ports, and the end of the one line `validate` says about each.
HOSTILE = {
    "spy://, writing a file": ("spy:///dev/null?file=victim.txt", HANDLER.format(scheme="spy")),
    "spy://, a pty master": ("spy:///dev/ptmx", HANDLER.format(scheme="spy")),
    "alt://, a class": ("alt:///dev/ptmx?class=PosixPollSerial", HANDLER.format(scheme="alt")),
    "loop://": ("loop://", HANDLER.format(scheme="loop")),
    "hwgrep://": ("hwgrep://0403:6001", HANDLER.format(scheme="hwgrep")),
    "cp2110://": ("cp2110://0001:0004:00", HANDLER.format(scheme="cp2110")),
    "file://": ("file:///etc/passwd", HANDLER.format(scheme="file")),
    "an unknown scheme": ("xyz://a", HANDLER.format(scheme="xyz")),
    "the emulator in capitals": ("EMULATOR://a", HANDLER.format(scheme="emulator")),
    "a path holding ://": ("/dev/tty://x", HANDLER.format(scheme="/dev/tty")),
    "a relative path": ("ttyUSB0", NOT_DEVICE),
    "a relative path into a folder": ("dev/ttyUSB0", NOT_DEVICE),
    "a path outside /dev": ("/tmp/victim.txt", NOT_DEVICE),
    "a path out of /dev by ..": ("/dev/../etc/passwd", NOT_DEVICE),
    "/dev alone": ("/dev/", NOT_DEVICE),
    "a Windows path": ("C:\\\\Windows\\\\win.ini", NOT_DEVICE),
    "a Windows device that is no COM port": ("\\\\\\\\.\\\\PhysicalDrive0", NOT_DEVICE),
    "COM0": ("COM0", NOT_DEVICE),
    "the controlling terminal": ("/dev/tty", NOT_A_LINE),
    "the console": ("/dev/console", NOT_A_LINE),
    "a virtual console": ("/dev/tty1", NOT_A_LINE),
    "the pty master": ("/dev/ptmx", NOT_A_LINE),
    "standard output": ("/dev/stdout", NOT_A_LINE),
    "a file descriptor": ("/dev/fd/1", NOT_A_LINE),
    "shared memory, writable by all": ("/dev/shm/victim", NOT_A_LINE),
}

#: Ports a plant file may name (YAML double-quoted: a backslash is written twice).
ALLOWED = {
    "a device": "/dev/ttyUSB0",
    "a device by id": "/dev/serial/by-id/usb-FTDI_FT232R_A50285BI-if00-port0",
    "a pty": "/dev/pts/3",
    "macOS": "/dev/cu.usbserial-A50285BI",
    "a COM port": "COM3",
    "a COM port as Windows names it": "\\\\\\\\.\\\\COM12",
    "socket://": "socket://h:1",
    "socket:// in capitals": "SOCKET://h:1",
    "rfc2217://": "rfc2217://h:2?ign_set_control",
    "emulator://": "emulator://a?line-speed=1200",
}


def _unquoted(port: str) -> str:
    """A port of the tables as the plant file holds it (they are written for YAML's double quotes)."""
    return port.replace("\\\\", "\\")


def plant_with(folder: Path, port: str) -> Path:
    path = folder / "plant.yaml"
    path.write_text(PLANT.format(port=port))
    return path


@pytest.mark.parametrize("case", HOSTILE, ids=list(HOSTILE))
def test_validate_refuses_a_port_a_plant_file_may_not_name_in_one_line(tmp_path, capsys, case):
    port, said = HOSTILE[case]
    path = plant_with(tmp_path, port)
    result = run_cli(capsys, "validate", path)
    assert result.code == 1 and result.out == ""
    (line,) = result.err.splitlines()
    assert line.startswith(f"error: {path}:{AT}: port ") and line.endswith(said), line


@pytest.mark.parametrize("case", ALLOWED, ids=list(ALLOWED))
def test_validate_takes_the_ports_a_plant_file_may_name(tmp_path, capsys, case):
    result = run_cli(capsys, "validate", plant_with(tmp_path, ALLOWED[case]))
    assert (result.code, result.err) == (0, ""), result.err


def test_a_plant_file_naming_spy_leaves_the_file_it_names_untouched(tmp_path):
    """The issue's case across a real process: `plan` of `port: spy:///dev/null?file=victim.txt` truncated
    it."""
    folder = tmp_path / "repository"
    folder.mkdir()
    victim = folder / "victim.txt"
    victim.write_text("the system's user database\n")
    path = plant_with(folder, "spy:///dev/null?file=victim.txt")
    env = os.environ | {"PYTHONPATH": str(ROOT)}
    for command in (["plan", path.name], ["read", path.name], ["apply", path.name, "--auto-approve"]):
        ran = subprocess.run([sys.executable, "-m", "prc3cfg", *command], cwd=folder, env=env,
                             capture_output=True, text=True,
                             timeout=60)
        assert ran.returncode == 1 and ran.stdout == "", ran
        (line,) = ran.stderr.splitlines()
        assert line.startswith(f"error: {path.name}:{AT}: port 'spy://") and "handler" in line, line
        assert victim.read_text() == "the system's user database\n"
    assert sorted(p.name for p in folder.iterdir()) == ["plant.yaml", "victim.txt"]


@pytest.mark.parametrize("port", ["spy:///dev/null?file=victim.txt", "alt:///dev/ptmx?class=PosixPollSerial",
                                  "loop://",
                                  "ttyUSB0", "/dev/tty"])
def test_open_port_refuses_what_a_plant_file_may_not_name_before_pyserial_sees_it(tmp_path, monkeypatch,
                                                                                  port):
    folder = tmp_path / "cwd"
    folder.mkdir()
    monkeypatch.chdir(folder)
    (folder / "victim.txt").write_text("kept\n")
    with pytest.raises(UserError) as refused:
        open_port(port, LineSettings(parity="none"), bus="a")
    assert str(refused.value).startswith(f"bus a: port {port!r} ") and "\n" not in str(refused.value)
    assert (folder / "victim.txt").read_text() == "kept\n"
    assert sorted(p.name for p in folder.iterdir()) == ["victim.txt"]


def test_an_api_users_bus_with_another_handler_is_refused_before_the_line(tmp_path, monkeypatch):
    """A bus made in code, past the plant file's validation (`model_copy`), is refused by `open_port`."""
    folder = tmp_path / "cwd"
    folder.mkdir()
    monkeypatch.chdir(folder)
    plant = load_plant(plant_with(folder, "socket://127.0.0.1:9"))
    victim = folder / "victim.txt"
    victim.write_text("kept\n")
    spy = plant.buses[0].model_copy(update={"port": "spy:///dev/null?file=victim.txt"})
    forged = plant.model_copy(update={"buses": (spy,)})
    with pytest.raises(UserError) as refused:
        api.plan(forged)
    assert str(refused.value) == ("bus a: port 'spy:///dev/null?file=victim.txt' "
                                  f"{HANDLER.format(scheme='spy')}")
    assert victim.read_text() == "kept\n"


def test_a_command_lines_port_may_name_any_handler_of_pyserial(tmp_path, capsys, monkeypatch):
    """The operator's own choice at the machine: `scan --port loop://` opens pyserial's loop (where nothing
    answers)."""
    monkeypatch.chdir(tmp_path)
    result = run_cli(capsys, "scan", "--port", "loop://", "--parity", "none", "--timeout", "0.01")
    assert result.err.splitlines()[-1].startswith("error: loop://: no module answered at any "
                                                  "address 1..30"), result.err


def test_import_refuses_a_port_it_could_not_write_into_a_plant_file(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = run_cli(capsys, "import", "--port", "loop://", "--parity", "none")
    assert (result.code, result.out) == (1, "")
    assert result.err == (f"error: --port 'loop://' {HANDLER.format(scheme='loop')}: import writes it into "
                          "the plant file\n")


def test_the_schema_refuses_the_handlers_and_paths_validate_refuses():
    """What an editor marks: every hostile port of the table, and none of the allowed ones."""
    schema = jsonschema.Draft7Validator(plant_schema())

    def takes(port: str) -> bool:
        return schema.is_valid({"plant": "p",
                                "buses": [{"name": "a", "port": port,
                                           "modules": [{"address": 1, "name": "m"}]}]})

    for port, _ in HOSTILE.values():
        assert not takes(_unquoted(port)), port
    for port in ALLOWED.values():
        assert takes(_unquoted(port)), port


def test_an_emulators_name_and_query_select_no_path_a_plant_file_chooses(tmp_path, capsys):
    """`emulator://NAME` keeps its state in .prc3cfg/emulators/NAME.json beside the plant file; its query only
    tunes the emulator (`emulator_query`), so a key naming a path is refused in one line and nothing is made
    there."""
    elsewhere = tmp_path / "elsewhere.json"
    (tmp_path / "repository").mkdir()
    path = plant_with(tmp_path / "repository", f"emulator://a?state={elsewhere}")
    result = run_cli(capsys, "read", path)
    assert (result.code, result.out) == (1, "")
    assert result.err.startswith(f"error: bus a: port emulator://a?state={elsewhere}: unknown option "
                                 "'state' — emulator:// takes ")
    assert not elsewhere.exists() and not (path.parent / ".prc3cfg").exists()
    assert run_cli(capsys, "read", plant_with(path.parent, "emulator://a?line-speed=9600")).code == 0
    # a.json, its lock
    assert {p.name.partition(".")[0] for p in (path.parent / ".prc3cfg" / "emulators").iterdir()} == {"a"}


# -- the machine at the line: PRC3CFG_PORTS --------------------------------------------------------

#: The refusal of a bus whose port the machine does not list, after "bus NAME: port PORT".
NOT_LISTED = (" is not a line of this machine — PRC3CFG_PORTS, the machine's own list, names {listed}: name "
              "one of those in "
              "the plant file, or add the port to PRC3CFG_PORTS in the machine's configuration")


def test_where_the_machine_lists_its_ports_a_plant_file_opens_only_those(plant, capsys, monkeypatch):
    ports = {bus.name: bus.port for bus in plant.plant.buses}
    monkeypatch.setenv("PRC3CFG_PORTS", ports["booth-a"])
    refused = run_cli(capsys, "plan", plant.path)
    assert (refused.code, refused.out) == (1, "")
    assert refused.err == (f"error: {plant.path}: bus booth-b: port "
                           f"{ports['booth-b']}{NOT_LISTED.format(listed=ports['booth-a'])}\n")
    monkeypatch.setenv("PRC3CFG_PORTS", "")
    assert run_cli(capsys, "read", plant.path).err.endswith(NOT_LISTED.format(listed="none") + "\n")
    # another spelling of a listed line is that line (`line_keys`): 0.0.0.0 is the loopback a connection
    # reaches
    monkeypatch.setenv("PRC3CFG_PORTS",
                       f" {ports['booth-a']} ;{ports['booth-b'].replace('127.0.0.1', '0.0.0.0')}; ")
    planned = run_cli(capsys, "plan", plant.path, "--detailed-exitcode")
    assert planned.code == 2, planned


def test_the_emulator_inside_prc3cfg_is_no_port_of_the_machine(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("PRC3CFG_PORTS", "/dev/ttyUSB0")
    result = run_cli(capsys, "read", plant_with(tmp_path, "emulator://a"))
    assert result.code == 0, result


def test_a_machine_list_with_a_control_character_is_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("PRC3CFG_PORTS", "/dev/ttyUSB0\x1b[2K")
    result = run_cli(capsys, "read", plant_with(tmp_path, "/dev/ttyUSB1"))
    assert (result.code,
            result.err) == (1, "error: PRC3CFG_PORTS: port '/dev/ttyUSB0\\x1b[2K' holds a control "
                               "character — write "
                                            "the device path or URL as plain text\n")


def test_a_pull_requests_plant_file_cannot_make_the_runner_open_another_port(plant, tmp_path):
    """The recipe's plan job, across a real process: the runner lists its lines, the pull request's plant file
    names another port (a host of the runner's network) — refused before anything connects to it."""
    ports = {bus.name: bus.port for bus in plant.plant.buses}
    with socket.create_server(("127.0.0.1", 0)) as other:
        other.setblocking(False)
        elsewhere = f"socket://127.0.0.1:{other.getsockname()[1]}"
        pull_request = tmp_path / "pr" / "plant.yaml"
        pull_request.parent.mkdir()
        pull_request.write_text(plant.path.read_text().replace(ports["booth-b"], elsewhere))
        env = os.environ | {"PYTHONPATH": str(ROOT)}
        # and without the list, as a control
        for listed, connected in ((";".join(ports.values()), False), (None, True)):
            planning = [sys.executable, "-m", "prc3cfg", "plan", pull_request, "--detailed-exitcode"]
            ran = subprocess.run(planning, capture_output=True, text=True, timeout=120,
                                 env=env | ({"PRC3CFG_PORTS": listed} if listed else {}))
            assert ran.returncode == 1, ran
            if not connected:
                assert ran.stderr == (f"error: {pull_request}: bus booth-b: port "
                                      f"{elsewhere}{NOT_LISTED.format(listed=', '.join(ports.values()))}\n")
                with pytest.raises(BlockingIOError):
                    other.accept()  # the process has ended: a connection it made would be waiting here
            else:
                other.accept()[0].close()


# -- soak: random URL-ish ports --------------------------------------------------------------------

#: pyserial's handlers (`serial.protocol_handler_packages`: serial.urlhandler's protocol_*.py), prc3cfg's own,
#: others.
SCHEMES = [*sorted(path.stem.removeprefix("protocol_")
                   for path in Path(serial.urlhandler.__file__).parent.glob("protocol_*.py")),
           "emulator", "EMULATOR", "Socket", "file", "http", "xyz", ""]
PORTS = st.builds(
    "{}{}{}{}".format,
    st.sampled_from([f"{s}://" for s in SCHEMES] + ["", "/dev/", "/tmp/", "COM", "\\\\.\\COM", "./"]),
    st.sampled_from(["", "/dev/null", "/dev/ptmx", "ttyUSB0", "h:1", "127.0.0.1:7001", "a", "..", "../..",
                     "victim.txt", "1", "0"]),
    st.sampled_from(["", "?", "?file=victim.txt", "?class=PosixPollSerial", "?logging=debug",
                     "?line-speed=1200",
                     "?state=/tmp/x", "#x", "/x"]),
    st.text(alphabet="/?&=:.%\\ab", max_size=6),
)


@settings(max_examples=25)
@given(PORTS)
def test_a_few_random_ports_are_allowed_or_refused_in_one_line(tmp_path_factory, port):
    taken_or_refused(tmp_path_factory.mktemp("port"), port)


@pytest.mark.soak
@given(PORTS)
def test_random_ports_are_allowed_or_refused_in_one_line_and_write_nothing(tmp_path_factory, port):
    taken_or_refused(tmp_path_factory.mktemp("port"), port)


def taken_or_refused(folder: Path, port: str) -> None:
    """`validate` takes `port` only where the allowed set holds it, else refuses it in one line at
    file:line:col; `open_port` refuses it as well, before pyserial sees it; in the folder they ran in, no file
    appeared."""
    before = os.getcwd()
    os.chdir(folder)
    try:
        path = folder / "plant.yaml"
        path.write_text(PLANT.replace('"{port}"', "{port}").format(port=_yaml_string(port)))
        try:
            plant = load_plant(path)
        except PlantError as error:
            (problem,) = error.problems
            assert problem.startswith(f"{path}:{AT}: port ") and "\n" not in problem, problem
            with pytest.raises(UserError) as refused:
                open_port(port, LineSettings(parity="none"), bus="a")
            assert str(refused.value) == f"bus a: {problem.removeprefix(f'{path}:{AT}: ')}"
        else:
            assert _allowed(plant.buses[0].port), port
    finally:
        os.chdir(before)
    assert sorted(p.name for p in folder.iterdir()) == ["plant.yaml"]


def _yaml_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _allowed(port: str) -> bool:
    """The allowed set, said again the slow way (looser: no terminals left out)."""
    scheme, sep, rest = port.partition("://")
    if sep:
        return scheme.lower() in ("socket", "rfc2217") or (scheme == "emulator" and rest[:1] not in ("", "."))
    if re.fullmatch(r"(\\\\\.\\)?COM[1-9][0-9]*", port, re.IGNORECASE):
        return True
    return port.startswith("/dev/") and len(port) > 5 and ".." not in port.split("/")


@pytest.mark.soak
@pytest.mark.parametrize("scheme", SCHEMES)
def test_plan_across_a_real_process_refuses_every_handler_and_writes_nothing(tmp_path, scheme):
    """Each of pyserial's handlers (and others, and prc3cfg's own with no TCP port or a path for a name), as
    `plan` of a plant file naming it would open it: one line at the port, and no file."""
    folder = tmp_path / "repository"
    folder.mkdir()
    path = plant_with(folder, f"{scheme}:///dev/ptmx?file=victim.txt&class=PosixPollSerial&logging=debug")
    ran = subprocess.run([sys.executable, "-m", "prc3cfg", "plan", path.name], cwd=folder,
                         env=os.environ | {"PYTHONPATH": str(ROOT)},
                         capture_output=True, text=True, timeout=60)
    (line,) = ran.stderr.splitlines()
    assert (ran.returncode, ran.stdout) == (1, "") and line.startswith(f"error: {path.name}:{AT}: port "), ran
    assert sorted(p.name for p in folder.iterdir()) == ["plant.yaml"]
