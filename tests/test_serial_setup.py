"""Serial setup that works the first time: a pseudo-terminal from `emulator serve --pty` is
scanned, imported and planned with the defaults; a hint is written in the syntax of the place it
is read; and `rfc2217://` through a real ser2net onto a device without modem lines (a pty) works
with `?ign_set_control`, as docs/plant-files.md's ser2net configuration says.
"""

from __future__ import annotations

import contextlib
import shutil
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from emulated import run_cli

SER2NET = shutil.which("ser2net")


@contextlib.contextmanager
def served_pty(*options: str) -> Iterator[str]:
    """`prc3cfg emulator serve --pty` with `options`: the path of its pseudo-terminal."""
    process = subprocess.Popen([sys.executable, "-m", "prc3cfg", "emulator", "serve", "--pty", "--modules", "1-3", *options],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
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
        scanned = run_cli(capsys, "scan", "--port", pty)  # scan's 0.2 s: at 0.1 s a module of the emulator process went unheard under load
        assert scanned.code == 0, scanned.err
        assert "3 modules answered" in scanned.out
        imported = run_cli(capsys, "import", "--port", pty, "--modules", "1-3", "--timeout", "0.2")
        assert imported.code == 0, imported.err
        assert "parity: none" in imported.out
        plant = tmp_path / "plant.yaml"
        plant.write_text(imported.out)
        assert run_cli(capsys, "plan", plant, "--detailed-exitcode").code == 0


def test_a_parity_hint_is_written_as_the_place_it_is_read_says_it(tmp_path, capsys):
    with served_pty() as pty:
        scanned = run_cli(capsys, "scan", "--port", pty, "--parity", "even")
        assert scanned.code == 1
        assert scanned.err.endswith("a pseudo-terminal carries no parity: give --parity none\n"), scanned.err
        plant = tmp_path / "plant.yaml"
        plant.write_text(f"plant: p\nbuses:\n  - name: line\n    port: {pty}\n    parity: even\n    modules:\n      - {{address: 1, name: m1}}\n")
        planned = run_cli(capsys, "plan", plant)
        assert planned.code == 1
        assert planned.err.endswith("a pseudo-terminal carries no parity: set parity: none\n"), planned.err


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def listening(port: int) -> bool:
    """Whether something listens on 127.0.0.1:`port`, as the kernel's socket table says (no connection made)."""
    rows = Path("/proc/net/tcp").read_text().splitlines()[1:]
    return any(row.split()[1] == f"0100007F:{port:04X}" and row.split()[3] == "0A" for row in rows)


@pytest.mark.skipif(SER2NET is None, reason="ser2net is not installed (apt-get install -y ser2net)")
def test_rfc2217_through_ser2net_onto_a_device_without_modem_lines(tmp_path, capsys):
    """docs/plant-files.md's ser2net 4 configuration, its device a pty (no modem lines, like an RS-422 adapter)."""
    port = free_port()
    with served_pty() as pty:
        config = tmp_path / "ser2net.yaml"
        config.write_text(f"connection: &prc3\n  accepter: telnet(rfc2217),tcp,127.0.0.1,{port}\n"
                          f"  connector: serialdev,{pty},9600n81,local\n  options:\n    max-connections: 1\n")  # fmt: skip
        ser2net = subprocess.Popen([SER2NET, "-n", "-c", config], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            while not listening(port):  # ser2net says nothing once it listens: the socket table does
                with contextlib.suppress(subprocess.TimeoutExpired):
                    ser2net.wait(0.01)
                assert ser2net.returncode is None, ser2net.stdout.read()
            plant = tmp_path / "plant.yaml"
            plant.write_text(f"plant: p\nbuses:\n  - name: line\n    port: rfc2217://127.0.0.1:{port}?ign_set_control\n"
                             "    parity: none\n    modules:\n      - {address: 1, name: m1}\n      - {address: 2, name: m2}\n")  # fmt: skip
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
