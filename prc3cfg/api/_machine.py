"""The machine as the command line meets it: its shared folder of records, its serial ports, its terminal.

`setup_machine` and `unshared_records` (`prc3cfg.shell.machine_folder`); `serial_ports` and `SerialPort`
(`prc3cfg.shell.link.ports`); `terminal_path`, `device_number`, `wait_for` (`prc3cfg.shell.platform`).
"""

from __future__ import annotations

from pathlib import Path

from prc3cfg.shell import machine_folder
from prc3cfg.shell.link.ports import SerialPort as SerialPort
from prc3cfg.shell.link.ports import serial_ports as serial_ports
from prc3cfg.shell.platform import device_number as device_number
from prc3cfg.shell.platform import terminal_path as terminal_path
from prc3cfg.shell.platform import wait_for as wait_for


def setup_machine(group: str | None = None) -> tuple[Path, str | None]:
    """Make (or put right) the machine's folder of axis-release records and line records that every user
    of its lines shares — run once by an administrator; the folder and the serial ports' group it gave it."""
    return machine_folder.setup_machine(group)


def unshared_records() -> str | None:
    """The one-line hint for a user whose records no other user of the machine sees (None: they do)."""
    return machine_folder.unshared()
