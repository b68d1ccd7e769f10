"""What CI pays per command: `prc3cfg --help`'s start-up CPU, and the demo's plan + apply on `emulator://`
against the line.

    python bench/startup_bench.py [--runs 20] [--demo-runs 3] [--here]

Measures prc3cfg where a user and a CI job run it: a virtual environment made as the README's first command
makes it (`python -m venv`, `pip install .` from this worktree; in a temporary folder, about 10 s with pip's
cache), its `prc3cfg` console script. `--here` measures `python -m prc3cfg` in this environment instead — a
maintainer's, whose editable install's finder and other .pth files every process pays for at start-up (on
the 2-core machine, 29 November 2026: the interpreter alone 31 ms there, 9 ms in the README's environment).

Prints, medians of the runs (each a subprocess, as CI and the tests run prc3cfg):

- **start-up**: CPU time (user + system) of `python -m prc3cfg --help`, beside the interpreter's own
  start-up in the same environment (`python -c pass`: site-packages' .pth files included) and typer's
  import (`python -c "import typer"`, the floor of any typer command line) — what prc3cfg adds is the
  difference; acceptance: `--help` under 60 ms CPU;
- **CI speed**: wall time of the demo plant (plants/demo-line.yaml) planned, then applied
  (`apply --auto-approve --allow-axis-release`, from factory defaults), in a fresh folder, its buses on
  `emulator://` as written, against the same with each port `emulator://NAME?line-speed=9600`
  (the emulator answers in the time the real line takes: docs/line.md); acceptance: at least 20 times
  faster.

With `--here`, the package's bytecode is written first, as pip writes it at install (with
PYTHONDONTWRITEBYTECODE set and an editable install, every run would compile what it imports: 0.15 s of a
plan). CPU is read from the children's resource usage (POSIX's `resource`): run it on Linux or macOS.
"""

from __future__ import annotations

import argparse
import compileall
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from line_bench import run  # the wall time and output of a command that must succeed

ROOT = Path(__file__).resolve().parent.parent
DEMO = ROOT / "plants" / "demo-line.yaml"


def cpu_ms(command: list[str]) -> float:
    """The CPU time (user + system, ms) of running `command` to its end."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    run(command)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return 1000 * (after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)


@contextmanager
def installed(here: bool) -> Iterator[tuple[str, list[str]]]:
    """The interpreter and the `prc3cfg` command to measure: this environment's (`here`), or those of a
    virtual environment made in a temporary folder as the README's first command makes it."""
    if here:
        # as pip's install does: no module compiled per run
        compileall.compile_dir(ROOT / "prc3cfg", quiet=2)
        yield sys.executable, [sys.executable, "-m", "prc3cfg"]
        return
    with tempfile.TemporaryDirectory() as folder:
        venv = Path(folder) / "venv"
        subprocess.run([sys.executable, "-m", "venv", venv], check=True)
        python = venv / "bin" / "python"
        subprocess.run([python, "-m", "pip", "install", "-q", ROOT], check=True)
        yield str(python), [str(venv / "bin" / "prc3cfg")]


def demo_seconds(command: list[str], line_speed: int | None) -> float:
    """Wall time of the demo's plan, then its apply, by `command`, in a fresh folder (the emulators' state
    starts at factory defaults)."""
    text = DEMO.read_text()
    if line_speed is not None:
        text = re.sub(r"(port: emulator://[\w-]+)", rf"\1?line-speed={line_speed}", text)
    with tempfile.TemporaryDirectory() as folder:
        plant = Path(folder) / "plant.yaml"
        plant.write_text(text)
        start = time.perf_counter()
        run([*command, "plan", str(plant)])
        run([*command, "apply", str(plant), "--auto-approve", "--allow-axis-release"])
        return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20, help="start-up runs of each command")
    parser.add_argument("--demo-runs", type=int, default=3, help="runs of the demo's plan + apply, each way")
    parser.add_argument("--here", action="store_true",
                        help="measure `python -m prc3cfg` in this environment, not in the README's")
    args = parser.parse_args()
    with installed(args.here) as (python, command):
        print(f"measuring {' '.join(command)}")
        measure(python, command, args.runs, args.demo_runs)


def measure(python: str, command: list[str], runs: int, demo_runs: int) -> None:
    bare = statistics.median(cpu_ms([python, "-c", "pass"]) for _ in range(runs))
    typed = statistics.median(cpu_ms([python, "-c", "import typer"]) for _ in range(runs))
    helped = statistics.median(cpu_ms([*command, "--help"]) for _ in range(runs))
    print(f"start-up: prc3cfg --help {helped:.0f} ms CPU (the interpreter alone {bare:.0f} ms, with typer "
          "imported "
          f"{typed:.0f}: prc3cfg adds {helped - bare:.0f}, {helped - typed:.0f} of it its own); "
          f"target under 60 — {'met' if helped < 60 else 'NOT met'}")

    emulated = statistics.median(demo_seconds(command, None) for _ in range(demo_runs))
    line = statistics.median(demo_seconds(command, 9600) for _ in range(demo_runs))
    ratio = line / emulated
    print(f"CI speed: the demo's plan + apply {emulated:.2f} s on emulator://, {line:.2f} s at 9600 baud: "
          f"{ratio:.1f}× "
          f"(target at least 20× — {'met' if ratio >= 20 else 'NOT met'})")


if __name__ == "__main__":
    main()
