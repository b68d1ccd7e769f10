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
  read-back, the plan's writes, the verification) priced at 9600 baud 8E1 by link.md's cost
  model; buses are separate lines and run in parallel, so the real line takes as long as
  its slowest bus; acceptance: at least 10 times faster.

Wall times include each command's start-up (imports, about 0.3 s), reported separately.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

from prc3cfg import codec
from prc3cfg.bustime import LineCost
from prc3cfg.line import LineSettings

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
PROGRAMS = "\n".join(f"          {n}: {{position: {0.5 + n / 100:.3f}, speed: 0.{200 + n:03d}, dwell: {n % 7}.5}}" for n in range(1, 33))
#: `prc3cfg` whose in-process emulators keep no state file: the apply without persistence.
WITHOUT_STATE_FILE = (
    "import prc3cfg.link.ports as ports\n"
    "from prc3cfg.cli import main\n"
    "Emulator = ports.Emulator\n"
    "ports.Emulator = lambda *args, **options: Emulator(*args, **{**options, 'state_path': None})\n"
    "main()\n"
)
REAL_LINE = LineSettings(baud=9600, parity="even")
TURNAROUND, ZVZ = 0.010, 0.020


def write_plant(folder: Path, buses: int, modules: int, framing: str) -> Path:
    plant = folder / "plant.yaml"
    text = "".join(
        BUS.format(bus=b, framing=framing, modules="".join(MODULE.format(bus=b, address=a, programs=PROGRAMS) for a in range(1, modules + 1)))
        for b in range(1, buses + 1)
    )
    plant.write_text(PLANT.format(buses=text))
    return plant


def timed(command: list[str]) -> float:
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        sys.exit(f"{' '.join(command[:3])} … failed (exit {done.returncode}):\n{done.stdout}\n{done.stderr}")
    return elapsed


def apply(prc3cfg: list[str], buses: int, modules: int, framing: str) -> tuple[float, dict[str, float]]:
    """One apply from factory defaults in a fresh folder: its wall time, and each bus's time on the real line."""
    with tempfile.TemporaryDirectory() as work:
        plant = write_plant(Path(work), buses, modules, framing)
        wall = timed([*prc3cfg, "apply", str(plant), "--auto-approve", "--allow-axis-release"])
        (journal,) = (Path(work) / ".prc3cfg" / "journal").iterdir()
        cost = LineCost.of(framing, REAL_LINE, TURNAROUND, ZVZ)
        line: dict[str, float] = defaultdict(float)
        for record in map(json.loads, journal.read_text().splitlines()):
            if record["event"] == "exchange":
                message = codec.decode_message(bytes.fromhex(record["request"]))
                line[record["bus"]] += cost.message_time(record["address"], message)
        return wall, dict(line)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--modules", type=int, default=30)
    parser.add_argument("--buses", type=int, default=8)
    parser.add_argument("--framing", default="crc16")
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    prc3cfg = [sys.executable, "-m", "prc3cfg"]
    without_state = [sys.executable, "-c", WITHOUT_STATE_FILE]
    startup = statistics.median(timed([*prc3cfg, "--help"]) for _ in range(args.runs))
    print(f"{args.framing}, runs {args.runs} (medians); command start-up {startup:.2f} s (included below)")

    kept = statistics.median(apply(prc3cfg, 1, args.modules, args.framing)[0] for _ in range(args.runs))
    bare = statistics.median(apply(without_state, 1, args.modules, args.framing)[0] for _ in range(args.runs))
    print(f"  persistence, 1 bus × {args.modules} modules: with the state file {kept:6.2f} s   without {bare:6.2f} s"
          f"   ratio {kept / bare:.2f} (acceptance ≤ 1.3; without start-up {(kept - startup) / (bare - startup):.2f})")  # fmt: skip

    runs = [apply(prc3cfg, args.buses, args.modules, args.framing) for _ in range(args.runs)]
    wall = statistics.median(w for w, _ in runs)
    per_bus = runs[0][1]
    real = max(per_bus.values())
    print(f"  real line, {args.buses} buses × {args.modules} modules: emulator:// {wall:6.2f} s   real line {real:7.2f} s"
          f" (slowest bus at {REAL_LINE.baud} baud 8E1; {sum(per_bus.values()):.2f} s summed over buses)"
          f"   {real / wall:.1f}× faster (acceptance ≥ 10)")  # fmt: skip


if __name__ == "__main__":
    main()
