"""How long validating the 30-module example plant takes: the median of several runs.

    python bench/validate_bench.py [PLANT] [--runs N]

Prints two figures: `load_plant` in this process (read, YAML, models, profiles, rules),
after one warm-up run that pays for imports and pydantic's schema building; and the whole
command `python -m prc3cfg validate PLANT` in a fresh process, imports included.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from prc3cfg.shell.plant_files import load_plant

EXAMPLE = Path(__file__).parents[1] / "plants" / "examples" / "coating-line.yaml"


def median_seconds(run: Callable[[], object], runs: int) -> tuple[float, float, float]:
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return statistics.median(times), min(times), max(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("plant", nargs="?", type=Path, default=EXAMPLE)
    parser.add_argument("--runs", type=int, default=15)
    args = parser.parse_args()
    modules = len(load_plant(args.plant).modules())
    command = [sys.executable, "-m", "prc3cfg", "validate", str(args.plant)]
    figures = {
        "load_plant": median_seconds(lambda: load_plant(args.plant), args.runs),
        "prc3cfg validate": median_seconds(lambda: subprocess.run(command, check=True, capture_output=True),
                                           max(3, args.runs // 3)),
    }
    print(f"{args.plant.name}: {modules} modules")
    for name, (median, low, high) in figures.items():
        print(f"  {name:<17} median {median * 1000:6.1f} ms  (min {low * 1000:.1f}, max {high * 1000:.1f})")


if __name__ == "__main__":
    main()
