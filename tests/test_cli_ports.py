"""`prc3cfg ports`: the machine's serial ports as pyserial's `serial.tools.list_ports` finds them —
here a machine's answer stood in for (a Windows laptop with two USB adapters, a built-in port),
and this machine's own."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import pytest
from emulated import run_cli
from serial.tools import list_ports
from serial.tools.list_ports_common import ListPortInfo

from prc3cfg.shell import platform


def port(device: str, description: str = "n/a", vid: int | None = None,
         pid: int | None = None) -> ListPortInfo:
    info = ListPortInfo(device, skip_link_detection=True)
    info.description, info.vid, info.pid = description, vid, pid
    return info


LAPTOP = [
    port("COM10", "USB Serial Port (COM10)", 0x0403, 0x6001),
    port("COM3", "Prolific USB-to-Serial Comm Port (COM3)", 0x067B, 0x2303),
    port("COM1", "Communications Port (COM1)"),
]


@pytest.fixture
def laptop(monkeypatch):
    monkeypatch.setattr(list_ports, "comports", lambda include_links=False: list(LAPTOP))


def test_each_port_is_listed_with_its_vid_pid_and_description_in_number_order(laptop, capsys):
    result = run_cli(capsys, "ports")
    assert result.code == 0, result.err
    assert result.out.splitlines() == [
        "COM1   -          Communications Port (COM1)",
        "COM3   067B:2303  Prolific USB-to-Serial Comm Port (COM3)",
        "COM10  0403:6001  USB Serial Port (COM10)",
    ]


def test_the_ports_as_json(laptop, capsys):
    result = run_cli(capsys, "ports", "--json")
    assert result.code == 0, result.err
    assert json.loads(result.out)[1:] == [
        {"device": "COM3", "description": "Prolific USB-to-Serial Comm Port (COM3)", "usb": "067B:2303"},
        {"device": "COM10", "description": "USB Serial Port (COM10)", "usb": "0403:6001"},
    ]


def test_a_port_without_a_description_has_none(monkeypatch, capsys):
    monkeypatch.setattr(list_ports, "comports",
                        lambda include_links=False: [port("/dev/ttyS0"), port("/dev/ttyUSB0", "ttyUSB0")])
    assert run_cli(capsys, "ports").out.splitlines() == ["/dev/ttyS0    -", "/dev/ttyUSB0  -"]


def test_where_pyserial_s_listing_cannot_load_the_registry_s_com_ports_are_listed(monkeypatch, capsys):
    """Wine 8's cfgmgr32 lacks a function pyserial's Windows listing binds at import (AttributeError from
    ctypes): the ports Windows' registry names are listed, in number order, without description."""
    monkeypatch.setattr(platform, "registered_serial_ports", lambda: ["COM10", "COM7", "COM1"])
    monkeypatch.setattr("builtins.__import__",
                        failing_import(__import__, "serial.tools",
                                       AttributeError("function 'CM_MapCrToWin32Err' not found")))
    result = run_cli(capsys, "ports")
    assert result.code == 0, result.err
    assert result.out.splitlines() == ["COM1   -", "COM7   -", "COM10  -"]


def failing_import(real, name, error):
    def imported(module, globals=None, locals=None, fromlist=(), level=0):
        if module == name and fromlist and "list_ports" in fromlist:
            raise error
        return real(module, globals, locals, fromlist, level)

    return imported


def test_no_port_is_said_on_stderr(monkeypatch, capsys):
    monkeypatch.setattr(list_ports, "comports", lambda include_links=False: [])
    result = run_cli(capsys, "ports")
    assert (result.code, result.out) == (0, "")
    assert result.err.startswith("no serial ports found — plug the adapter in")


def test_this_machine_s_ports_are_listed_without_a_traceback():
    done = subprocess.run([sys.executable, "-m", "prc3cfg", "ports", "--json"], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert isinstance(json.loads(done.stdout), list)


@pytest.mark.skipif(not platform.HAS_PTY, reason="no pseudo-terminals here")
def test_a_pseudo_terminal_is_not_listed():
    """As docs/commands.md says: pyserial lists the machine's serial devices, not its ptys (`emulator serve
    --pty` prints its path)."""
    from prc3cfg import api

    master, slave, path = platform.open_pty()
    try:
        assert path not in {found.device for found in api.serial_ports()}
    finally:
        os.close(master)
        os.close(slave)


@pytest.mark.skipif(not platform.HAS_PTY, reason="no pseudo-terminals on this system")
def test_an_emulator_s_pty_is_listed_while_it_serves_and_not_after(capsys):
    """The port a person tries prc3cfg on without hardware: `emulator serve --pty`'s, which the system
    lists among no serial ports — listed with its process and modules while it serves."""
    process = subprocess.Popen([sys.executable, "-m", "prc3cfg", "emulator", "serve", "--pty", "--modules",
                                "1,3-5"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert process.stdout is not None
        pty = process.stdout.readline().strip().removeprefix("pty: ")  # printed once it serves
        listed = run_cli(capsys, "ports", "--json")
        assert {"device": pty,
                "description": f"prc3cfg emulator serve --pty (pid {process.pid}), addresses 1, 3–5",
                "usb": None} \
            in json.loads(listed.out), listed.out
    finally:
        process.send_signal(signal.SIGINT)
        process.wait(timeout=30)
    assert pty not in run_cli(capsys, "ports").out  # gone with its emulator
