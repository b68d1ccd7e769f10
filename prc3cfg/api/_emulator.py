"""An emulated bus: `emulator`, served over TCP (`listen`) or a pseudo-terminal (`open_pty`, `served_pty`).

Turns what the emulator refuses into one-line errors. Does not own the emulator
(`prc3cfg.shell.emulator`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterable, Mapping
from pathlib import Path

from prc3cfg.core.line import LineSettings
from prc3cfg.errors import UserError
from prc3cfg.shell.emulator import ptys
from prc3cfg.shell.emulator.server import IDLE_TIMEOUT, MAX_CONNECTIONS, Emulator, FaultInjection
from prc3cfg.shell.emulator.state import modules_to_serve
from prc3cfg.shell.platform import HAS_PTY


def emulator(modules: Iterable[int] | None = None, *, state: Path | None = None, framing: str = "crc16",
             line: LineSettings = LineSettings(), line_speed: bool = False, zvz: float = 0.020,
             turnaround: float = 0.010,
             turnarounds: Mapping[int, float] | None = None, jitter: float = 0.0, drop_rate: float = 0.0,
             corrupt_rate: float = 0.0,
             seed: int | None = None, max_connections: int | None = None,
             idle_timeout: float | None = None) -> Emulator:
    """A bus emulator (`prc3cfg emulator serve`), serving nothing yet (`listen`, `open_pty`): the
    modules at `modules` — else those of the `state` file, else 1-30 — as `state` holds them, every
    write it accepts saved there; closed on leaving its `with`. `turnarounds`: some modules' own
    turnaround instead of `turnaround`; `jitter`: each turnaround shifted by up to ± this (seeded by
    `seed`). Settings it refuses: `UserError`."""
    served, unserved = modules_to_serve(state, sorted(modules) if modules is not None else None)
    try:
        return Emulator(
            served, framing=framing, zvz=zvz, turnaround=turnaround, turnarounds=turnarounds, jitter=jitter,
                        line_speed=line_speed, line=line,
            faults=FaultInjection(drop_rate, corrupt_rate, seed), state_path=state, unserved=unserved,
            max_connections=MAX_CONNECTIONS if max_connections is None else max_connections,
            idle_timeout=IDLE_TIMEOUT if idle_timeout is None else idle_timeout,
        )
    except ValueError as error:
        raise UserError(f"emulator: {error}") from None


def listen(running: Emulator, host: str, port: int, *, rfc2217: bool = False) -> tuple[str, int]:
    """Serve `running` to TCP clients at HOST:PORT (0: any free port) — speaking RFC 2217 if asked (a
    client at other line settings then gets what a UART would make of its bytes); the address it listens at.
    """
    try:
        return running.listen(host, port, rfc2217=rfc2217)
    except OSError as error:  # the reason, without the "(while attempting to bind …)" Python adds
        reason = str(error.strerror or error).partition(" (while attempting")[0]
        raise UserError(f"--listen {host}:{port}: cannot listen ({reason}) — choose a free port on an "
                        "address of this host") from None


def served_pty(path: str, modules: Iterable[int]) -> contextlib.AbstractContextManager[None]:
    """While it runs, `prc3cfg ports` lists the pseudo-terminal at `path` as this process's emulator of
    `modules`."""
    return ptys.served(path, modules)


def open_pty(running: Emulator) -> str:
    """Serve `running` on a new pseudo-terminal too; its path."""
    if not HAS_PTY:
        raise UserError("--pty: Windows has no pseudo-terminals — serve over TCP (--listen HOST:PORT) and "
                        "use socket://HOST:PORT")
    try:
        return running.open_pty()
    except OSError as error:
        raise UserError(f"--pty: cannot open a pseudo-terminal ({error.strerror or error})") from None
