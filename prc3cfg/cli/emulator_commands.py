"""`prc3cfg emulator serve`: run a bus emulator until SIGINT/SIGTERM (docs/commands.md) — made and
served by the API (`prc3cfg.api.emulator`); here, its options and what it prints."""


import contextlib
import signal
import threading
from pathlib import Path
from typing import Annotated

import typer

from prc3cfg.cli import emulator_app
from prc3cfg.cli.common import (
    FRAMING_NAMES,
    PARITY_NAMES,
    STOP_BITS,
    addresses_option,
    frame_data_bits,
    one_of,
    parse_addresses,
)
from prc3cfg.cli.durations import TIMES, duration, parse_duration

DEFAULT_LISTEN = "127.0.0.1:7001"


def parse_listen(text: str) -> tuple[str, int]:
    """HOST:PORT (":PORT": 127.0.0.1); ValueError, with an example, for anything else — "" too."""
    host, sep, port = text.rpartition(":")
    if not sep or not port.isascii() or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ValueError(f"'{text}' is not HOST:PORT — for example {DEFAULT_LISTEN}")
    return host or "127.0.0.1", int(port)


def parse_module_turnaround(text: str) -> tuple[list[int], float]:
    """ADDRESSES=TIME ("3-5=40ms") → ([3, 4, 5], 0.04); ValueError, with an example, for anything else."""
    addresses, sep, time = text.partition("=")
    if not sep:
        raise ValueError(f"'{text}' is not ADDRESSES=TIME — for example 3-5=40ms")
    seconds = parse_duration(time)
    if not 0 <= seconds <= 10:
        raise ValueError(f"'{time}' is not a turnaround of 0..10 s")
    return parse_addresses(addresses), seconds


def module_turnarounds_option(values: list[str] | None) -> list[str] | None:
    """`--module-turnaround`'s callback: what `parse_module_turnaround` cannot read is a usage error (exit
    64)."""
    for value in values or ():
        try:
            parse_module_turnaround(value)
        except ValueError as error:
            raise typer.BadParameter(str(error)) from None
    return values


def listen_option(value: str | None) -> str | None:
    """`--listen`'s callback: what `parse_listen` cannot read is a usage error (exit 64)."""
    if value is not None:
        try:
            parse_listen(value)
        except ValueError as error:
            raise typer.BadParameter(str(error)) from None
    return value


@emulator_app.command("serve")
def serve(
    listen: Annotated[str | None,
                      typer.Option(callback=listen_option, metavar="HOST:PORT",
                                   help="HOST:PORT to accept TCP connections on "
                                        "(socket://HOST:PORT).")] = None,
    pty: Annotated[bool, typer.Option("--pty", help="Also serve a pseudo-terminal and print "
                                                    "its path.")] = False,
    rfc2217: Annotated[bool, typer.Option("--rfc2217",
                                          help="The TCP port speaks RFC 2217 (rfc2217://HOST:PORT), as "
                                               "ser2net's telnet(rfc2217): frames at the client's other "
                                               "baud or character format arrive as a UART "
                                               "receives them.")] = False,
    state: Annotated[Path | None,
                     typer.Option(metavar="FILE",
                                  help="State file (prc3-emulator/1): loaded, every accepted write saved "
                                       "before it is answered (in its journal FILE.journal while running), "
                                       "all of it on exit.")] = None,
    modules: Annotated[str | None,
                       typer.Option(callback=addresses_option, metavar="ADDRESSES",
                                    help="Module addresses to serve, e.g. 1,3-5 (default: the state file's, "
                                         "else 1-30).")] = None,
    framing: Annotated[str, typer.Option(callback=one_of(FRAMING_NAMES), metavar="FRAMING",
                                         help=f"Framing: {' | '.join(FRAMING_NAMES)}.")] = "crc16",
    line_speed: Annotated[int | None,
                          typer.Option("--line-speed", min=1, max=10_000_000, metavar="BAUD",
                                       help="Make every exchange take as long as on a line of this "
                                            "baud rate.")] = None,
    parity: Annotated[str | None,
                      typer.Option(callback=one_of(PARITY_NAMES), metavar="PARITY",
                                   show_default="even; none with --pty",
                                               help=f"{' | '.join(PARITY_NAMES)} (character time, and "
                                                    "framing time-outs; a pseudo-terminal "
                                                    "carries none).")] = None,
    data_bits: Annotated[int, typer.Option(callback=frame_data_bits, metavar="BITS",
                                           help="8: a PRC 3 frame is binary")] = 8,
    stop_bits: Annotated[float, typer.Option(callback=one_of(STOP_BITS), metavar="BITS",
                                             help=" | ".join(map(str, STOP_BITS)))] = 1,
    zvz: Annotated[float, typer.Option(parser=duration(0.001, 65.535), metavar="TIME",
                                       help=f"open-driver end-of-frame gap ({TIMES}).")] = 0.020,
    turnaround: Annotated[float, typer.Option(parser=duration(0, 10), metavar="TIME",
                                              help="Module turnaround, with --line-speed "
                                                   f"({TIMES}).")] = 0.010,
    module_turnaround: Annotated[list[str] | None,
                                 typer.Option("--module-turnaround", callback=module_turnarounds_option,
                                              metavar="ADDRESSES=TIME",
                                                                help="These modules' turnaround instead, "
                                                                     "e.g. 3-5=40ms; repeatable.")] = None,
    jitter: Annotated[float, typer.Option(parser=duration(0, 10), metavar="TIME",
                                          help="Each exchange's turnaround shifted by up to ± this, with "
                                               f"--line-speed ({TIMES}; seeded by --seed).")] = 0.0,
    drop_rate: Annotated[float, typer.Option(min=0, max=1, metavar="FRACTION",
                                             help="Fraction of exchanges lost (request or reply).")] = 0.0,
    corrupt_rate: Annotated[float, typer.Option(min=0, max=1, metavar="FRACTION",
                                                help="Fraction of exchanges with one bit flipped.")] = 0.0,
    seed: Annotated[int | None,
                    typer.Option(metavar="N", help="Seed for fault injection and jitter.")] = None,
    max_connections: Annotated[int | None,
                               typer.Option("--max-connections", min=1, max=100_000, metavar="N",
                                            help="TCP clients served at once (default 1: one client per "
                                                 "line, as ser2net); one more is closed at once "
                                                 "(logged).")] = None,
    idle_timeout: Annotated[float | None,
                            typer.Option("--idle-timeout", parser=duration(0.001, 10_000_000), metavar="TIME",
                                         help=f"Close a TCP connection that sends nothing for this long "
                                              f"({TIMES}; default 300).")] = None,
    verbose: Annotated[bool,
                       typer.Option("--verbose", help="Also log connections, discarded bytes and injected "
                                                      "faults.")] = False,
) -> None:
    """Run a PRC 3 bus emulator until SIGINT or SIGTERM (exit 0).

    Serves the modules of --modules, else those of the state file, else
    1-30. The state file keeps the modules it holds that are not served.

    One TCP client is served at a time (--max-connections raises it), as a gateway serves one client per
    serial line; one more is closed at once. A client that sends nothing for --idle-timeout seconds is
    disconnected. Running out of file descriptors only pauses accepting.

    A write is answered only once it is saved: appended to the journal
    beside --state and flushed to disk, so a killed emulator loses no
    acknowledged write (the next start replays the journal). The state file
    takes everything on exit, at a start after a kill, and after every
    1000 journal lines. When a write cannot be saved, the error is logged, the module
    keeps its state and the write gets no reply: the master repeats it.
    Warnings and errors are logged on stderr.
    """
    import logging  # the server's log: only where it serves

    from prc3cfg import api
    from prc3cfg.core.line import LineSettings

    logging.basicConfig(level=logging.INFO if verbose else logging.WARNING,
                        format="%(asctime)s %(levelname)s %(message)s")
    if parity is None:  # as scan and import take a pseudo-terminal: without parity
        parity = "none" if pty else "even"
    turnarounds = {address: seconds for value in module_turnaround or ()
                   for addresses, seconds in [parse_module_turnaround(value)]
                   for address in addresses}
    emulator = api.emulator(
        parse_addresses(modules) if modules is not None else None, state=state, framing=framing, zvz=zvz,
                            turnaround=turnaround,
        turnarounds=turnarounds, jitter=jitter, line_speed=line_speed is not None,
        line=LineSettings(baud=line_speed or 9600, data_bits=data_bits, parity=parity, stop_bits=stop_bits),
        drop_rate=drop_rate, corrupt_rate=corrupt_rate, seed=seed, max_connections=max_connections,
                            idle_timeout=idle_timeout,
    )
    # The API imports each name the first time it is asked for: the ones serving uses are taken now,
    # as a server that later runs out of file descriptors could not import them then.
    listen_on, open_pty, served_pty, wait_for = api.listen, api.open_pty, api.served_pty, api.wait_for
    stop = threading.Event()
    with emulator:
        address = None
        if listen is not None or not pty:
            address = listen_on(emulator, *parse_listen(DEFAULT_LISTEN if listen is None else listen),
                                rfc2217=rfc2217)
        path = open_pty(emulator) if pty else None
        # started: a signal stops it (until now, it was interrupted) — from before it says so, which
        # is what a script waits for before it may stop it
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, lambda *_: stop.set())
        if address is not None:
            print(f"listening on {address[0]}:{address[1]} "
                  f"({framing}{', rfc2217' if rfc2217 else ''}, modules "
                  f"{', '.join(map(str, sorted(emulator.modules())))})", flush=True)
        # prc3cfg ports lists the pty from before its path is printed, which is what a script waits for
        with served_pty(path, emulator.modules()) if path is not None else contextlib.nullcontext():
            if path is not None:
                print(f"pty: {path}", flush=True)
            wait_for(stop)  # a signal's handler runs meanwhile, on Windows too
