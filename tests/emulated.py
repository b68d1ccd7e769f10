"""Test support: the demo plant on real emulators behind socket:// (`prc3cfg.shell.testing`, as plant
repositories use it), reached through a lossy proxy where a test says, and the CLI run in-process."""

from __future__ import annotations

import contextlib
import subprocess
import threading
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import pytest
from lossy import LossyProxy, Rule

from prc3cfg.cli import main
from prc3cfg.shell.emulator.server import FaultInjection
from prc3cfg.shell.testing import EmulatedPlant, emulate

DEMO = Path(__file__).resolve().parent.parent / "plants" / "demo-line.yaml"


@contextlib.contextmanager
def emulated_plant(
    directory: Path, *, faults: FaultInjection = FaultInjection(), timeout: float = 0.1,
                   framing: str = "crc16",
    line_speed: bool = False, source: Path = DEMO, lossy: dict[str, Rule] | None = None, zvz: float = 0.020,
    unlisted: dict[str, list[int]] | None = None, **bus_settings: object,
) -> Iterator[EmulatedPlant]:
    """`source` with every bus on an emulator (factory-default modules) via socket:// as `plant.yaml`
    in `directory`; a bus named in `lossy` is reached through a `LossyProxy` with that rule;
    `bus_settings` (`parity="none"`, …) are written into every bus."""
    with contextlib.ExitStack() as stack:

        def route(bus: str, host: str, port: int) -> str:
            if lossy and bus in lossy:
                proxy = LossyProxy((host, port), lossy[bus], framing=framing, zvz=zvz)
                return stack.enter_context(proxy).listen()
            return f"socket://{host}:{port}"

        emulated = stack.enter_context(emulate(source, directory, faults=faults, line_speed=line_speed,
                                               route=route,
                                               unlisted=unlisted, timeout=timeout, framing=framing, zvz=zvz,
                                               **bus_settings))
        yield emulated


@dataclass
class Result:
    code: int
    out: str
    err: str

    @property
    def problems(self) -> list[str]:
        """stderr without its notes (a busy test machine can make a line repeat an exchange)."""
        return [line for line in self.err.splitlines() if not line.startswith("note: ")]


#: The heading of an account's reference-travel list (`render.TRAVEL`, without its sign).
TRAVEL = "Travel to reference point required before production on:"
#: The heading of a plan's list of the modules it releases (`render.AXIS_HEADING`, without its sign).
PLANNED_TRAVEL = "Travel to reference point required after apply on:"


def travel_list(out: str, heading: str = TRAVEL) -> str:
    """What an account's reference-travel lists say (a plan's, given its `heading`), on one line ("" where
    there is none): each heading with the indented lines of modules under it (`render.listed` wraps them),
    and each earlier release's line."""
    said, lines = [], out.splitlines()
    for at, line in enumerate(lines):
        if heading in line:
            block = [line]
            for following in lines[at + 1 :]:
                if not following.startswith("    "):
                    break
                block.append(following.strip())
            said.append(" ".join(block))
    return " ".join(said)


def signal_once_every_line_writes(trace: TextIO, process: subprocess.Popen, buses: Iterable[str],
                                  signum: int) -> None:
    """Read `process`'s frame trace (the FIFO its `--trace` writes) until a first write has gone out on every
    one of `buses`, then send it `signum` — synchronised on what the process traced, never on time — and read
    the rest of the trace in the background, so that the process never waits on it."""
    writing: set[str] = set()
    for line in trace:
        _, bus, direction, frame = line.rstrip("\n").split("\t")[:4]
        # a crc16 request (A5h, address, length, ID): a write
        if direction == ">" and int(frame[6:8], 16) < 0x50:
            writing.add(bus)
        if writing == set(buses):
            process.send_signal(signum)
            break
    threading.Thread(target=trace.read, daemon=True).start()


def read_next(path: Path) -> dict[str, tuple[int, ...]]:
    """By module name, the programs the next plan of the plant file at `path` reads (not `--full-read`): what
    the change needs, and what rolling evidence adds (`what_to_read.rolling`) — as the lines' records stand.
    """
    from prc3cfg.api._plan import reads, select  # what a plan reads, worked out as the plan does
    from prc3cfg.shell.plant_files import load_plant

    plant = load_plant(path)
    names = {(b.name, m.address): m.name for b, m in plant.modules()}
    return {names[(t.bus, t.address)]: t.programs for t in reads(plant, select(plant)).targets}


def run_cli(capsys: pytest.CaptureFixture, *args: str) -> Result:
    """Run `prc3cfg ARGS` in this process, as the console script does."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        main([str(a) for a in args])
    captured = capsys.readouterr()
    code = exit_info.value.code
    return Result(0 if code is None else int(code), captured.out, captured.err)
