r"""Line settings of an RS-422 line and the times that follow from them (docs/line.md "The line").

Owns the character format and the character time, the URL schemes of ports that are not
UARTs (TCP, the emulator), and which ports a plant file may name (`port_refusal`). Does not own
framing (see `prc3cfg.core.framing`) or the cost of a plan (see `prc3cfg.core.bustime`). Pure.

A plant file is reviewed text, and pyserial turns any port holding `://` into one of its URL
handlers — `spy://…?file=` writes a file, `alt://` picks a class to open with, `hwgrep://` searches
the machine — so a plant file may name only a serial device, `socket://`, `rfc2217://` (the
schemes pyserial lowercases: `SOCKET://` is socket) and prc3cfg's own `emulator://` (as written).
A serial device is a COM port on Windows (`COM3`, `\\.\COM12`) or an absolute path under `/dev`
without a `..` in it, on any system (a file validated on one machine is applied on another).
A relative path is refused, not completed: pyserial would open it relative to wherever the
command runs, which the file's reviewer cannot see. Under `/dev`, the machine's own terminals
and files are refused too: the controlling terminal, consoles, the pty master, the process's
own descriptors, and `/dev/shm`, `/dev/mqueue` (folders every user writes in) — none is a line,
and the controlling terminal would take the line's settings and binary frames. The command line
is not a reviewed file: its ports are the operator's own choice (`prc3cfg.plant.messages.port_error`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal, get_args

#: Ports whose bytes come over TCP (pyserial URLs): `HOST:PORT`, no UART between (docs/line.md).
TCP_SCHEMES = ("socket", "rfc2217")
#: The in-process emulator a plant file can name as its port: `emulator://NAME`.
EMULATOR_SCHEME = "emulator://"
#: Where POSIX systems keep their serial devices (Linux /dev/ttyUSB0, macOS /dev/cu.*, BSD /dev/cuaU0).
DEVICE_FOLDER = "/dev/"
#: A Windows serial port's names: COM10, com10, \\.\COM10 — one device (its name the group).
COM_PORT = re.compile(r"(?:\\\\\.\\)?(COM[1-9][0-9]*)", re.IGNORECASE)
#: What under `DEVICE_FOLDER` is this machine's own, never a line: written for Python and for a JSON
#: Schema's ECMA 262 alike (the end is a lookahead, not `$`).
NOT_A_LINE = r"(?:(?:tty[0-9]*|console|ptmx|pts/ptmx|std(?:in|out|err))(?![\s\S])|fd/|shm/|mqueue/)"
#: Why a plant file may not name a port: pyserial's other URL handlers, a path that is not a serial
#: device's, the machine's own terminals and files (`port_refusal`; `plant.messages` says each).
PortRefusal = Literal["port_handler", "port_not_device", "port_not_a_line"]
Parity = Literal["none", "odd", "even"]
PARITIES: tuple[Parity, ...] = get_args(Parity)
#: What a UART can be set to (the emulator's RFC 2217 gateway receives a client at any of them as a UART
#: would).
DATA_BITS = (5, 6, 7, 8)
#: What a PRC 3 line takes: its frames are binary, and fewer bits lose the top of each byte.
FRAME_DATA_BITS = 8
STOP_BITS = (1, 1.5, 2)


@dataclass(frozen=True, slots=True)
class LineSettings:
    """Baud rate and character format. The default is the PRC 3 line: 9600 baud, 8E1."""

    baud: int = 9600
    data_bits: int = 8
    parity: str = "even"
    stop_bits: float = 1

    def __post_init__(self) -> None:
        if self.baud <= 0:
            raise ValueError(f"baud must be positive, not {self.baud}")
        if self.data_bits not in DATA_BITS:
            raise ValueError(f"data bits must be one of {DATA_BITS}, not {self.data_bits}")
        if self.parity not in PARITIES:
            raise ValueError(f"parity must be one of {', '.join(PARITIES)}, not {self.parity!r}")
        if self.stop_bits not in STOP_BITS:
            raise ValueError(f"stop bits must be one of 1, 1.5, 2, not {self.stop_bits}")

    @property
    def bits_per_char(self) -> float:
        """Start bit + data bits + parity bit + stop bits: 11 for 8E1."""
        return 1 + self.data_bits + (0 if self.parity == "none" else 1) + self.stop_bits

    @property
    def char_time(self) -> float:
        """Seconds one character takes on the line (8E1 at 9600 baud: 1.146 ms)."""
        return self.bits_per_char / self.baud

    def transmission_time(self, n_bytes: int) -> float:
        return n_bytes * self.char_time


def port_refusal(port: str) -> tuple[PortRefusal, str] | None:
    """Why a plant file may not name `port` and the scheme it names ("" for a path); None where it may."""
    scheme, sep, _ = port.partition("://")
    if sep:
        allowed = scheme.lower() in TCP_SCHEMES or scheme == EMULATOR_SCHEME[:-3]
        return None if allowed else ("port_handler", scheme.lower())
    if COM_PORT.fullmatch(port):
        return None
    if not port.startswith(DEVICE_FOLDER) or port == DEVICE_FOLDER or ".." in port.split("/"):
        return "port_not_device", ""
    if re.match(NOT_A_LINE, port[len(DEVICE_FOLDER) :]):
        return "port_not_a_line", ""
    return None
