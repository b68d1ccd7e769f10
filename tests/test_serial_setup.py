"""Serial setup that works the first time: a pseudo-terminal from `emulator serve --pty` is
scanned, imported and planned with the defaults; a hint is written in the syntax of the place it
is read; and `rfc2217://` through a real ser2net onto a device without modem lines (a pty) works
with `?ign_set_control`, as docs/plant-files.md's ser2net configuration says.
"""

from __future__ import annotations

import contextlib
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

from emulated import run_cli
from tools import needs, which

SER2NET = which("ser2net")


@contextlib.contextmanager
def served_pty(*options: str) -> Iterator[str]:
    """`prc3cfg emulator serve --pty` with `options`: the path of its pseudo-terminal."""
    process = subprocess.Popen([sys.executable, "-m", "prc3cfg", "emulator", "serve", "--pty", "--modules",
                                "1-3", *options],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = process.stdout.readline()
        assert line.startswith("pty: "), line + process.stderr.read()
        yield line.removeprefix("pty: ").strip()
    finally:
        process.terminate()
        process.wait()
        process.stdout.close()
        process.stderr.close()


def test_a_served_pty_is_scanned_and_imported_with_the_defaults(tmp_path, capsys):
    with served_pty() as pty:
        # scan's 0.2 s: at 0.1 s a module of the emulator process went unheard under load
        scanned = run_cli(capsys, "scan", "--port", pty)
        assert scanned.code == 0, scanned.err
        assert "3 modules answered" in scanned.out
        imported = run_cli(capsys, "import", "--port", pty, "--modules", "1-3", "--timeout", "0.2")
        assert imported.code == 0, imported.err
        assert "parity: none" in imported.out
        plant = tmp_path / "plant.yaml"
        written = run_cli(capsys, "import", "--port", pty, "--modules", "1-3", "--timeout", "0.2", "--out",
                          plant)
        assert (written.code == 0 and written.out == ""
                and plant.read_text(encoding="utf-8") == imported.out), written.err
        assert run_cli(capsys, "plan", plant, "--detailed-exitcode").code == 0


def test_a_parity_hint_is_written_as_the_place_it_is_read_says_it(tmp_path, capsys):
    with served_pty() as pty:
        scanned = run_cli(capsys, "scan", "--port", pty, "--parity", "even")
        assert scanned.code == 1
        assert scanned.err.endswith("a pseudo-terminal carries no parity: give --parity none\n"), scanned.err
        plant = tmp_path / "plant.yaml"
        plant.write_text(f"plant: p\nbuses:\n  - name: line\n    port: {pty}\n    parity: even\n    "
                         f"modules:\n      - {{address: 1, name: m1}}\n")
        said = (f"error: {plant}:5:13: port {pty} is a pseudo-terminal, which carries no parity (parity "
                "even) — set parity: none")
        for command in ("validate", "plan"):  # validate says what plan would refuse, where the file says it
            refused = run_cli(capsys, command, plant)
            assert refused.code == 1 and refused.problems == [said], refused.err
        # the default, even, is said at the port
        plant.write_text(plant.read_text().replace("    parity: even\n", ""))
        assert run_cli(capsys, "validate", plant).problems == [
            f"error: {plant}:4:5: port {pty} is a pseudo-terminal, which carries no parity (the default "
            "parity even) — set parity: none"]


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def listening(port: int) -> bool:
    """Whether something listens on 127.0.0.1:`port`, as the kernel's socket table says (no connection
    made)."""
    rows = Path("/proc/net/tcp").read_text().splitlines()[1:]
    return any(row.split()[1] == f"0100007F:{port:04X}" and row.split()[3] == "0A" for row in rows)


@needs("ser2net")
def test_rfc2217_through_ser2net_onto_a_device_without_modem_lines(tmp_path, capsys):
    """docs/plant-files.md's ser2net 4 configuration, its device a pty (no modem lines, like an RS-422
    adapter)."""
    port = free_port()
    with served_pty() as pty:
        config = tmp_path / "ser2net.yaml"
        config.write_text(f"connection: &prc3\n  accepter: telnet(rfc2217),tcp,127.0.0.1,{port}\n"
                          f"  connector: serialdev,{pty},9600n81,local\n  options:\n    "
                          "max-connections: 1\n")
        ser2net = subprocess.Popen([SER2NET, "-n", "-c", config], stdout=subprocess.PIPE,
                                   stderr=subprocess.STDOUT, text=True)
        try:
            while not listening(port):  # ser2net says nothing once it listens: the socket table does
                with contextlib.suppress(subprocess.TimeoutExpired):
                    ser2net.wait(0.01)
                assert ser2net.returncode is None, ser2net.stdout.read()
            plant = tmp_path / "plant.yaml"
            plant.write_text("plant: p\nbuses:\n  - name: line\n    port: "
                             f"rfc2217://127.0.0.1:{port}?ign_set_control\n"
                             "    parity: none\n    modules:\n      - {address: 1, name: m1}\n      - "
                             "{address: 2, name: m2}\n")
            planned = run_cli(capsys, "plan", plant, "--detailed-exitcode")
            assert planned.code == 0, planned.err
            assert "No changes" in planned.out
            plant.write_text(plant.read_text().replace("?ign_set_control", ""))
            refused = run_cli(capsys, "plan", plant)
            assert refused.code == 1
            assert refused.err.endswith("— a port without modem lines (ser2net's local) does not answer it: "
                                        "add ?ign_set_control to the rfc2217:// URL\n"), refused.err
        finally:
            ser2net.terminate()
            ser2net.wait()
            ser2net.stdout.close()
