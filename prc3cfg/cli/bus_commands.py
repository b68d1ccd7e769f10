"""`prc3cfg ports`, `prc3cfg scan`, `prc3cfg import`, `prc3cfg doctor` and `prc3cfg link init-db`: the
machine's serial ports, a bus without a plant file, and its gateway.

Without `--parity`, scan and import use even parity (a PRC 3 line's), and none on a
pseudo-terminal, which carries no parity (`emulator serve --pty` defaults to none as well).
"""

import contextlib
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from prc3cfg.cli import app, link_app
from prc3cfg.cli.common import (
    FRAMING_NAMES,
    PARITY_NAMES,
    STOP_BITS,
    LockOpt,
    OutFileOpt,
    PlantArg,
    RetriesOpt,
    TraceOpt,
    addresses_option,
    check_output,
    frame_data_bits,
    line_options,
    one_of,
    parse_addresses,
    print_document,
    printed_or_written,
    stderr_console,
    stdout_console,
    write_output,
)
from prc3cfg.cli.durations import TIMES, duration
from prc3cfg.errors import UserError

if TYPE_CHECKING:
    from prc3cfg import api
    from prc3cfg.api import Diagnosis

#: The `--json` documents of `scan`, `import` and `doctor` (`schemas/scan.schema.json`, …).
SCAN_FORMAT, IMPORT_FORMAT, DOCTOR_FORMAT = "prc3cfg-scan/1", "prc3cfg-import/1", "prc3cfg-doctor/1"

PortOpt = Annotated[str, typer.Option("--port", metavar="PORT",
                                      help="Device path or pyserial URL (e.g. /dev/ttyUSB0, "
                                           "socket://host:7001).")]
FramingOpt = Annotated[str, typer.Option(callback=one_of(FRAMING_NAMES), metavar="FRAMING",
                                         help=f"Framing: {' | '.join(FRAMING_NAMES)}.")]
BaudOpt = Annotated[int, typer.Option(min=1, max=10_000_000, metavar="BAUD", help="Baud rate.")]
ParityOpt = Annotated[str | None,
                      typer.Option(callback=one_of(PARITY_NAMES), metavar="PARITY",
                                   show_default="even; none on a pseudo-terminal",
                                               help=" | ".join(PARITY_NAMES))]
DataBitsOpt = Annotated[int, typer.Option(callback=frame_data_bits, metavar="BITS",
                                          help="8: a PRC 3 frame is binary")]
StopBitsOpt = Annotated[float, typer.Option(callback=one_of(STOP_BITS), metavar="BITS",
                                            help=" | ".join(map(str, STOP_BITS)))]
TimeoutOpt = Annotated[float, typer.Option(parser=duration(0.001, 3600), metavar="TIME",
                                           help="How long to wait for a reply beyond the line's own time: "
                                                "its frames at the baud and character format, the "
                                                f"turnaround ({TIMES}).")]
ZvzOpt = Annotated[float, typer.Option(parser=duration(0.004, 65.535), metavar="TIME",
                                       help="open-driver: the character delay time ZVZ that ends a frame "
                                            f"({TIMES}).")]


def _bare_line(port: str, framing: str, baud: int, parity: str | None, data_bits: int, stop_bits: float,
               timeout: float, zvz: float) -> "api.BareLine":
    from prc3cfg import api
    from prc3cfg.core.line import LineSettings

    if parity is None:
        parity = api.default_parity(port)
    # the options' callbacks checked them
    line = LineSettings(baud=baud, data_bits=data_bits, parity=parity, stop_bits=stop_bits)
    return api.BareLine(port, framing, line, timeout, zvz)


@contextlib.contextmanager
def _said_as_options() -> Iterator[None]:
    """A port's refusal of the character format, with the fix as an option (`--parity none`), not as a plant
    file's key."""
    from prc3cfg import api

    try:
        yield
    except api.FormatRefused as refused:
        raise UserError(f"{refused.refusal}: give --parity none") from None


@app.command()
def ports(
    json_out: Annotated[bool, typer.Option("--json",
                                           help="Print the ports as JSON: a list of {device, "
                                                "description, usb}.")] = False,
) -> None:
    """The machine's serial ports: the name a plant file's port takes, a description, a USB adapter's
    VID:PID."""
    import json
    import sys
    from dataclasses import asdict

    from prc3cfg import api

    found = api.serial_ports()
    if json_out:
        print(json.dumps([asdict(port) for port in found], indent=2))
    else:
        width = max((len(port.device) for port in found), default=0)
        for port in found:
            print(f"{port.device:<{width}}  {port.usb or '-':<9}  {port.description}".rstrip())
    if not found:
        print("no serial ports found — plug the adapter in (a pseudo-terminal is not listed: emulator serve "
              "--pty prints its path)",
              file=sys.stderr)


@app.command("setup-machine")
def setup_machine(
    group: Annotated[str | None,
                     typer.Option(metavar="GROUP",
                                  help="The group of the lines' users (default: dialout, else uucp — the "
                                       "serial ports' group).")] = None,
) -> None:
    """Make the machine's folder of axis-release records and line records that every user of its lines shares
    (once, as an administrator)."""
    from prc3cfg import api

    folder, owner = api.setup_machine(group)
    shared = f"the group {owner}" if owner else "every user (the folder's rights)"
    print(f"{folder}: the records of axis releases and of what the modules hold, shared by {shared} — each "
          "user's files their own")


@app.command()
def scan(
    port: PortOpt,
    framing: FramingOpt = "crc16",
    baud: BaudOpt = 9600,
    parity: ParityOpt = None,
    data_bits: DataBitsOpt = 8,
    stop_bits: StopBitsOpt = 1,
    timeout: TimeoutOpt = 0.2,
    zvz: ZvzOpt = 0.020,
    retries: RetriesOpt = 1,
    trace: TraceOpt = None,
    lock_timeout: LockOpt = 0.0,
    json_out: Annotated[bool, typer.Option("--json",
                                           help=f"Print what answered as a {SCAN_FORMAT} document (system "
                                                "parameters in device units).")] = False,
) -> None:
    """Which addresses 1..30 answer, with their S9 and system parameters."""
    from rich.table import Table

    from prc3cfg import api
    from prc3cfg.core.render import plural
    from prc3cfg.core.units import BY_SYMBOL, human_text

    check_output(trace, "--trace")
    bare = _bare_line(port, framing, baud, parity, data_bits, stop_bits, timeout, zvz)
    with line_options(trace, retries, lock_timeout, json_out=json_out) as options, _said_as_options():
        found = api.scan(bare, options)
    if not found:
        raise UserError(f"{port}: no module answered at any address 1..30 — check the framing ({framing}), "
                        "line settings and wiring")
    if json_out:
        modules = [{"address": address, "s9": reply.address, "system": reply.system.to_json()}
                   for address, reply in found.items()]
        print_document({"format": SCAN_FORMAT, "port": port, "framing": framing, "modules": modules})
        return
    table = Table("address", "S9", *(f"{k} {BY_SYMBOL[k].key}" for k in ("S1", "S2", "S4", "S5", "S6")),
                  "others")
    for address, reply in found.items():
        s = reply.system
        others = ", ".join(f"{k}={human_text(k, getattr(s, k))}"
                           for k in ("S3", "S7", "S8", "S10", "S11", "S12"))
        warn = "" if reply.address == address else " ⚠"
        table.add_row(str(address), f"{reply.address}{warn}",
                      *(human_text(k, getattr(s, k)) for k in ("S1", "S2", "S4", "S5", "S6")), others)
    stdout_console().print(table)
    print(f"{plural(len(found), 'module')} answered on {port}.")


@app.command("import")
def import_plant(
    ports: Annotated[list[str],
                     typer.Option("--port", metavar="PORT",
                                  help="Device path or pyserial URL of a line (e.g. COM3, /dev/ttyUSB0, "
                                       "socket://host:7001); repeatable: one bus each.")],
    framing: FramingOpt = "crc16",
    baud: BaudOpt = 9600,
    parity: ParityOpt = None,
    data_bits: DataBitsOpt = 8,
    stop_bits: StopBitsOpt = 1,
    timeout: TimeoutOpt = 0.5,
    zvz: ZvzOpt = 0.020,
    retries: RetriesOpt = 5,
    plant_name: Annotated[str, typer.Option(metavar="NAME", help="The plant's name in "
                                                                 "the file.")] = "imported",
    bus_names: Annotated[list[str] | None,
                         typer.Option("--bus-name", metavar="NAME",
                                      help="The bus's name in the file; repeatable, one per --port in their "
                                           "order (default: bus-1, bus-2, …).")] = None,
    modules: Annotated[str | None,
                       typer.Option(callback=addresses_option, metavar="ADDRESSES",
                                    help="Addresses to import, e.g. 1,3-5 (default: scan 1..30).")] = None,
    trace: TraceOpt = None,
    lock_timeout: LockOpt = 0.0,
    out: OutFileOpt = None,
    json_out: Annotated[bool, typer.Option("--json", help=(
        f"Print a {IMPORT_FORMAT} document: the buses and modules imported, and the plant file's text (null "
        "where it was written with --out)."))] = False,
) -> None:
    """Write a plant file (to stdout, or --out) from the live modules of one bus or more (a --port each, with
    the same line settings)."""
    from prc3cfg import api
    from prc3cfg.core.render import plural

    check_output(trace, "--trace")
    names = bus_names or [f"bus-{number}" for number in range(1, len(ports) + 1)]
    if len(names) != len(ports):
        raise UserError(f"{len(names)} --bus-name for {len(ports)} --port: give one name per port, in their "
                        "order (or none)")
    if len(set(names)) != len(names):
        raise UserError(f"--bus-name {next(n for n in names if names.count(n) > 1)} is given twice: each "
                        "bus needs a name of its own")
    buses = {name: _bare_line(port, framing, baud, parity, data_bits, stop_bits, timeout, zvz)
             for name, port in zip(names, ports)}
    with line_options(trace, retries, lock_timeout, json_out=json_out) as options, _said_as_options():
        text, count = api.import_plant(buses, parse_addresses(modules) if modules is not None else None,
                                       options, plant_name=plant_name)
    if json_out:
        if out is not None:
            write_output(out, text, "--out")
        print_document({"format": IMPORT_FORMAT, "plant": plant_name,
                        "buses": [{"name": n, "port": p} for n, p in zip(names, ports)],
                        "modules": count, "out": None if out is None else str(out),
                        "plant_file": text if out is None else None})
        return
    printed_or_written(text, out)
    stderr_console().print(f"imported {plural(count, 'module')} from {', '.join(ports)}")
    if out is not None:
        _schema_beside(text, out)


def _schema_beside(text: str, out: Path) -> None:
    """The command that writes the JSON Schema the plant file's first line names beside it, for an editor
    (yaml-language-server) — where that file is not there yet."""
    from prc3cfg.shell.platform import command_line

    schema = text.partition("$schema=")[2].partition("\n")[0]
    if schema and not (out.parent / schema).exists():
        print(f"its first line names {schema} beside it, for an editor — write that with: "
              f"{command_line('prc3cfg', 'schema', '--out', str(out.parent / schema))}", file=sys.stderr)


@link_app.command("init-db")
def init_db(
    plant: PlantArg,
    bus: Annotated[str, typer.Option("--bus", metavar="NAME", help="The bus whose gateway to parameterise.")],
) -> None:
    """The CP 524/525 Open Driver INIT data block (eight data words) for a bus's gateway."""
    from prc3cfg import api

    loaded = api.load(plant)
    words = api.init_data_block(loaded, bus)
    port = next(b.port for b in loaded.buses if b.name == bus)
    print(f"INIT data block for bus {bus} (CP 524/525 Open Driver S5D004, interface for {port}):")
    for label, notation, hex_value in words:
        print(f"  {label:<5} {notation:<26} {hex_value}")


@app.command()
def doctor(
    port: PortOpt,
    framing: Annotated[str | None,
                       typer.Option(callback=one_of(FRAMING_NAMES), metavar="FRAMING",
                                    show_default="tried: crc16, stx, open-driver",
                                                help=f"Framing: {' | '.join(FRAMING_NAMES)}.")] = None,
    baud: Annotated[int | None,
                    typer.Option(min=1, max=10_000_000, metavar="BAUD",
                                 show_default="tried: 9600, 19200, 4800, … 300",
                                             help="Baud rate.")] = None,
    parity: Annotated[str | None,
                      typer.Option(callback=one_of(PARITY_NAMES), metavar="PARITY",
                                   show_default="tried: even, none, odd; none on a pseudo-terminal",
                                               help=" | ".join(PARITY_NAMES))] = None,
    stop_bits: StopBitsOpt = 1,
    zvz: ZvzOpt = 0.020,
    modules: Annotated[str | None,
                       typer.Option(callback=addresses_option, metavar="ADDRESSES",
                                    help="Addresses to probe, e.g. 1,3-5 (default 1..30).")] = None,
    exchanges: Annotated[int, typer.Option(min=1, max=1000, metavar="N",
                                           help="Timed exchanges with each module that answers.")] = 10,
    allow_unchecked_probes: Annotated[bool, typer.Option("--allow-unchecked-probes",
                                                         help="Probe in framings without a checksum "
                                                              "(open-driver) without asking (see "
                                                              "docs/commands.md).")] = False,
    lock_timeout: LockOpt = 0.0,
    json_out: Annotated[bool, typer.Option("--json", help=(
        f"Print a {DOCTOR_FORMAT} document: what the line speaks, each module's turnarounds (s), the plant "
        "file's keys."))] = False,
) -> None:
    """Which framing, baud and parity a line speaks, and each module's turnaround, measured."""
    import sys

    from rich.table import Table

    from prc3cfg import api
    from prc3cfg.cli.common import ask
    from prc3cfg.core.line import LineSettings
    from prc3cfg.core.render import plural

    if parity is None and api.default_parity(port) == "none":
        parity = "none"  # a pseudo-terminal carries no other
    tried = api.Search()
    search = api.Search(framings=(framing,) if framing else tried.framings,
                        bauds=(baud,) if baud else tried.bauds,
                        parities=(parity,) if parity else tried.parities, stop_bits=stop_bits)
    bare = api.BareLine(port, "crc16", LineSettings(baud or 9600, 8, parity or "even", stop_bits), zvz=zvz)
    with line_options(None, 0, lock_timeout, json_out=json_out) as options, _said_as_options():

        def allow() -> bool:
            question = ("No module answered in a framing with a checksum. Probe in open-driver, which has "
                        "none? A probe at the "
                        "wrong baud or parity arrives as other bytes, which a module there could take "
                        "for a write")
            return allow_unchecked_probes or (sys.stdin.isatty() and ask(question, options, typed=True))

        found = api.doctor(bare, search, options,
                           addresses=parse_addresses(modules) if modules is not None else None,
                           exchanges=exchanges, allow_unchecked=allow)
    if found.found is None:
        were = "was" if found.skipped_unchecked == 1 else "were"
        skipped = (f"; {plural(found.skipped_unchecked, 'probe')} in open-driver, which has no checksum, "
                   f"{were} not made — "
                   "give --allow-unchecked-probes to make them") if found.skipped_unchecked else ""
        raise UserError(f"{port}: no module answered at any framing, baud and parity tried "
                        f"({plural(found.probes, 'probe')}){skipped} "
                        "— check the wiring, the power and the addresses (--modules)")
    if json_out:
        print_document(_diagnosis(found, exchanges))
        return
    print(f"{port} speaks {found.found.said()} ({plural(len(found.modules), 'module')} answered, after "
          f"{plural(found.probes, 'probe')}).")
    if not found.settings_found:
        print("socket://: the gateway fixes the baud rate and character format, so only the framing was "
              "probed; the baud, "
              "parity and turnarounds shown take --baud and --parity as given.")
    print("Stop bits cannot be probed (a UART checks one): give the gateway's.")
    table = Table("address", "turnaround median", "worst", "answered", "damaged", "lost")
    for timing in found.modules:
        table.add_row(str(timing.address), f"{timing.median * 1000:.1f} ms", f"{timing.worst * 1000:.1f} ms",
                      f"{len(timing.turnarounds)}/{exchanges}", str(timing.damaged), str(timing.lost))
    stdout_console().print(table)
    print("The plant file's keys for this bus:")
    for key, value in found.plant_keys().items():
        print(f"    {key}: {value:g}" if isinstance(value, float) else f"    {key}: {value}")


def _diagnosis(found: "Diagnosis", exchanges: int) -> dict[str, Any]:
    """`doctor --json`'s document: what the line speaks, how each module answered, the plant file's keys."""
    assert found.found is not None  # (a line nothing answered on is an error, said before)
    return {"format": DOCTOR_FORMAT, "port": found.port, "speaks": found.found.said(),
            "settings_found": found.settings_found,
            "probes": found.probes, "skipped_unchecked": found.skipped_unchecked,
            "plant_keys": found.plant_keys(),
            "modules": [{"address": t.address, "turnarounds_s": list(t.turnarounds), "median_s": t.median,
                         "worst_s": t.worst, "exchanges": exchanges, "damaged": t.damaged, "lost": t.lost}
                        for t in found.modules]}
