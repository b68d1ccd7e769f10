"""`prc3cfg emulator serve`: run a bus emulator until SIGINT/SIGTERM (interfaces.md §5)."""

from __future__ import annotations

import signal
import threading
from pathlib import Path
from typing import Annotated, Optional

import typer

from prc3cfg.cli import emulator_app
from prc3cfg.cli.common import parse_addresses
from prc3cfg.device import ModuleState
from prc3cfg.emulator import Emulator, FaultInjection, load_state
from prc3cfg.errors import UserError
from prc3cfg.framing import FRAMINGS
from prc3cfg.image import MAX_MODULE_ADDRESS
from prc3cfg.line import LineSettings


def parse_listen(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise UserError(f"--listen: '{text}' is not HOST:PORT — for example 127.0.0.1:7001")
    return host or "127.0.0.1", int(port)


@emulator_app.command("serve")
def serve(
    listen: Annotated[Optional[str], typer.Option(help="HOST:PORT to accept TCP connections on (socket://HOST:PORT).")] = None,
    pty: Annotated[bool, typer.Option("--pty", help="Also serve a pseudo-terminal and print its path.")] = False,
    state: Annotated[Optional[Path], typer.Option(help="State file (prc3-emulator/1), loaded and saved after every accepted write.")] = None,
    modules: Annotated[Optional[str], typer.Option(help="Module addresses, e.g. 1,3-5 (default: the state file's, else 1-30).")] = None,
    framing: Annotated[str, typer.Option(help=f"Framing: {' | '.join(FRAMINGS)}.")] = "crc16",
    line_speed: Annotated[Optional[int], typer.Option("--line-speed", help="Make every exchange take as long as on a line of this baud rate.")] = None,
    parity: Annotated[str, typer.Option(help="none | odd | even (character time, and framing time-outs).")] = "even",
    data_bits: Annotated[int, typer.Option(help="5..8")] = 8,
    stop_bits: Annotated[float, typer.Option(help="1 | 1.5 | 2")] = 1,
    zvz: Annotated[float, typer.Option(help="open-driver end-of-frame gap, s.")] = 0.020,
    turnaround: Annotated[float, typer.Option(help="Module turnaround, s (with --line-speed).")] = 0.010,
    drop_rate: Annotated[float, typer.Option(help="Fraction of exchanges lost (request or reply).")] = 0.0,
    corrupt_rate: Annotated[float, typer.Option(help="Fraction of exchanges with one bit flipped.")] = 0.0,
    seed: Annotated[Optional[int], typer.Option(help="Seed for fault injection.")] = None,
) -> None:
    """Run a PRC 3 bus emulator until interrupted."""
    if framing not in FRAMINGS:
        raise UserError(f"--framing: unknown framing '{framing}' — use one of {', '.join(FRAMINGS)}")
    try:
        line = LineSettings(baud=line_speed or 9600, data_bits=data_bits, parity=parity, stop_bits=stop_bits)
        faults = FaultInjection(drop_rate, corrupt_rate, seed)
    except ValueError as error:
        raise UserError(f"emulator: {error}") from None
    bus = load_state(state) if state is not None else {}
    addresses = parse_addresses(modules) if modules else ([] if bus else range(1, MAX_MODULE_ADDRESS + 1))
    for address in addresses:
        bus.setdefault(address, ModuleState.factory(address))
    emulator = Emulator(
        bus, framing=framing, line=line, zvz=zvz, turnaround=turnaround,
        line_speed=line_speed is not None, faults=faults, state_path=state,
    )  # fmt: skip
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    with emulator:
        if listen is not None or not pty:
            try:
                host, port = emulator.listen(*parse_listen(listen or "127.0.0.1:7001"))
            except OSError as error:
                raise UserError(f"--listen {listen}: {error.strerror} — choose another port") from None
            print(f"listening on {host}:{port} ({framing}, modules {', '.join(map(str, sorted(bus)))})", flush=True)
        if pty:
            print(f"pty: {emulator.open_pty()}", flush=True)
        stop.wait()
