"""Every input a person can get wrong or an attacker can craft, on the command line: one line, the
right exit code, and no time spent on the line first.

Tables of cases per class: the command line itself (usage errors, exit 64), output paths,
plan files and other JSON inputs. A case's plant points at a port where nothing listens,
so an error about the line would mean the input was not checked first. A fuzz test mangles
plan files. Run in-process with the real CLI, and as processes where the process matters
(a closed stdout pipe).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from emulated import DEMO, emulated_plant, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from prc3cfg import __version__

EXIT_USAGE = 64


@pytest.fixture
def nowhere(tmp_path) -> Path:
    """The demo plant on a port where nothing listens: any time spent on the line is an error there."""
    plant = tmp_path / "plant.yaml"
    plant.write_text(DEMO.read_text().replace("emulator://demo-a", "socket://127.0.0.1:9")
                     .replace("emulator://demo-b", "socket://127.0.0.1:19"))
    return plant


# -- the command line ------------------------------------------------------------------------

#: A table: one case a row (ruff's E501 is off for this file, pyproject.toml).
USAGE = {
    "apply without a plant": (["apply"], "error: prc3cfg apply: name the plant file, or a plan file with --plan — see prc3cfg apply --help"),
    "plan without a plant": (["plan"], "error: prc3cfg plan: Missing argument 'PLANT' — see prc3cfg plan --help"),
    "an unknown command": (["nosuch"], "error: prc3cfg: No such command 'nosuch' — see prc3cfg --help"),
    "an unknown option": (["plan", "p.yaml", "--outt", "x"], "error: prc3cfg plan: No such option: --outt (Possible options: --out, --plot) — see prc3cfg plan --help"),
    "negative retries": (["plan", "p.yaml", "--retries", "-1"], "error: prc3cfg plan: Invalid value for '--retries': must be 0 or more — see prc3cfg plan --help"),
    "a negative lock time-out": (["apply", "p.yaml", "--lock-timeout", "-5"], "error: prc3cfg apply: Invalid value for '--lock-timeout': '-5' is not a time — write seconds (30, 0.5) or with a unit: 500ms, 5s, 2m, 1h — see prc3cfg apply --help"),
    "a lock time-out in parsecs": (["apply", "p.yaml", "--lock-timeout", "5pc"], "error: prc3cfg apply: Invalid value for '--lock-timeout': '5pc' is not a time — write seconds (30, 0.5) or with a unit: 500ms, 5s, 2m, 1h — see prc3cfg apply --help"),
    "a reply time-out of two hours": (["scan", "--port", "socket://127.0.0.1:9", "--timeout", "2h"], "error: prc3cfg scan: Invalid value for '--timeout': 2h is more than 1h — see prc3cfg scan --help"),
    "a zvz below the open driver's": (["import", "--port", "socket://127.0.0.1:9", "--zvz", "1ms"], "error: prc3cfg import: Invalid value for '--zvz': 1ms is less than 4ms — see prc3cfg import --help"),
    "retries as text": (["read", "p.yaml", "--retries", "many"], "error: prc3cfg read: Invalid value for '--retries': must be a whole number — see prc3cfg read --help"),
    "scan's baud 0": (["scan", "--port", "socket://127.0.0.1:9", "--baud", "0"], "error: prc3cfg scan: Invalid value for '--baud': must be 1 or more — see prc3cfg scan --help"),
    "scan's parity": (["scan", "--port", "socket://127.0.0.1:9", "--parity", "x"], "error: prc3cfg scan: Invalid value for '--parity': 'x' is not one of none, odd, even — see prc3cfg scan --help"),
    "import's framing": (["import", "--port", "socket://127.0.0.1:9", "--framing", "modbus"], "error: prc3cfg import: Invalid value for '--framing': 'modbus' is not one of crc16, open-driver, stx — see prc3cfg import --help"),
    "import's empty address": (["import", "--port", "socket://127.0.0.1:9", "--modules", "1,,2"], "error: prc3cfg import: Invalid value for '--modules': '1,,2' has an empty entry — write addresses and ranges between commas, e.g. 1,3-5 — see prc3cfg import --help"),
    "scan's 7 data bits": (["scan", "--port", "socket://127.0.0.1:9", "--data-bits", "7"], "error: prc3cfg scan: Invalid value for '--data-bits': 7 data bits cannot carry a PRC 3 frame — its frames are binary and need 8 data bits: give 8 or leave the option out — see prc3cfg scan --help"),
    "import's 5 data bits": (["import", "--port", "socket://127.0.0.1:9", "--data-bits", "5"], "error: prc3cfg import: Invalid value for '--data-bits': 5 data bits cannot carry a PRC 3 frame — its frames are binary and need 8 data bits: give 8 or leave the option out — see prc3cfg import --help"),
    "the emulator's 7 data bits": (["emulator", "serve", "--listen", "127.0.0.1:9", "--data-bits", "7"], "error: prc3cfg emulator serve: Invalid value for '--data-bits': 7 data bits cannot carry a PRC 3 frame — its frames are binary and need 8 data bits: give 8 or leave the option out — see prc3cfg emulator serve --help"),
    "scan's stop bits": (["scan", "--port", "socket://127.0.0.1:9", "--stop-bits", "3"], "error: prc3cfg scan: Invalid value for '--stop-bits': 3.0 is not one of 1, 1.5, 2 — see prc3cfg scan --help"),
    "refresh-only with --plot": (["plan", "p.yaml", "--refresh-only", "--plot", "p.svg", "--module", "m"], "error: prc3cfg plan: --refresh-only reports drift and makes no plan — leave out --plot — see prc3cfg plan --help"),
    "verify not a choice": (["apply", "p.yaml", "--verify", "bogus"], "error: prc3cfg apply: Invalid value for '--verify': 'bogus' is not one of 'floor', 'full' — see prc3cfg apply --help"),
    "completion for a named shell": (["--install-completion", "zsh"], "error: prc3cfg: --install-completion takes no shell name (zsh): it is for the shell it is run in — run prc3cfg --install-completion from that shell"),
    "refresh-only with --previous": (["plan", "p.yaml", "--refresh-only", "--previous", "old.yaml"], "error: prc3cfg plan: --refresh-only reports drift and makes no plan — leave out --previous — see prc3cfg plan --help"),
    "terraform's -out=": (["plan", "p.yaml", "-out=plan.json"], "error: -out=plan.json: prc3cfg options take two dashes — did you mean --out plan.json?"),
    "terraform's -auto-approve": (["apply", "p.yaml", "-auto-approve"], "error: -auto-approve: prc3cfg options take two dashes — did you mean --auto-approve?"),
    "terraform's -lock-timeout=": (["apply", "p.yaml", "-lock-timeout=10"], "error: -lock-timeout=10: prc3cfg options take two dashes — did you mean --lock-timeout 10?"),
    "terraform's -target=": (["plan", "p.yaml", "-target=booth-a-top"], "error: -target=booth-a-top: prc3cfg names a module with --module — did you mean --module booth-a-top?"),
    "terraform's -target NAME": (["apply", "p.yaml", "-target", "booth-a-top"], "error: -target booth-a-top: prc3cfg names a module with --module — did you mean --module booth-a-top?"),
    "terraform's -out FILE": (["plan", "p.yaml", "-out", "plan.json"], "error: -out plan.json: prc3cfg options take two dashes — did you mean --out plan.json?"),
    "terraform's apply PLAN": (["apply", "plan.json"], "error: prc3cfg apply: plan.json is a plan file — did you mean prc3cfg apply PLANT --plan plan.json? — see prc3cfg apply --help"),
}


@pytest.mark.parametrize("case", USAGE, ids=list(USAGE))
def test_every_usage_error_is_one_line_and_exits_64(capsys, case):
    args, line = USAGE[case]
    result = run_cli(capsys, *args)
    assert (result.code, result.err, result.out) == (EXIT_USAGE, line + "\n", "")


@pytest.mark.parametrize("group", [[], ["emulator"], ["link"]])
def test_no_command_shows_what_there_is_to_run_and_exits_64(capsys, group):
    result = run_cli(capsys, *group)
    assert result.code == EXIT_USAGE and result.err == ""
    assert (result.out.startswith(f"Usage: prc3cfg {' '.join(group)}".rstrip() + " [OPTIONS] COMMAND")
            and "Commands" in result.out)


PORTS = {
    "no TCP port": ("socket://127.0.0.1",
                    "error: port 'socket://127.0.0.1' has no TCP port 1..65535 — write socket://HOST:PORT, "
                    "e.g. socket://127.0.0.1:7001"),
    "a broken IPv6 host": ("socket://[::1",
                           "error: port 'socket://[::1' has no TCP port 1..65535 — write "
                           "socket://HOST:PORT, e.g. socket://127.0.0.1:7001"),
    "a TCP port too high": ("rfc2217://127.0.0.1:99999",
                            "error: port 'rfc2217://127.0.0.1:99999' has no TCP port 1..65535 — write "
                            "rfc2217://HOST:PORT, e.g. rfc2217://127.0.0.1:7001"),
    "a NUL": ("/dev/ttyS0\x00x",
              "error: port '/dev/ttyS0\\x00x' holds a control character — write the device path or URL as "
              "plain text"),
    "an emulator of a plant file": ("emulator://demo-a",
                                    "error: port emulator://demo-a is a plant file's emulator (its state is "
                                    "kept beside the plant file) — for a bus without a plant file run "
                                    "prc3cfg emulator serve and give its socket://HOST:PORT"),
}


@pytest.mark.parametrize("command", ["scan", "import"])
@pytest.mark.parametrize("case", PORTS, ids=list(PORTS))
def test_a_bad_port_on_the_command_line_is_one_line(capsys, command, case):
    port, line = PORTS[case]
    result = run_cli(capsys, command, "--port", port)
    assert (result.code, result.err, result.out) == (1, line + "\n", "")


def test_a_control_character_in_a_plant_port_is_refused_by_validate(tmp_path, capsys):
    plant = tmp_path / "plant.yaml"
    plant.write_text(DEMO.read_text().replace("emulator://demo-a", '"/dev/ttyS0\\0x"'))
    result = run_cli(capsys, "validate", plant)
    assert result.code == 1 and result.err.count("\n") == 1
    assert "holds a control character — write the device path or URL as plain text" in result.err


def test_version(capsys):
    result = run_cli(capsys, "--version")
    assert (result.code, result.out) == (0, f"prc3cfg {__version__}\n")


def test_a_usage_error_under_detailed_exitcode_is_never_changes(capsys):
    assert run_cli(capsys, "plan", "p.yaml", "--detailed-exitcode", "--no-such").code == EXIT_USAGE


# -- output paths: checked before any time on the line -------------------------------------------


def outputs(tmp_path: Path, plant: Path) -> dict[str, tuple[list[str], str]]:
    (tmp_path / "folder").mkdir()
    return {
        "--out in a missing folder": (
            ["plan", plant, "--out", tmp_path / "missing" / "plan.json"],
            f"error: --out {tmp_path}/missing/plan.json: the folder {tmp_path}/missing does not exist — "
            "create it, or name a file in an existing folder",
        ),
        "--out a directory": (["plan", plant, "--out", tmp_path / "folder"],
                              f"error: --out {tmp_path}/folder is a directory — name a file in it"),
        "--out /dev/full": (["plan", plant, "--out", "/dev/full"],
                            "error: --out /dev/full: no space left on device — name a file on a disk "
                            "with space"),
        "--out the plant file": (["plan", plant, "--out", plant],
                                 f"error: --out {plant} is the plant file itself — name another file"),
        "--trace /dev/full": (["read", plant, "--trace", "/dev/full"],
                              "error: --trace /dev/full: no space left on device — name a file on a disk "
                              "with space"),
        "--trace in a missing folder": (
            ["apply", plant, "--trace", tmp_path / "missing" / "t.txt"],
            f"error: --trace {tmp_path}/missing/t.txt: the folder {tmp_path}/missing does not exist — "
            "create it, or name a file in an existing folder",
        ),
        "--trace the plant file": (["plan", plant, "--trace", plant],
                                   f"error: --trace {plant} is the plant file itself — name another file"),
    }


@pytest.mark.parametrize("case", ["--out in a missing folder", "--out a directory", "--out /dev/full",
                                  "--out the plant file",
                                  "--trace /dev/full", "--trace in a "
                                                       "missing folder", "--trace the plant file"])
def test_an_output_that_cannot_be_written_is_one_line_before_the_line_is_touched(nowhere, tmp_path, capsys,
                                                                                 case):
    args, line = outputs(tmp_path, nowhere)[case]
    before = nowhere.read_bytes()
    result = run_cli(capsys, *args)
    assert (result.code, result.err) == (1, line + "\n")
    assert nowhere.read_bytes() == before
    assert not (tmp_path / ".prc3cfg" / "journal").exists()


def test_a_plan_file_to_a_device_is_written_as_it_is(tmp_path, capsys):
    with emulated_plant(tmp_path) as plant:
        result = run_cli(capsys, "plan", plant.path, "--out", "/dev/null")
    assert result.code == 0, result.err


@pytest.mark.parametrize("command", ["plan", "read"])
def test_a_closed_stdout_pipe_ends_quietly_as_git_does(tmp_path, capsys, command):
    """`prc3cfg read … | head -1`: no traceback, no message, exit 141 (128 + SIGPIPE), as git and
    coreutils."""
    with emulated_plant(tmp_path) as plant:
        saved = tmp_path / "images.json"
        saved.write_text(run_cli(capsys, "read", plant.path, "--json").out)
        env = {**os.environ, "PRC3CFG_LOCK_DIR": str(tmp_path / "locks")}
        gone, stdout = os.pipe()
        os.close(gone)  # the reader has gone, as `| head` does once it has its lines
        args = ["plan", plant.path, "--actual", saved] if command == "plan" else ["read", plant.path]
        done = subprocess.run([sys.executable, "-m", "prc3cfg", *args], stdout=stdout, stderr=subprocess.PIPE,
                              text=True, env=env)
        os.close(stdout)
    assert (done.returncode, done.stderr) == (141, "")


@pytest.mark.skipif(sys.platform == "win32", reason="closes descriptors with a POSIX shell")
def test_a_command_started_without_standard_streams_still_exits_with_its_outcome(tmp_path):
    """pythonw, a service, `>&- 2>&-`: Python's sys.stdout and sys.stderr are None; the exit status
    still says valid or not (before, the first word ended every command in exit 1, said to nobody)."""
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text(DEMO.read_text().replace("max_speed: 0.500", "max_speed: 9.500", 1))
    codes = [subprocess.run(["sh", "-c", 'exec "$0" -m prc3cfg validate "$1" >&- 2>&-', sys.executable,
                             str(path)]).returncode
             for path in (DEMO, wrong)]
    assert codes == [0, 1]


# -- plan files and other JSON inputs ------------------------------------------------------------


def json_inputs(tmp_path: Path, plant: Path) -> dict[str, tuple[list[str], str]]:
    def write(name: str, text: str | bytes) -> Path:
        path = tmp_path / name
        path.write_bytes(text if isinstance(text, bytes) else text.encode())
        return path

    huge = tmp_path / "huge.json"
    with huge.open("wb") as handle:
        handle.truncate(300 * 2**20)  # 300 MB, sparse
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    plan = "the plan file prc3cfg plan --out wrote"
    return {
        "a truncated plan": (
            ["apply", plant, "--plan", write("cut.json", '{"format": "prc3cfg-plan/1", "buses": [')],
            f"error: {tmp_path}/cut.json:1:40: not valid JSON (Expecting value) — make the plan again",
        ),
        "a plan nested 10,000 deep": (
            ["apply", plant, "--plan", write("deep.json", "[" * 10_000 + "]" * 10_000)],
            (
                f"error: {tmp_path}/deep.json: nested too deeply for any file prc3cfg "
                "writes — make the plan again"
            ),
        ),
        # plan_file.PLAN_LIMIT
        "a 300 MB plan": (
            ["apply", plant, "--plan", huge],
            f"error: {huge}: larger than 32 MiB — name {plan}",
        ),
        "a plan that is a FIFO": (
            ["apply", plant, "--plan", fifo],
            f"error: {fifo}: is a named pipe (FIFO), not a file — name {plan}",
        ),
        "a plan that is a directory": (
            ["apply", plant, "--plan", tmp_path],
            f"error: {tmp_path}: is a directory — name {plan}",
        ),
        "a missing plan": (
            ["apply", plant, "--plan", tmp_path / "none.json"],
            f"error: {tmp_path}/none.json: no such file — name {plan}",
        ),
        "a plan that is a list": (
            ["apply", plant, "--plan", write("list.json", "[]")],
            f'error: {tmp_path}/list.json: not a plan file — expected "format": "prc3cfg-plan/1"',
        ),
        "a plan without its plant": (
            ["apply", "--plan", write("alone.json", '{"format": "prc3cfg-plan/1"}')],
            (
                f"error: {tmp_path}/alone.json: the plant file it was made from is not "
                "at None — name it: "
                f"prc3cfg apply PLANT --plan {tmp_path}/alone.json"
            ),
        ),
        "saved images that are not JSON": (
            ["plan", plant, "--actual", write("images.json", "\x00\x01")],
            (
                f"error: {tmp_path}/images.json:1:1: not valid JSON (Expecting "
                "value) — save the images again with prc3cfg read --json"
            ),
        ),
        "saved images with text for numbers": (
            [
                "plan",
                plant,
                "--actual",
                write("texts.json", json.dumps([{"address": "1", "system": {}, "programs": []}])),
            ],
            (
                f"error: {tmp_path}/texts.json: not a list of module images as `prc3cfg read --json` writes "
                '([0].address is the text "1", where a whole number belongs) '
                "— save the images again with prc3cfg read --json"
            ),
        ),
        "a snapshot that is a directory": (
            ["restore", tmp_path],
            f"error: {tmp_path}: is a directory — name a file under .prc3cfg/snapshots/",
        ),
    }


JSON_CASES = ["a truncated plan", "a plan nested 10,000 deep", "a 300 MB plan", "a plan that is a FIFO",
              "a plan that is a directory",
              "a missing plan", "a plan that is a list", "a plan without its plant",
              "saved images that are not JSON",
              "saved images with text for numbers", "a snapshot that is a directory"]


@pytest.mark.parametrize("case", JSON_CASES)
def test_a_bad_json_input_is_one_line_before_the_line_is_touched(nowhere, tmp_path, capsys, case):
    args, line = json_inputs(tmp_path, nowhere)[case]
    result = run_cli(capsys, *args)
    assert (result.code, result.err) == (1, line + "\n")
    assert not (tmp_path / ".prc3cfg" / "journal").exists()


# -- fuzzed plan files -----------------------------------------------------------------------------

DEBRIS = ['"', "{", "}", "[", "]", ",", ":", "0", "-1", "1e999", "null", "true", '"2"', "2.7", "\\u0000",
          "9" * 40, "[" * 300]


@pytest.fixture(scope="module")
def fuzz_plant(tmp_path_factory):
    directory = tmp_path_factory.mktemp("fuzz")
    with emulated_plant(directory) as plant:
        yield plant


@settings(max_examples=60, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_mangled_plan_file_is_refused_in_one_line(fuzz_plant, capsys, tmp_path, data, monkeypatch):
    monkeypatch.setenv("PRC3CFG_LOCK_DIR", str(fuzz_plant.path.parent / "locks"))
    made = fuzz_plant.path.parent / "made.json"
    if not made.exists():
        assert run_cli(capsys, "plan", fuzz_plant.path, "--out", made).code == 0
    text = made.read_text()
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(0, len(text)))
        cut = data.draw(st.integers(0, 12))
        text = text[:at] + data.draw(st.sampled_from(DEBRIS)) + text[at + cut :]
    mangled = fuzz_plant.path.parent / "mangled.json"
    mangled.write_text(text)
    before = fuzz_plant.images()
    result = run_cli(capsys, "apply", fuzz_plant.path, "--plan", mangled, "--auto-approve",
                     "--allow-axis-release")
    if text == made.read_text():
        return
    assert result.code == 1, result.out
    assert len(result.problems) == 1 and result.problems[0].startswith("error: "), result.err
    assert fuzz_plant.images() == before
