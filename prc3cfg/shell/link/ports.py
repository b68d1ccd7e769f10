"""Opening a plant bus's line: a serial device, `socket://`, `rfc2217://` or `emulator://NAME` — the
ports a plant file may name (`prc3cfg.core.line.port_refusal`), checked again by `open_port` — and a
port the operator names on the command line, which may be any pyserial URL.

`emulator://NAME` runs the bus emulator in this process (the same code as `prc3cfg
emulator serve`) on a loopback port and connects to it through `socket://`, so the whole
link is exercised. Its state is kept in `.prc3cfg/emulators/NAME.json` beside the plant
file (with its journal beside it while it runs, `prc3cfg.shell.emulator.state`), created with
factory-default modules at the plant's addresses. It takes every frame at once and in order,
so the link waits no line time after a broadcast. `emulator://NAME?line-speed=BAUD` makes
every exchange take as long as on a line of BAUD baud with the bus's character format, to
rehearse real timings without hardware (broadcasts then wait as on a line); with it,
`turnaround=S` (else the bus's), `module-turnaround=ADDRESS:S` (repeatable) and `jitter=S`
(`seed=N`) make the modules answer as a line that is not ideal would (`Emulator`); the query
takes no other key.

`socket://` ports are pyserial's with two changes (`TcpPort`): `in_waiting` says how many
bytes have arrived (pyserial says 1 whenever there are any, so a reply would be read a
byte at a time), and closing does not sleep 0.3 s (pyserial's pause for a quick
reconnect, which prc3cfg never makes: it closes a line when a command is done with it).

`serial_ports` lists the machine's serial ports as pyserial's `serial.tools.list_ports` finds
them (Windows' COM ports from the registry, Linux's /dev/ttyS*, ttyUSB*, ttyACM*, … from sysfs, macOS'
/dev/cu.*): the port a plant file names, a description, a USB adapter's VID:PID — else, where that
listing cannot load (Wine 8), the COM ports Windows' registry names.
"""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any
from urllib.parse import parse_qsl, urlsplit

import serial
from serial.urlhandler import protocol_socket

from prc3cfg.core.bustime import LineCost
from prc3cfg.core.device import ModuleState
from prc3cfg.core.framing import get_framing
from prc3cfg.core.image import MAX_MODULE_ADDRESS
from prc3cfg.core.line import EMULATOR_SCHEME, LineSettings
from prc3cfg.core.text import address_ranges
from prc3cfg.errors import UserError
from prc3cfg.plant.messages import port_error
from prc3cfg.shell import platform
from prc3cfg.shell.emulator import ptys
from prc3cfg.shell.link.client import Exchange, Link
from prc3cfg.shell.link.trace import Trace

PARITY = {"none": serial.PARITY_NONE, "odd": serial.PARITY_ODD, "even": serial.PARITY_EVEN}
STOP_BITS = {1: serial.STOPBITS_ONE, 1.5: serial.STOPBITS_ONE_POINT_FIVE, 2: serial.STOPBITS_TWO}


@dataclass(frozen=True)
class SerialPort:
    """A serial port of this machine: the `device` a plant file's `port` names (COM3, /dev/ttyUSB0),
    the system's `description` of it ("" when it has none), and a USB adapter's `usb` VID:PID ("0403:6001").
    """

    device: str
    description: str
    usb: str | None


def serial_ports() -> list[SerialPort]:
    """The machine's serial ports in pyserial's order (COM2 before COM10), then the pseudo-terminals this
    user's `prc3cfg emulator serve --pty` serve (the system lists none). Where pyserial's listing cannot
    load (Windows' cfgmgr32 without a function it needs: Wine 8), the registry's COM ports, without
    description or VID:PID."""
    emulated = [SerialPort(path, f"prc3cfg emulator serve --pty (pid {pid}), {address_ranges(modules)}", None)
                for path, pid, modules in ptys.serving()]
    try:
        from serial.tools import list_ports
    except (AttributeError, OSError):  # ctypes: a system DLL without the function pyserial binds at import
        registered = sorted(platform.registered_serial_ports(), key=lambda name: (len(name), name))
        return [SerialPort(name, "", None) for name in registered] + emulated

    return [SerialPort(info.device, "" if info.description in ("n/a", info.name) else info.description,
                       None if info.vid is None or info.pid is None else f"{info.vid:04X}:{info.pid:04X}")
            for info in sorted(list_ports.comports())] + emulated


class FormatRefused(UserError):
    """A port that does not keep the line's character format — a pseudo-terminal takes no parity.
    `str()` says the fix as a plant file's bus is written (`parity: none`); `refusal` is the rest,
    for a command line to say its own (`--parity none`)."""

    def __init__(self, bus: str, url: str, line: LineSettings) -> None:
        self.refusal = (f"port {url} refuses {line.data_bits} data bits, parity {line.parity}, "
                        f"{line.stop_bits:g} stop bits "
                        "— a pseudo-terminal carries no parity")
        super().__init__(f"bus {bus}: {self.refusal}: set parity: none")


class TcpPort(protocol_socket.Serial):
    """pyserial's `socket://` port that tells how many bytes have arrived and closes at once."""

    _socket: socket.socket | None  # pyserial's, which its stubs leave out

    @property
    def in_waiting(self) -> int:
        if not self.is_open or self._socket is None:
            raise serial.PortNotOpenError()
        return platform.bytes_waiting(self._socket)

    def close(self) -> None:
        if self.is_open and self._socket:
            with contextlib.suppress(OSError):
                self._socket.close()
            self._socket = None
        self.is_open = False


def emulator_state_path(plant_path: Path, port: str) -> Path:
    name = port[len(EMULATOR_SCHEME) :].partition("?")[0]
    return plant_path.parent / ".prc3cfg" / "emulators" / f"{name}.json"


@dataclass(frozen=True)
class EmulatorQuery:
    """What `emulator://NAME?…` asks of its emulator: a line speed, the modules' turnarounds, jitter."""

    line_speed: int | None = None
    turnaround: float | None = None  # s; None: the bus's
    turnarounds: dict[int, float] = field(default_factory=dict)  # s, by module address
    jitter: float = 0.0  # s
    seed: int | None = None


#: The keys of an `emulator://` query, as docs/plant-files.md and the refusal of any other key say them.
EMULATOR_KEYS = "line-speed=BAUD, turnaround=S, module-turnaround=ADDRESS:S, jitter=S, seed=N"


def emulator_query(port: str) -> EmulatorQuery:
    """The query of `emulator://NAME?line-speed=BAUD&turnaround=S&module-turnaround=ADDRESS:S&jitter=S&seed=N`
    (times in seconds, as a plant file writes them; `module-turnaround` repeatable, the others once);
    ValueError, in words that say what to write, for anything else."""
    options = parse_qsl(urlsplit(port).query, keep_blank_values=True)
    given: dict[str, str] = {}
    turnarounds: dict[int, float] = {}
    for key, value in options:
        if key == "module-turnaround":
            address, _, seconds = value.partition(":")
            if not (address.isascii() and address.isdigit() and 1 <= int(address) <= MAX_MODULE_ADDRESS):
                raise ValueError(f"module-turnaround '{value}' is not ADDRESS:SECONDS — write e.g. "
                                 "module-turnaround=3:0.040")
            turnarounds[int(address)] = _seconds(key, seconds)
        elif key not in ("line-speed", "turnaround", "jitter", "seed"):
            raise ValueError(f"unknown option '{key}' — emulator:// takes {EMULATOR_KEYS}")
        elif key in given:
            raise ValueError(f"{key} is given more than once — give it once")
        else:
            given[key] = value
    return EmulatorQuery(
        line_speed=(_whole(given["line-speed"], "a baud rate", "line-speed=9600") if "line-speed" in given
                    else None),
        turnaround=_seconds("turnaround", given["turnaround"]) if "turnaround" in given else None,
        turnarounds=turnarounds,
        jitter=_seconds("jitter", given["jitter"]) if "jitter" in given else 0.0,
        seed=_whole(given["seed"], "a seed", "seed=1", least=0) if "seed" in given else None,
    )


def _whole(value: str, what: str, example: str, least: int = 1) -> int:
    if not value.isascii() or not value.isdigit() or int(value) < least:
        raise ValueError(f"{example.partition('=')[0]} '{value}' is not {what} — write a whole number, e.g. "
                         f"{example}")
    return int(value)


def _seconds(key: str, value: str) -> float:
    try:
        seconds = float(value)
    except ValueError:
        seconds = -1.0
    if not 0 <= seconds <= 10 or not value.isascii():
        raise ValueError(f"{key} '{value}' is not a time of 0..10 s — write seconds, e.g. {key}=0.010")
    return seconds


def open_port(url: str, line: LineSettings, *, bus: str, operators: bool = False) -> serial.Serial | TcpPort:
    """Open a device path (exclusively) or a TCP URL with the line's settings — a port a plant file may
    name, checked again here, before pyserial sees it, whichever way it came (a bus an API user made
    in code skips the plant file's validation); or, where `operators` (a port the operator gave on
    the command line, a `BareLine`), any port pyserial opens, its URL handlers too.

    A device that silently drops a setting (a pseudo-terminal takes parity without a word,
    then refuses the next change with a bare `termios.error`) is refused here, at once.
    """
    problem = port_error("port", url, operators=operators)
    if problem is not None:
        raise UserError(f"bus {bus}: {problem}")
    is_url = "://" in url
    refused = FormatRefused(bus, url, line)
    settings: dict[str, Any] = {"baudrate": line.baud, "bytesize": line.data_bits,
                                "parity": PARITY[line.parity],
                                "stopbits": STOP_BITS[line.stop_bits], "timeout": 0.05}
    port: serial.Serial | TcpPort
    try:
        if url.partition("://")[0].lower() == "socket":
            port = TcpPort(None, **settings)
            port.port = url
            port.open()
        else:
            port = serial.serial_for_url(url, **(settings if is_url else settings | {"exclusive": True}))
    except platform.TERMINAL_ERRORS:
        raise refused from None
    except (serial.SerialException, ValueError, OSError) as error:
        # pyserial waits for SET_CONTROL's answer
        if url.lower().startswith("rfc2217://") and "option 'control'" in str(error):
            raise UserError(f"bus {bus}: cannot open port {url} ({error}) — a port without modem lines "
                            "(ser2net's local) does "
                            "not answer it: add ?ign_set_control to the rfc2217:// URL") from None
        raise UserError(f"bus {bus}: cannot open port {url} ({error}) — check the adapter, the path "
                        "or the URL") from None
    except Exception as error:  # noqa: BLE001 — a pyserial URL handler (alt://, spy://, …) failing its own way
        raise UserError(f"bus {bus}: cannot open port {url} (pyserial's {url.partition('://')[0]}:// "
                        "handler failed: "
                        f"{type(error).__name__}: {error}) — check the URL's options") from None
    if not is_url and not _holds(port, line):
        port.close()
        raise refused
    return port


def _holds(port: serial.SerialBase, line: LineSettings) -> bool:
    """Whether the device kept the character format it was given (parity, data bits, stop bits)."""
    kept = platform.character_format(port)
    if kept is None:
        return True  # not a terminal: nothing to read back
    parity, data_bits, two_stop_bits = kept
    return parity == line.parity and data_bits == line.data_bits and two_stop_bits == (line.stop_bits != 1)


@contextlib.contextmanager
def open_link(
    bus,
    plant_path: Path,
    *,
    retries: int = 5,
    trace: Trace | None = None,
    observer: Callable[[Exchange], None] | None = None,
    announce: Callable[[Exchange], None] | None = None,
    cancel: threading.Event | None = None,
) -> Iterator[Link]:
    """A `Link` to one plant bus (`prc3cfg.plant.Bus`), closed on exit."""
    with contextlib.ExitStack() as stack:
        url, takes_line_time = bus.port, True
        if url.startswith(EMULATOR_SCHEME):
            # the embedded emulator: for emulator:// only
            from prc3cfg.shell.emulator.server import Emulator, FaultInjection
            from prc3cfg.shell.emulator.state import load_state

            try:
                query = emulator_query(url)
            except ValueError as error:
                raise UserError(f"bus {bus.name}: port {url}: {error}") from None
            line_speed = query.line_speed
            state_path = emulator_state_path(plant_path, url)
            modules = load_state(state_path)
            for module in bus.modules:
                modules.setdefault(module.address, ModuleState.factory(module.address))
            emulator = stack.enter_context(
                Emulator(modules, framing=bus.framing, zvz=bus.zvz, state_path=state_path,
                         turnaround=bus.turnaround if query.turnaround is None else query.turnaround,
                         turnarounds=query.turnarounds,
                         jitter=query.jitter, faults=FaultInjection(seed=query.seed),
                         line=replace(bus.line, baud=line_speed or bus.line.baud),
                         line_speed=line_speed is not None)
            )
            host, tcp_port = emulator.listen("127.0.0.1", 0)
            url, takes_line_time = f"socket://{host}:{tcp_port}", line_speed is not None
        port = open_port(url, bus.line, bus=bus.name)
        stack.callback(port.close)
        yield Link(
            port,
            get_framing(bus.framing),
            bus=bus.name,
            line=bus.line,
            timeout=bus.timeout,
            zvz=bus.zvz,
            retries=retries,
            trace=trace,
            observer=observer,
            announce=announce,
            cancel=cancel,
            takes_line_time=takes_line_time,
            cost=LineCost.of(bus.framing, bus.line, bus.turnaround, bus.zvz),
            port_name=bus.port,
        )


@contextlib.contextmanager
def open_plant_links(plant, buses: Iterable[str] | None = None, **options) -> Iterator[dict[str, Link]]:
    """A `Link` per bus of `plant` (or of the named buses), all closed on exit."""
    names = None if buses is None else set(buses)
    with contextlib.ExitStack() as stack:
        yield {
            bus.name: stack.enter_context(open_link(bus, plant.path, **options))
            for bus in plant.buses
            if names is None or bus.name in names
        }
