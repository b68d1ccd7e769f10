"""`prc3cfg scan`, `prc3cfg import` and `prc3cfg link init-db`: a bus without a plant file, and its gateway."""

from __future__ import annotations

import contextlib
from decimal import Decimal
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.table import Table

from prc3cfg import codec, gateway
from prc3cfg.cli import app, link_app
from prc3cfg.cli.common import CANCEL, LockOpt, PlantArg, RetriesOpt, TraceOpt, locked_line, parse_addresses, progress_bar, stderr
from prc3cfg.errors import UserError
from prc3cfg.plant import load_plant
from prc3cfg.framing import FRAMINGS, get_framing
from prc3cfg.image import MAX_MODULE_ADDRESS, PROGRAM_COUNT
from prc3cfg.importer import module_entry, plant_yaml
from prc3cfg.line import LineSettings
from prc3cfg.link import Link, LinkError, Trace, open_port
from prc3cfg.locks import line_keys
from prc3cfg.plant.units import BY_SYMBOL
from prc3cfg.readback import read_module

PortOpt = Annotated[str, typer.Option("--port", help="Device path or pyserial URL (e.g. /dev/ttyUSB0, socket://host:7001).")]
FramingOpt = Annotated[str, typer.Option(help=f"Framing: {' | '.join(FRAMINGS)}.")]
BaudOpt = Annotated[int, typer.Option(help="Baud rate.")]
ParityOpt = Annotated[str, typer.Option(help="none | odd | even")]
TimeoutOpt = Annotated[float, typer.Option(min=0.001, help="Seconds to wait for a reply.")]
ZvzOpt = Annotated[float, typer.Option(min=0.004, help="open-driver: the character delay time ZVZ that ends a frame, s.")]


@contextlib.contextmanager
def _bare_link(port: str, framing: str, baud: int, parity: str, data_bits: int, stop_bits: float, timeout: float, zvz: float, retries: int, trace: Path | None, lock_timeout: float, purpose: str):
    if framing not in FRAMINGS:
        raise UserError(f"--framing: unknown framing '{framing}' — use one of {', '.join(FRAMINGS)}")
    try:
        line = LineSettings(baud=baud, data_bits=data_bits, parity=parity, stop_bits=stop_bits)
    except ValueError as error:
        raise UserError(f"line settings: {error}") from None
    with contextlib.ExitStack() as stack:
        stack.enter_context(locked_line(line_keys(port), port, lock_timeout, purpose))
        tracer = Trace(stack.enter_context(trace.open("a"))) if trace else None
        serial_port = open_port(port, line, bus=port)
        stack.callback(serial_port.close)
        yield Link(serial_port, get_framing(framing), bus=port, line=line, timeout=timeout, zvz=zvz, retries=retries,
                   trace=tracer, cancel=CANCEL.event)  # fmt: skip


def _scan(link: Link) -> dict[int, codec.SystemReply]:
    found = {}
    with progress_bar(MAX_MODULE_ADDRESS, "scanning addresses") as tick:
        for address in range(1, MAX_MODULE_ADDRESS + 1):
            try:
                reply = link.request(address, codec.ReadSystem())
            except LinkError:
                reply = None
            if isinstance(reply, codec.SystemReply):
                found[address] = reply
            tick()
    return found


@app.command()
def scan(
    port: PortOpt,
    framing: FramingOpt = "crc16",
    baud: BaudOpt = 9600,
    parity: ParityOpt = "even",
    data_bits: int = 8,
    stop_bits: float = 1,
    timeout: TimeoutOpt = 0.2,
    zvz: ZvzOpt = 0.020,
    retries: RetriesOpt = 1,
    trace: TraceOpt = None,
    lock_timeout: LockOpt = 0.0,
) -> None:
    """Which addresses 1..30 answer, with their S9 and system parameters."""
    with _bare_link(port, framing, baud, parity, data_bits, stop_bits, timeout, zvz, retries, trace, lock_timeout, "scan") as link:
        found = _scan(link)
    if not found:
        raise UserError(f"{port}: no module answered at any address 1..30 — check the framing ({framing}), line settings and wiring")
    table = Table("address", "S9", *(f"{k} {BY_SYMBOL[k].key}" for k in ("S1", "S2", "S4", "S5", "S6")), "others")
    for address, reply in found.items():
        s = reply.system
        others = ", ".join(f"{k}={BY_SYMBOL[k].format(getattr(s, k))}" for k in ("S3", "S7", "S8", "S10", "S11", "S12"))
        warn = "" if reply.address == address else " ⚠"
        table.add_row(str(address), f"{reply.address}{warn}", *(BY_SYMBOL[k].format(getattr(s, k)) for k in ("S1", "S2", "S4", "S5", "S6")), others)
    Console().print(table)
    print(f"{len(found)} module{'s' if len(found) != 1 else ''} answered on {port}.")


@app.command("import")
def import_plant(
    port: PortOpt,
    framing: FramingOpt = "crc16",
    baud: BaudOpt = 9600,
    parity: ParityOpt = "even",
    data_bits: int = 8,
    stop_bits: float = 1,
    timeout: TimeoutOpt = 0.5,
    zvz: ZvzOpt = 0.020,
    retries: RetriesOpt = 5,
    plant_name: Annotated[str, typer.Option(help="The plant's name in the file.")] = "imported",
    bus_name: Annotated[str, typer.Option(help="The bus's name in the file.")] = "bus-1",
    modules: Annotated[Optional[str], typer.Option(help="Addresses to import, e.g. 1,3-5 (default: scan 1..30).")] = None,
    trace: TraceOpt = None,
    lock_timeout: LockOpt = 0.0,
) -> None:
    """Write a plant file (to stdout) from the live modules of one bus."""
    with _bare_link(port, framing, baud, parity, data_bits, stop_bits, timeout, zvz, retries, trace, lock_timeout, "import") as link:
        addresses = parse_addresses(modules) if modules else sorted(_scan(link))
        if not addresses:
            raise UserError(f"{port}: no module answered — nothing to import")
        images = []
        with progress_bar(len(addresses), "reading modules") as tick:
            for address in addresses:
                images.append(read_module(link, address, range(1, PROGRAM_COUNT + 1)))
                tick()
    bus = {"name": bus_name, "port": port, "framing": framing, "baud": baud, "parity": parity,
           "data_bits": data_bits, "stop_bits": stop_bits, "timeout": Decimal(str(timeout))}  # fmt: skip
    if framing == "open-driver":
        bus["zvz"] = Decimal(str(zvz))
    entries = [module_entry(image, f"{bus_name}-{image.address}") for image in images]
    print(plant_yaml(plant_name, bus, entries), end="")
    stderr.print(f"imported {len(images)} modules from {port}")


@link_app.command("init-db")
def init_db(
    plant: PlantArg,
    bus: Annotated[str, typer.Option("--bus", help="The bus whose gateway to parameterise.")],
) -> None:
    """The CP 524/525 Open Driver INIT data block (eight data words) for a bus's gateway."""
    loaded = load_plant(plant)
    found = [b for b in loaded.buses if b.name == bus]
    if not found:
        raise UserError(f"{plant}: no bus named {bus} — the plant's buses are {', '.join(b.name for b in loaded.buses)}")
    b = found[0]
    if b.gateway is None:
        raise UserError(f"{plant}: bus {bus} has no gateway block — add gateway: {{receive_db, receive_dw, cpu, identifier}}")
    zvz_ms = Decimal(str(b.zvz)) * 1000
    if zvz_ms != zvz_ms.to_integral_value():
        raise UserError(f"{plant}: bus {bus}: zvz {b.zvz} s is not a whole number of milliseconds — ZVZTIM is set in ms")
    settings = gateway.GatewaySettings(
        receive_db=b.gateway.receive_db, receive_dw=b.gateway.receive_dw, cpu=b.gateway.cpu,
        identifier=b.gateway.identifier, line=b.line, zvz_ms=int(zvz_ms),
    )  # fmt: skip
    problems = gateway.refusals(settings)
    if problems:
        raise UserError(f"bus {bus}: the CP 524/525 Open Driver would refuse these settings: " + "; ".join(map(str, problems)))
    print(f"INIT data block for bus {bus} (CP 524/525 Open Driver S5D004, interface for {b.port}):")
    for label, notation, hex_value in gateway.format_data_block(gateway.init_data_block(settings)):
        print(f"  {label:<5} {notation:<26} {hex_value}")
