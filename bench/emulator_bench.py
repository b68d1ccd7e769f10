"""The embedded emulator in CI: an apply through `emulator://` against the line it stands for.

    python bench/emulator_bench.py [--modules 30] [--buses 8] [--framing crc16] [--runs 3]

Each run is `prc3cfg apply PLANT --auto-approve --allow-axis-release` (a subprocess) of a
plant commissioned from factory defaults, in a fresh temporary folder: every module gets
new system parameters (an axis release), 32 programs and two chains, and its other
programs reset. Prints, medians of `--runs`:

- **persistence**: one bus of `--modules` modules through `emulator://`, which keeps its
  state file (and the journal beside it), against the same apply with emulators that keep
  no state file (the same command, run through a wrapper that builds the in-process
  emulators without a state path); acceptance: at most 1.3;
- **against the real line**: `--buses` buses of `--modules` modules through `emulator://`
  against the time the real line would take — every exchange of the apply's journal (the
  read-back, the plan's writes, the verification) priced at 9600 baud 8E1 by docs/line.md's cost
  model (beside the plan's own estimated bus time of its writes, from `plan --json`);
  acceptance: at least 10 times faster. Two figures for the real line: summed over the
  buses, as the plan file sums its estimate, and the slowest bus alone, as buses are
  separate lines that apply runs in parallel. The apply's phases (from its journal) show
  where the emulator:// time goes.

Wall times include each command's start-up (imports, about 0.3 s), reported separately.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from collections import defaultdict
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from line_bench import run  # the wall time and output of a command that must succeed

from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.line import LineSettings
from prc3cfg.shell.emulator.bus import BROADCAST

PLANT = """\
plant: emulator-bench
buses:
{buses}"""
BUS = """\
  - name: line-{bus}
    port: emulator://bench-{bus}
    framing: {framing}
    modules:
{modules}"""
MODULE = """\
      - address: {address}
        name: m{bus}-{address}
        unmanaged_programs: reset
        system: {{upper_reversing_point: 2.000, max_speed: 0.500}}
        programs:
{programs}
        chains: [[1, 2, 3, 4], {{programs: [10, 11], loop: true}}]
"""
PROGRAMS = "\n".join(f"          {n}: "
                     f"{{position: {0.5 + n / 100:.3f}, speed: 0.{200 + n:03d}, dwell: {n % 7}.5}}"
                     for n in range(1, 33))
#: `prc3cfg` whose in-process emulators keep no state file: the apply without persistence.
WITHOUT_STATE_FILE = (
    "import prc3cfg.shell.link.ports as ports\n"
    "from prc3cfg.cli import main\n"
    "Emulator = ports.Emulator\n"
    "ports.Emulator = lambda *args, **options: Emulator(*args, **{**options, 'state_path': None})\n"
    "main()\n"
)
REAL_LINE = LineSettings(baud=9600, parity="even")
READS = ("50", "51", "52")  # message IDs of reads, in hex
TURNAROUND, ZVZ = 0.010, 0.020


def write_plant(folder: Path, buses: int, modules: int, framing: str) -> Path:
    plant = folder / "plant.yaml"
    text = "".join(
        BUS.format(bus=b, framing=framing,
                   modules="".join(MODULE.format(bus=b, address=a, programs=PROGRAMS)
                                   for a in range(1, modules + 1)))
        for b in range(1, buses + 1)
    )
    plant.write_text(PLANT.format(buses=text))
    return plant


@dataclass
class Applied:
    wall: float  # s, the apply command
    line: dict[str, float]  # bus → s its exchanges take on the real line
    planned: float  # s, the plan's estimated bus time (its writes, all buses)
    phases: dict[str, float]  # s of the apply, from its start: to the first exchange, read-back, planning, …


def apply(prc3cfg: list[str], buses: int, modules: int, framing: str, *, estimate: bool = False) -> Applied:
    """One apply from factory defaults in a fresh folder (after `plan --json`, with `estimate`)."""
    with tempfile.TemporaryDirectory() as work:
        plant = write_plant(Path(work), buses, modules, framing)
        planned = (json.loads(run([*prc3cfg, "plan", str(plant), "--json"])[1])["estimated_bus_time_s"]
                   if estimate else 0.0)
        started = time.time()
        wall, _ = run([*prc3cfg, "apply", str(plant), "--auto-approve", "--allow-axis-release"])
        (journal,) = (Path(work) / ".prc3cfg" / "journal").iterdir()
        exchanges = [r for r in map(json.loads, journal.read_text().splitlines()) if r["event"] == "exchange"]
    cost = LineCost.of(framing, REAL_LINE, TURNAROUND, ZVZ)
    line: dict[str, float] = defaultdict(float)
    for record in exchanges:
        message = codec.decode_message(bytes.fromhex(record["request"]))
        address = record["address"]
        line[record["bus"]] += (cost.broadcast_time(message) if address == BROADCAST
                                else cost.message_time(address, message))
    return Applied(wall, dict(line), planned, phases(exchanges, started, wall))


def phases(exchanges: list[dict], started: float, wall: float) -> dict[str, float]:
    """Seconds of an apply by phase, from the times its journal gives each exchange (when it ended)."""
    ends = [datetime.fromisoformat(r["time"]).timestamp() - started for r in exchanges]
    writes = [i for i, r in enumerate(exchanges) if not r["request"].startswith(READS)]
    first, last = writes[0], writes[-1]
    return {"start": ends[0] - exchanges[0]["duration_s"], "read-back": ends[first - 1],
            "planning": ends[first],
            "writes": ends[last], "verification": ends[-1], "end": wall}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--modules", type=int, default=30)
    parser.add_argument("--buses", type=int, default=8)
    parser.add_argument("--framing", default="crc16")
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    prc3cfg = [sys.executable, "-m", "prc3cfg"]
    without_state = [sys.executable, "-c", WITHOUT_STATE_FILE]
    startup = statistics.median(run([*prc3cfg, "--help"])[0] for _ in range(args.runs))
    print(f"{args.framing}, runs {args.runs} (medians); command start-up {startup:.2f} s (included below)")

    kept = statistics.median(apply(prc3cfg, 1, args.modules, args.framing).wall for _ in range(args.runs))
    bare = statistics.median(apply(without_state, 1, args.modules, args.framing).wall
                             for _ in range(args.runs))
    print(f"  persistence, 1 bus × {args.modules} modules: with the state file {kept:6.2f} s   without "
          f"{bare:6.2f} s"
          f"   ratio {kept / bare:.2f} (acceptance ≤ 1.3; without start-up "
          f"{(kept - startup) / (bare - startup):.2f})")

    runs = [apply(prc3cfg, args.buses, args.modules, args.framing, estimate=n == 0) for n in range(args.runs)]
    wall = statistics.median(r.wall for r in runs)
    summed, slowest = sum(runs[0].line.values()), max(runs[0].line.values())
    print(f"  real line, {args.buses} buses × {args.modules} modules: emulator:// {wall:6.2f} s; at "
          f"{REAL_LINE.baud} baud 8E1 "
          f"{summed:.2f} s summed over the buses (the plan's estimate {runs[0].planned:.2f} s + read-backs "
          f"{summed - runs[0].planned:.2f} s), {slowest:.2f} s on the slowest bus")
    print(f"    {summed / wall:.1f}× faster than the buses summed, {slowest / wall:.1f}× than the slowest "
          "bus (acceptance ≥ 10)")
    middle = sorted(runs, key=lambda r: r.wall)[len(runs) // 2]
    marks = list(middle.phases.items())
    print("    where the time goes: "
          + ", ".join(f"{name} {end - (marks[i - 1][1] if i else 0):.2f} s"
                      for i, (name, end) in enumerate(marks)))


if __name__ == "__main__":
    main()
