"""The Windows tier (`pytest -m windows -n 0`): prc3cfg on the official Windows CPython 3.13 under
Wine 8, as `.ci/windows` sets it up (`PRC3CFG_WINE_CACHE`, else ~/.cache/prc3cfg-wine). This
tree's wheel is installed there at the start; each command then runs as a Windows user runs it —
`prc3cfg.exe` (pip's launcher), or `python.exe -m prc3cfg` where a signal must reach Python itself.

What runs: the README's first commands against the embedded emulator (plan, apply, plan = no
changes), validate, plan/apply/restore/adopt against emulators over TCP (one on Linux, one served by
the Windows Python), scan/doctor/read/plan/apply on a COM port (Wine's COMn, a link to the pty of a
Linux `emulator serve --pty`, registered in Wine's registry so that `prc3cfg ports` lists it), two
applies racing on one line, output redirected to a file by `cmd /c … > file`, and Ctrl-C as Wine
delivers it (SIGINT to the Unix process: Windows' CTRL_C_EVENT to the console handler). No command
may print a traceback.

Without `.ci/windows`'s set-up the tier is skipped (the README's fast tier never needs Wine);
with `PRC3CFG_WINDOWS_TIER=required` (`.ci/run`) it fails instead.

Wine's own quirks, none of them Windows': stdout redirected to a regular file from Linux is an
invalid handle (commands here write to pipes); ERROR_TIMEOUT at the end of a timed-out serial read
is absorbed by the Wine Python's sitecustomize (`.ci/windows`), not by prc3cfg; and once in a CI
run a command exited 1 having said nothing on either pipe — what the Windows Python does when its
standard handles are invalid (its fatal error has nowhere to go), and never what prc3cfg does with
working pipes (every failure says why; without streams it still does not die: test_cli_inputs). `run`
runs such a command once more, with a warning, so that Wine's fault never reads as prc3cfg's.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
import warnings
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CACHE = Path(os.environ.get("PRC3CFG_WINE_CACHE") or Path.home() / ".cache" / "prc3cfg-wine")
ENV_FILE = CACHE / "env"
COM = 12  # the COM port number the tier maps to an emulator's pty: two digits, which Windows names \\.\COM12

pytestmark = pytest.mark.windows


def win(path: Path | str) -> str:
    """A Linux path as the Windows programs under Wine name it (Wine's Z: is /)."""
    return "Z:" + str(path).replace("/", "\\")


def text(output: bytes) -> str:
    """A Windows program's output: UTF-8 whatever the console's code page, its lines ended by CRLF."""
    return output.decode("utf-8").replace("\r\n", "\n")


@dataclass
class Result:
    code: int
    out: str
    err: str

    def __str__(self) -> str:
        return f"exit {self.code}\n--- stdout\n{self.out}\n--- stderr\n{self.err}"


@dataclass
class Wine:
    """The Windows Python under Wine, ready to run prc3cfg."""

    wine: str
    prefix: Path
    python: str  # C:\python313\python.exe
    python_dir: Path
    wheels: Path

    @property
    def launcher(self) -> str:
        return self.python.rsplit("\\", 1)[0] + r"\Scripts\prc3cfg.exe"

    def env(self) -> dict[str, str]:
        """This process's environment for a Windows program: the tests' private lock and state
        folders as Windows paths, Wine quiet and headless, no pip settings of this machine."""
        env = {key: value for key, value in os.environ.items()
               if not key.startswith(("PIP_", "PYTHON", "VIRTUAL_ENV"))}
        for key in ("PRC3CFG_LOCK_DIR", "PRC3CFG_STATE_DIR", "PRC3CFG_UUCP_LOCK_DIR"):
            if key in env:
                env[key] = win(env[key])
        env.update(WINEPREFIX=str(self.prefix), WINEDEBUG="-all", DISPLAY="",
                   WINEDLLOVERRIDES="mscoree,mshtml=")
        return env

    def command(self, *args: str, module: bool = False, python: bool = False) -> list[str]:
        """prc3cfg as pip's launcher starts it; as `python.exe -m prc3cfg` (`module`); or python.exe given
        `args` (`python`)."""
        if python:
            return [self.wine, self.python, *args]
        return [self.wine, self.python, "-m", "prc3cfg", *args] if module else [self.wine, self.launcher,
                                                                                *args]

    def run(self, *args: str | Path, cwd: Path, timeout: float = 120, module: bool = False,
            python: bool = False) -> Result:
        """`prc3cfg ARGS` run to its end, its output through pipes; a traceback fails the test. Run
        once more, with a warning, where it failed without a word (the docstring's end: Wine's fault)."""
        for attempt in (1, 2):
            done = subprocess.run(self.command(*(str(a) for a in args), module=module, python=python),
                                  cwd=cwd, env=self.env(),
                                  stdin=subprocess.DEVNULL, capture_output=True, timeout=timeout)
            result = Result(done.returncode, text(done.stdout), text(done.stderr))
            if result.code == 0 or result.out or result.err or attempt == 2:
                break
            warnings.warn(f"`prc3cfg {' '.join(map(str, args))}` exited {result.code} without a word, as "
                          "the Windows Python "
                          "does when Wine gives it no standard handles: run once more",
                          stacklevel=2)
        assert "Traceback" not in result.out + result.err, result
        return result

    def start(self, *args: str | Path, cwd: Path, module: bool = False) -> subprocess.Popen[bytes]:
        return subprocess.Popen(self.command(*(str(a) for a in args), module=module), cwd=cwd, env=self.env(),
                                stdin=subprocess.DEVNULL,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE)

    def tool(self, *args: str, timeout: float = 60) -> subprocess.CompletedProcess[bytes]:
        """A Wine program (reg, cmd, …), its output through a pipe."""
        return subprocess.run([self.wine, *args], env=self.env(), stdin=subprocess.DEVNULL,
                              capture_output=True, timeout=timeout)

    def restart(self) -> None:
        """wineserver ended (and with it every Windows program): the next program starts Wine's
        services afresh, which read the registry's serial ports."""
        subprocess.run([str(Path(self.wine).parent / "wineserver64"), "-k"], env=self.env(),
                       capture_output=True, timeout=60)
        subprocess.run([str(Path(self.wine).parent / "wineserver64"), "-w"], env=self.env(),
                       capture_output=True, timeout=60)


def finished(process: subprocess.Popen[bytes], timeout: float = 120) -> Result:
    try:
        out, err = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        out, err = process.communicate()
        raise AssertionError(f"still running after {timeout:g} "
                             f"s\n{out.decode(errors='replace')}\n{err.decode(errors='replace')}") from None
    result = Result(process.returncode, text(out), text(err))
    assert "Traceback" not in result.out + result.err, result
    return result


@pytest.fixture(scope="session")
def wine(request) -> Wine:
    """The Windows Python `.ci/windows` set up, with this tree's prc3cfg installed by pip run from its
    wheel."""
    if not ENV_FILE.is_file():
        reason = f"the Windows tier needs .ci/windows run first (no {ENV_FILE})"
        if os.environ.get("PRC3CFG_WINDOWS_TIER") == "required":
            pytest.fail(reason)
        pytest.skip(reason)
    wheel = request.getfixturevalue("wheel")
    settings = dict(line.split("=", 1) for line in ENV_FILE.read_text().splitlines() if "=" in line)
    found = Wine(settings["WINE"], Path(settings["WINEPREFIX"]), settings["WINE_PYTHON"],
                 Path(settings["WINE_PYTHON_DIR"]),
                 Path(settings["WINE_WHEELS"]))
    (pip,) = sorted(found.wheels.glob("pip-*.whl"))[-1:]
    installed = found.tool(found.python, win(pip) + "\\pip", "--isolated", "install", "--no-index",
                           "--no-deps", "--force-reinstall",
                           "--no-warn-script-location", "--disable-pip-version-check", win(wheel),
                           timeout=300)
    assert installed.returncode == 0, installed.stdout.decode() + installed.stderr.decode()
    return found


@pytest.fixture
def demo(tmp_path) -> Path:
    """A checkout's plants/ and schemas/, as the README's commands find them."""
    for folder in ("plants", "schemas"):
        shutil.copytree(ROOT / folder, tmp_path / folder)
    return tmp_path


# -- the README's first commands, validate -------------------------------------------------


def test_the_readme_s_first_commands_plan_apply_and_plan_no_changes(wine, demo):
    first = wine.run("plan", "plants/demo-line.yaml", "--detailed-exitcode", cwd=demo)
    assert first.code == 2, first
    assert "Plan: 6 of 6 modules change" in first.out
    applied = wine.run("apply", "plants/demo-line.yaml", "--auto-approve", "--allow-axis-release", cwd=demo)
    assert applied.code == 0, applied
    assert "Apply complete: 6 modules written and verified." in applied.out
    # UTF-8 through a pipe, whatever the code page
    assert "✓ bus booth-a, module 1 (booth-a-left)" in applied.out
    again = wine.run("plan", "plants/demo-line.yaml", "--detailed-exitcode", cwd=demo)
    assert again.code == 0, again
    # what was read now: the system blocks, and the programs rolling evidence reads (test_rolling)
    assert re.search(r"No changes to what was read now \(the system blocks of 6 modules( and \d+ "
                     r"programs)?\) or to what prc3cfg last "
                     r"read or verified", again.out), again.out
    assert (demo / "plants" / ".prc3cfg" / "emulators" / "demo-a.json").is_file()


def test_validate_says_valid_and_points_at_a_mistake(wine, demo):
    valid = wine.run("validate", "plants/demo-line.yaml", cwd=demo)
    assert valid.code == 0, valid
    assert valid.out.strip() in ("plants/demo-line.yaml: valid (2 buses, 6 modules)",
                                 r"plants\demo-line.yaml: valid (2 buses, 6 modules)"), valid
    text = (demo / "plants" / "demo-line.yaml").read_text().replace("max_speed: 0.500", "max_speed: 9.500")
    (demo / "plants" / "wrong.yaml").write_text(text)
    invalid = wine.run("validate", "plants/wrong.yaml", cwd=demo)
    assert invalid.code == 1, invalid
    assert re.search(r"wrong\.yaml:\d+:\d+: .*max_speed", invalid.out + invalid.err), invalid


# -- the release's bundle for a Windows laptop, installed offline by hash ---------------------------


def test_the_release_bundle_installs_offline_by_hash_and_runs(wine, demo, tmp_path):
    """`.ci/release`'s zip, as INSTALL.txt says: pip with --no-index --require-hashes, nothing fetched,
    nothing built — into a folder of its own here (the embeddable CPython has no venv), then run."""
    made = subprocess.run([sys.executable, ROOT / ".ci" / "release", "--out", tmp_path / "dist", "--wheels",
                           wine.wheels],
                          capture_output=True, text=True, timeout=300)
    assert made.returncode == 0, made.stderr
    wheel, bundle = (Path(line) for line in made.stdout.split())
    with zipfile.ZipFile(bundle) as archive:
        archive.extractall(tmp_path / "unpacked")
    (folder,) = (tmp_path / "unpacked").iterdir()
    install = (folder / "INSTALL.txt").read_text(encoding="utf-8")
    assert "--no-index --find-links wheels --require-hashes -r requirements.txt" in install
    (pip,) = sorted(wine.wheels.glob("pip-*.whl"))[-1:]
    installed = wine.tool(wine.python, win(pip) + "\\pip", "--isolated", "install", "--no-index",
                          "--find-links", win(folder / "wheels"),
                          "--require-hashes", "-r", win(folder / "requirements.txt"), "--target",
                          win(tmp_path / "site"),
                          "--no-warn-script-location", "--disable-pip-version-check",
                          timeout=300)
    assert installed.returncode == 0, installed.stdout.decode() + installed.stderr.decode()
    assert {path.name.split("-")[0] for path in (tmp_path / "site").glob("*.dist-info")} >= {
        "prc3cfg",
        "pydantic_core",
        "typer",
        "colorama",
    }
    run = ("import runpy, sys; sys.path.insert(0, sys.argv.pop(1)); import prc3cfg; "
           "assert prc3cfg.__file__.startswith(sys.path[0]), prc3cfg.__file__; runpy.run_module('prc3cfg', "
           "run_name='__main__')")
    version = wine.run("-c", run, win(tmp_path / "site"), "--version", cwd=demo, python=True)
    assert version.out.strip() == f"prc3cfg {wheel.name.split('-')[1]}", version
    valid = wine.run("-c", run, win(tmp_path / "site"), "validate", "plants/demo-line.yaml", cwd=demo,
                     python=True)
    assert valid.code == 0 and "valid (2 buses, 6 modules)" in valid.out, valid


# -- over TCP: an emulator on Linux, one served by the Windows Python ----------------------


@contextlib.contextmanager
def linux_emulator(directory: Path, modules: str, *options: str) -> Iterator[int]:
    """`prc3cfg emulator serve` of this machine's Python; its TCP port."""
    log = directory / f"linux-{modules}.log"
    with log.open("w") as stderr:
        process = subprocess.Popen([sys.executable, "-m", "prc3cfg", "emulator", "serve", "--listen",
                                    "127.0.0.1:0", "--modules", modules,
                                    "--state", str(directory / f"linux-{modules}.json"), *options],
                                   stdout=subprocess.PIPE, stderr=stderr, text=True)
    try:
        banner = process.stdout.readline() if process.stdout else ""
        assert banner.startswith("listening on 127.0.0.1:"), banner + log.read_text()
        yield int(banner.split()[2].rsplit(":", 1)[1])
    finally:
        process.terminate()
        assert process.wait(timeout=30) == 0, log.read_text()


@contextlib.contextmanager
def windows_emulator(wine: Wine, directory: Path, modules: str) -> Iterator[int]:
    """`prc3cfg emulator serve` of the Windows Python; its TCP port. Stopped by Ctrl-C as Wine
    delivers it (SIGINT to the Unix process: CTRL_C_EVENT), which must end it with exit 0."""
    state = win(directory / f"windows-{modules}.json")
    serving = wine.command("emulator", "serve", "--listen", "127.0.0.1:0", "--modules", modules,
                           "--state", state, module=True)
    process = subprocess.Popen(serving, cwd=directory, env=wine.env(), stdin=subprocess.DEVNULL,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    lines: list[str] = []
    banner = process.stdout.readline().decode("utf-8") if process.stdout else ""
    drain = threading.Thread(target=lambda: lines.extend(line.decode("utf-8")
                                                         for line in process.stdout or ()), daemon=True)
    drain.start()
    try:
        assert banner.startswith("listening on 127.0.0.1:"), banner + (process.stdout.read().decode()
                                                                       if process.stdout else "")
        yield int(banner.split()[2].rsplit(":", 1)[1])
    finally:
        process.send_signal(signal.SIGINT)
        try:
            code = process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            raise
        drain.join(timeout=10)
        log = banner + "".join(lines)
        assert "Traceback" not in log, log
        assert code == 0, f"the Windows emulator ended with exit {code} on Ctrl-C\n{log}"


def socket_plant(demo: Path, port_a: int, port_b: int, *, newline: str = "\n") -> Path:
    text = (demo / "plants" / "demo-line.yaml").read_text()
    text = (text.replace("emulator://demo-a", f"socket://127.0.0.1:{port_a}")
            .replace("emulator://demo-b", f"socket://127.0.0.1:{port_b}"))
    path = demo / "plants" / "tcp-line.yaml"
    path.write_bytes(text.replace("\n", newline).encode())
    return path


def test_plan_apply_restore_and_adopt_over_tcp(wine, demo):
    with linux_emulator(demo, "1,2,5") as port_a, windows_emulator(wine, demo, "1,3,4") as port_b:
        plant = socket_plant(demo, port_a, port_b, newline="\r\n")  # as Git for Windows checks it out
        first = wine.run("plan", plant, "--detailed-exitcode", cwd=demo)
        assert first.code == 2, first
        applied = wine.run("apply", plant, "--auto-approve", "--allow-axis-release", cwd=demo)
        assert applied.code == 0, applied
        snapshot = re.search(r"^Snapshot of the modules before writing: (.+\.json)$", applied.out,
                             re.MULTILINE)
        assert snapshot, applied
        # a Windows path, as the user's system names it
        assert snapshot.group(1).startswith("Z:\\"), snapshot.group(1)
        assert wine.run("plan", plant, "--detailed-exitcode", cwd=demo).code == 0

        restored = wine.run("restore", snapshot.group(1), "--auto-approve", "--allow-axis-release", cwd=demo)
        assert restored.code == 0, restored
        assert wine.run("plan", plant, "--detailed-exitcode", cwd=demo).code == 2  # factory defaults again
        assert wine.run("apply", plant, "--auto-approve", "--allow-axis-release", cwd=demo).code == 0

        # The plant file says less than the modules hold (taught on the floor): adopt rewrites it.
        edited = plant.read_bytes().replace(b"upper_reversing_point: 2.200", b"upper_reversing_point: 2.150")
        assert edited != plant.read_bytes()
        plant.write_bytes(edited)
        check = wine.run("adopt", plant, "--check", cwd=demo)
        assert check.code == 2, check
        adopted = wine.run("adopt", plant, "--auto-approve", cwd=demo)
        assert adopted.code == 0, adopted
        rewritten = plant.read_bytes()
        assert b"upper_reversing_point: 2.200" in rewritten
        # its CRLF kept
        assert b"\r\r\n" not in rewritten and rewritten.count(b"\r\n") == rewritten.count(b"\n")
        assert wine.run("plan", plant, "--detailed-exitcode", cwd=demo).code == 0


def test_two_applies_on_one_line_one_is_refused_in_one_line(wine, demo):
    with linux_emulator(demo, "1,2,5", "--line-speed", "9600") as port_a, linux_emulator(demo, "1,3,4",
                                                                                         "--line-speed",
                                                                                         "9600") as port_b:
        plant = socket_plant(demo, port_a, port_b)
        assert wine.run("validate", plant, cwd=demo).code == 0  # Wine's services running: both start alike
        first = wine.start("apply", plant, "--auto-approve", "--allow-axis-release", "--full-read", cwd=demo)
        second = wine.start("apply", plant, "--auto-approve", "--allow-axis-release", "--full-read", cwd=demo)
        results = [finished(first), finished(second)]
    codes = sorted(result.code for result in results)
    assert codes[0] == 0 and codes[1] != 0, "\n".join(map(str, results))
    refused = next(result for result in results if result.code != 0)
    problems = [line for line in refused.err.splitlines() if not line.startswith("note: ")]
    assert len(problems) == 1 and "the line is locked by" in problems[0], refused
    assert "Apply complete" in next(result for result in results if result.code == 0).out


# -- a COM port: Wine's COMn in front of a Linux emulator's pty -----------------------------


@pytest.fixture
def com_port(wine, tmp_path) -> Iterator[str]:
    """COM12: a Linux `emulator serve --pty` (modules 1, 2, 5) behind Wine's COM12, registered in
    HKLM\\Software\\Wine\\Ports so that Wine's services list it (HARDWARE\\DEVICEMAP\\SERIALCOMM)."""
    log = tmp_path / "pty.log"
    with log.open("w") as stderr:
        process = subprocess.Popen([sys.executable, "-m", "prc3cfg", "emulator", "serve", "--pty",
                                    "--modules", "1,2,5",
                                    "--state", str(tmp_path / "pty.json")], stdout=subprocess.PIPE,
                                   stderr=stderr, text=True)
    try:
        banner = process.stdout.readline() if process.stdout else ""
        assert banner.startswith("pty: /dev/"), banner + log.read_text()
        pty = banner.split(": ", 1)[1].strip()
        added = wine.tool("reg", "add", r"HKLM\Software\Wine\Ports", "/v", f"COM{COM}", "/d", pty, "/f")
        assert added.returncode == 0, added
        wine.restart()
        link = wine.prefix / "dosdevices" / f"com{COM}"
        # Wine's services make it at start; made here if not
        if os.path.realpath(link) != os.path.realpath(pty):
            link.unlink(missing_ok=True)
            link.symlink_to(pty)
        yield f"COM{COM}"
    finally:
        wine.tool("reg", "delete", r"HKLM\Software\Wine\Ports", "/v", f"COM{COM}", "/f")
        (wine.prefix / "dosdevices" / f"com{COM}").unlink(missing_ok=True)
        process.terminate()
        assert process.wait(timeout=30) == 0, log.read_text()


def com_plant(demo: Path, port: str) -> Path:
    """Booth A of the demo plant alone, on `port`, without parity (a pty carries none)."""
    text = (demo / "plants" / "demo-line.yaml").read_text()
    text = text[: text.index("  - name: booth-b")]
    text = text.replace("port: emulator://demo-a", f"port: {port}\n    parity: none")
    path = demo / "plants" / "com-line.yaml"
    path.write_text(text)
    return path


def test_ports_scan_read_plan_and_apply_on_a_com_port(wine, demo, com_port):
    listed = wine.run("ports", "--json", cwd=demo)
    assert listed.code == 0, listed
    assert com_port in [port["device"] for port in json.loads(listed.out)], listed

    refused = wine.run("scan", "--port", com_port, cwd=demo)  # even parity, which the pty behind it drops
    assert refused.code == 1, refused
    assert refused.err.strip().endswith("give --parity none"), refused
    scanned = wine.run("scan", "--port", com_port, "--parity", "none", cwd=demo)
    assert scanned.code == 0, scanned
    assert f"3 modules answered on {com_port}." in scanned.out

    diagnosed = wine.run("doctor", "--port", com_port, "--parity", "none", "--exchanges", "3", cwd=demo)
    assert diagnosed.code == 0, diagnosed
    assert "    parity: none" in diagnosed.out and "    framing: crc16" in diagnosed.out, diagnosed

    plant = com_plant(demo, com_port.lower())  # any spelling of the port
    read = wine.run("read", plant, "--json", cwd=demo)
    assert read.code == 0, read
    assert wine.run("plan", plant, "--detailed-exitcode", cwd=demo).code == 2
    applied = wine.run("apply", plant, "--auto-approve", "--allow-axis-release", cwd=demo)
    assert applied.code == 0, applied
    assert "Apply complete: 3 modules written and verified." in applied.out
    assert wine.run("plan", plant, "--detailed-exitcode", cwd=demo).code == 0


# -- output to a file, Ctrl-C --------------------------------------------------------------


def test_emulator_serve_pty_is_refused_in_one_line(wine, demo):
    refused = wine.run("emulator", "serve", "--pty", cwd=demo)
    assert refused.code == 1, refused
    assert refused.err.strip().splitlines() == ["error: --pty: Windows has no pseudo-terminals — serve over "
                                                "TCP (--listen HOST:PORT) and use socket://HOST:PORT"]


def test_setup_machine_speaks_windows(wine, demo):
    """No group on Windows (the folder's rights share it): --group is refused in one line, not ignored."""
    refused = wine.run("setup-machine", "--group", "dialout", cwd=demo)
    assert refused.code == 1, refused
    assert refused.err.strip().splitlines() == [
        "error: --group dialout: this system shares the folder by its rights, not by a group — run "
        "setup-machine without --group; "
        "every user of the machine may then keep records there, each file its maker's"]


def test_output_redirected_to_a_file_is_whole_utf_8(wine, demo):
    """`cmd /c prc3cfg … > file`: Windows' own redirection (Wine cannot hand a Linux-side file to
    a Windows program as its stdout)."""
    schema, plan = demo / "plant.schema.json", demo / "plan.txt"
    plant = win(demo / "plants" / "demo-line.yaml")
    done = wine.tool("cmd", "/c",
                     f"{wine.launcher} schema > {win(schema)} && {wine.launcher} plan {plant} > {win(plan)}")
    assert done.returncode == 0, done
    assert json.loads(schema.read_text(encoding="utf-8"))["title"]
    text = plan.read_text(encoding="utf-8")
    assert "⚠ RELEASES AXES" in text and "Plan: 6 of 6 modules change" in text, text
    assert "Traceback" not in done.stdout.decode(errors="replace") + done.stderr.decode(errors="replace")


def test_ctrl_c_stops_an_apply_after_the_exchange_in_flight_with_exit_130(wine, demo):
    """Ctrl-C as Wine delivers it: SIGINT to the Unix process of python.exe becomes CTRL_C_EVENT
    for its console handler (pip's prc3cfg.exe launcher would take it for itself)."""
    with linux_emulator(demo, "1,2,5", "--line-speed", "1200") as port_a, linux_emulator(demo, "1,3,4",
                                                                                         "--line-speed",
                                                                                         "1200") as port_b:
        plant = socket_plant(demo, port_a, port_b)
        process = wine.start("apply", plant, "--auto-approve", "--allow-axis-release", "--full-read",
                             cwd=demo, module=True)
        journal = demo / "plants" / ".prc3cfg" / "journal"
        deadline = time.monotonic() + 60
        # reading back: some 30 s at 1200 baud
        while not any('"exchange"' in path.read_text() for path in journal.glob("*.jsonl")):
            assert process.poll() is None and time.monotonic() < deadline, finished(process)
            time.sleep(0.2)  # polling the journal the apply writes: the wait is on what it traced
        process.send_signal(signal.SIGINT)
        result = finished(process, timeout=60)
        (written,) = journal.glob("*.jsonl")
        events = [json.loads(line)["event"] for line in written.read_text().splitlines() if line.strip()]
    assert result.code == 130, result
    assert result.err.splitlines()[-1] == "error: interrupted", result
    # stopped within the read-back, after the exchange in flight — not once its lines were done (Windows runs
    # no handler inside a wait without a time-out: the read-back of all 6 modules, 6 × 17 exchanges, went on
    # to its end)
    assert 0 < events.count("exchange") < 6 * 17 and "apply" not in events, events


def test_a_plan_made_on_linux_applies_from_a_crlf_checkout(wine, demo):
    """CI plans on Linux; the person at the line applies that plan file from a Git for Windows checkout
    (CRLF)."""
    with linux_emulator(demo, "1,2,5") as port_a, linux_emulator(demo, "1,3,4") as port_b:
        plant = socket_plant(demo, port_a, port_b)
        planned = subprocess.run([sys.executable, "-m", "prc3cfg", "plan", str(plant.relative_to(demo)),
                                  "--out", "plan.json"], cwd=demo,
                                 capture_output=True, text=True, timeout=120)
        assert planned.returncode == 0, planned.stderr
        plant.write_bytes(plant.read_bytes().replace(b"\n", b"\r\n"))
        applied = wine.run("apply", plant.relative_to(demo), "--plan", "plan.json", "--auto-approve",
                           "--allow-axis-release", cwd=demo)
        assert len(applied.err.splitlines()) <= 1, applied  # at worst refused in one line
        assert applied.code == 0, applied


# -- the default folders, under a user folder with a space and non-ASCII letters; the records commands
# --------


def test_default_folders_a_non_ascii_checkout_and_the_records_commands(wine, demo):
    """No PRC3CFG_STATE_DIR or PRC3CFG_LOCK_DIR, as on a laptop: the line's record goes to the user's
    %LOCALAPPDATA%\\prc3cfg and the line locks to %ProgramData%\\prc3cfg\\locks (Wine's, in its prefix); the
    plant repository is checked out under "Jürgen Müller\\plant repo", and `records list`, `verify` and
    `prune` read what the apply kept beside it."""
    checkout = demo / "Jürgen Müller" / "plant repo"
    for folder in ("plants", "schemas"):
        shutil.copytree(demo / folder, checkout / folder)
    env = {key: value for key, value in wine.env().items()
           if key not in ("PRC3CFG_STATE_DIR", "PRC3CFG_LOCK_DIR")}
    records = wine.prefix / "drive_c" / "users"
    before = set(records.glob("*/AppData/Local/prc3cfg/lines/*.json"))

    def run(*args: str) -> Result:
        done = subprocess.run(wine.command(*args), cwd=checkout, env=env, stdin=subprocess.DEVNULL,
                              capture_output=True, timeout=180)
        result = Result(done.returncode, text(done.stdout), text(done.stderr))
        assert "Traceback" not in result.out + result.err, result
        return result

    made: set[Path] = set()
    try:
        applied = run("apply", "plants/demo-line.yaml", "--auto-approve", "--allow-axis-release")
        made = set(records.glob("*/AppData/Local/prc3cfg/lines/*.json")) - before
        assert applied.code == 0 and "Apply complete: 6 modules written and verified." in applied.out, applied
        assert len(made) == 2, applied  # each line's record, in the user's own folder
        assert list((wine.prefix / "drive_c" / "ProgramData" / "prc3cfg" / "locks").glob("*.lock")), applied
        assert list((checkout / "plants" / ".prc3cfg" / "journal").glob("*.jsonl")), applied
        assert run("plan", "plants/demo-line.yaml", "--detailed-exitcode").code == 0
        listed = run("records", "list", "plants/demo-line.yaml", "--json")
        assert listed.code == 0 and [r["command"] for r in json.loads(listed.out)] == ["apply"], listed
        verified = run("records", "verify", "plants/demo-line.yaml")
        assert verified.code == 0 and verified.out.startswith("Records verified:"), verified
        pruned = run("records", "prune", "plants/demo-line.yaml", "--keep", "1", "--dry-run")
        assert pruned.code == 0, pruned
    finally:  # the prefix is cached from run to run
        for path in made:
            path.unlink()
