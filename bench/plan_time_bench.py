"""`plan --actual` of the largest plant: 8 buses × 30 fully managed modules, every program changed.

    python bench/plan_time_bench.py [--runs 3] [--keep DIR] [--worst] [--one-profile]

Writes, in a temporary folder (or DIR), a plant file of 8 buses × 30 modules, each with
`unmanaged_programs: reset`, a system block and 64 programs of position, speed, dwell and
relative_speed in flow mappings, every module's values its own (about 1.3 MB), and a
`read --json` images file in which every program differs from the plant's. Then prints
- each command in a fresh process — the package's bytecode compiled first, as pip compiles it at
  install (with PYTHONDONTWRITEBYTECODE, an editable install compiles every module at every run:
  0.08 s of `plan`) — `prc3cfg validate`, `prc3cfg plan --actual` with human,
  `--json` and `--markdown` output — its wall time, CPU time and peak memory (max RSS, MiB), the
  median of RUNS (acceptance, issue 11: plan ≤ 4 s wall and < 100 MB on a 2-core machine),
  and `prc3cfg --help` as the installed script (acceptance: ≤ 150 ms);
- where the time of `plan` goes, in this process after a warm-up that pays for imports:
  loading the plant, loading the images, planning, and rendering each output.

`--one-profile` also plans, with `plan --actual` in a fresh process (CPU time and max RSS: the
machine may be shared, so CPU, not wall, is the figure), 32 buses × 30 modules that all take one
profile (a system block and 64 programs): commissioned from factory images — modules alike, one
search per line — and from images in which every module holds programs of its own (issue 21:
under 10 s CPU and 150 MiB). Every line is full, so broadcasts are searched for on each.

`--worst` also validates files at the plant file's limits (`prc3cfg.plant.document`,
`loader`): the largest valid plant (every field of every program written out), and hostile
files that reach the node limit, the part limit and the problem limit; each line says what
`validate` answered, its wall time and its max RSS (the limits' promise: a few seconds, well
under 200 MB).
"""

from __future__ import annotations

import argparse
import compileall
import json
import random
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from prc3cfg import api
from prc3cfg.core import plan_file, render
from prc3cfg.core.image import DEFAULT_SYSTEM, PROGRAM_NUMBERS, ModuleImage, Program
from prc3cfg.plant.document import MAX_NODES
from prc3cfg.plant.loader import MAX_PART_NODES

BUSES, MODULES = 8, 30
SYSTEM = replace(DEFAULT_SYSTEM, S1=2000, S4=500)
PROGRAM = "{{position: {P:.3f}, speed: {V:.3f}, dwell: {T:.1f}, relative_speed: {Vr:.3f}}}"
FULL_PROGRAM = ("{{position: {P:.3f}, speed: {V:.3f}, dwell: {T:.1f}, relative_speed: {Vr:.3f}, "
                "f1: {{action: set, distance: 0.010}}, f2: {{action: reset, distance: 0.050}}, next: {next}}}")


def write_plant(folder: Path, program: str = PROGRAM) -> tuple[Path, Path]:
    """The plant file and an images file in which every program differs; their paths."""
    rnd = random.Random(1)
    text, images = ["plant: big\nbuses:\n"], []
    for b in range(BUSES):
        text.append(f"  - name: bus{b}\n    port: socket://127.0.0.1:{7000 + b}\n    modules:\n")
        for address in range(1, MODULES + 1):
            programs = "".join(
                f"          {n}: " + program.format(P=rnd.randrange(100, 1900) / 1000, V=rnd.randrange(20, 480) / 1000,
                                                    T=rnd.randrange(0, 50) / 10, Vr=rnd.randrange(-50, 50) / 1000,
                                                    next=n % 64 + 1) + "\n"
                for n in PROGRAM_NUMBERS
            )
            text.append(f"      - address: {address}\n        name: b{b}m{address}\n        unmanaged_programs: reset\n"
                        f"        system: {{upper_reversing_point: 2.000, max_speed: 0.500}}\n        programs:\n{programs}")
            held = tuple(Program(P=rnd.randrange(100, 1900), V=rnd.randrange(20, 480), T=rnd.randrange(0, 50))
                         for _ in PROGRAM_NUMBERS)
            images.append({"bus": f"bus{b}", **ModuleImage(address, SYSTEM, held).to_json()})
    plant, actual = folder / "plant.yaml", folder / "actual.json"
    plant.write_text("".join(text))
    actual.write_text(json.dumps(images))
    return plant, actual


ONE_PROFILE_BUSES = 32


def write_one_profile_plant(folder: Path) -> tuple[Path, Path, Path]:
    """A plant of 32 × 30 modules taking one profile, factory images, images of programs of their own."""
    rnd = random.Random(2)
    programs = "".join(f"      {n}: " + PROGRAM.format(P=rnd.randrange(100, 1900) / 1000, V=rnd.randrange(20, 480) / 1000,
                                                      T=rnd.randrange(0, 50) / 10, Vr=0) + "\n"
                       for n in PROGRAM_NUMBERS)  # fmt: skip
    text = ["plant: one-profile\nprofiles:\n  line:\n    unmanaged_programs: reset\n",
            f"    system: {{upper_reversing_point: 2.000, max_speed: 0.500}}\n    programs:\n{programs}buses:\n"]
    factory, own = [], []
    for b in range(ONE_PROFILE_BUSES):
        text.append(f"  - name: bus{b}\n    port: socket://127.0.0.1:{7000 + b}\n    modules:\n")
        for address in range(1, MODULES + 1):
            text.append(f"      - {{address: {address}, name: b{b}m{address}, profiles: line}}\n")
            factory.append({"bus": f"bus{b}", **ModuleImage.factory(address).to_json()})
            held = tuple(Program(P=rnd.randrange(100, 1900), V=rnd.randrange(20, 480), T=rnd.randrange(0, 50)) for _ in PROGRAM_NUMBERS)
            own.append({"bus": f"bus{b}", **replace(ModuleImage.factory(address), programs=held).to_json()})
    plant, commissioning, drifted = folder / "one-profile.yaml", folder / "factory.json", folder / "own.json"
    plant.write_text("".join(text))
    commissioning.write_text(json.dumps(factory))
    drifted.write_text(json.dumps(own))
    return plant, commissioning, drifted


@dataclass(frozen=True)
class Run:
    wall: float
    cpu: float
    rss_mb: float
    said: str  # the first line of stderr, else of stdout


#: Runs a command and prints its wall and CPU seconds, max RSS (KiB) and exit code. A small
#: process of its own: Linux counts, in a child's max RSS, its parent's RSS at the fork.
_MEASURE = """
import json, os, subprocess, sys, time
out, err, *command = sys.argv[1:]
with open(out, "wb") as o, open(err, "wb") as e:
    start = time.perf_counter()
    _, status, usage = os.wait4(subprocess.Popen(command, stdout=o, stderr=e).pid, 0)
print(json.dumps([time.perf_counter() - start, usage.ru_utime + usage.ru_stime, usage.ru_maxrss,
                  os.waitstatus_to_exitcode(status)]))
"""


def run_process(command: list[str], ok: tuple[int, ...] = (0,)) -> Run:
    """One fresh process: wall and CPU seconds, max RSS, what it said first."""
    with tempfile.TemporaryDirectory() as folder:
        out, err = Path(folder, "out"), Path(folder, "err")
        measured = subprocess.run([sys.executable, "-c", _MEASURE, str(out), str(err), *command],
                                  check=True, capture_output=True, text=True)
        wall, cpu, rss_kib, code = json.loads(measured.stdout)
        said = (err.read_bytes()[:4000] or out.read_bytes()[:4000]).decode(errors="replace").partition("\n")[0]
    if code not in ok:
        sys.exit(f"{' '.join(command)} ended with {code}: {said}")
    return Run(wall, cpu, rss_kib / 1024, said)


def median_run(command: list[str], runs: int, ok: tuple[int, ...] = (0,)) -> Run:
    results = [run_process(command, ok) for _ in range(runs)]
    return Run(*(statistics.median(getattr(r, f) for r in results) for f in ("wall", "cpu", "rss_mb")), results[0].said)


def timed(run: Callable[[], object]) -> tuple[float, object]:
    start = time.perf_counter()
    result = run()
    return time.perf_counter() - start, result


def json_output(plan) -> str:
    """The document `plan --json` prints: the plan file with each module's `changes`."""
    document = plan_file.write(plan, (), render)
    return json.dumps(document, indent=1)


def in_process(plant: Path, actual: Path) -> dict[str, float]:
    """Seconds of each part of `plan --actual`, in this process."""
    figures = {}
    figures["load the plant"], loaded = timed(lambda: api.load(plant))
    figures["load the images"], images = timed(lambda: api.load_images(actual, loaded))
    figures["plan"], plan = timed(lambda: api.plan(loaded, images=images))
    figures["render --json"], _ = timed(lambda: json_output(plan))  # first, as the CLI does
    figures["render human"], _ = timed(lambda: render.human(plan))
    figures["render --markdown"], _ = timed(lambda: render.markdown(plan))
    return figures


def worst_files(folder: Path) -> dict[str, Path]:
    """Files at the limits, by what they are."""
    full = folder / "full"
    full.mkdir(exist_ok=True)
    largest, _ = write_plant(full, FULL_PROGRAM)
    profiles, keys = MAX_NODES // MAX_PART_NODES - 1, MAX_PART_NODES // 2 - 4
    one = "buses: [{name: a, port: emulator://a, modules: [{address: 1, name: m}]}]\n"
    texts = {
        f"{MAX_NODES:,} one-character list items": "plant: x\nbuses: [" + "a, " * MAX_NODES + "]\n",
        f"{MAX_PART_NODES:,} one-character list items": "plant: x\nbuses: [" + "a, " * (MAX_PART_NODES - 10) + "]\n",
        f"{profiles} profiles of {keys:,} keys 'on'": "plant: x\nprofiles:\n"
        + "".join(f"  p{p}:\n" + "".join(f"    k{k}: on\n" for k in range(keys)) for p in range(profiles)) + one,
        f"{profiles} profiles of {keys:,} keys, all different": "plant: x\nprofiles:\n"
        + "".join(f"  p{p}:\n" + "".join(f"    k{p}_{k}: v{p}_{k}\n" for k in range(keys)) for p in range(profiles)) + one,
        "the largest plant with every speed out of range": largest.read_text().replace("speed: 0.", "speed: 9."),
        "the largest plant with a syntax error at its end": largest.read_text() + "  oops\n",
    }
    files = {"the largest valid plant (f1, f2, next on every program)": largest}
    for name, text in texts.items():
        files[name] = folder / f"worst-{len(files)}.yaml"
        files[name].write_text(text)
    return files


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--keep", type=Path, help="write the files into this folder and keep them")
    parser.add_argument("--worst", action="store_true", help="also validate files at the plant file's limits")
    parser.add_argument("--one-profile", action="store_true", help="also plan 32 × 30 modules that take one profile")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as temporary:
        folder = args.keep or Path(temporary)
        folder.mkdir(parents=True, exist_ok=True)
        plant, actual = write_plant(folder)
        print(f"{BUSES} buses × {MODULES} modules, 64 programs each: plant file {plant.stat().st_size / 1e6:.2f} MB, "
              f"images {actual.stat().st_size / 1e6:.2f} MB; median of {args.runs} runs")
        compileall.compile_dir(Path(api.__file__).parents[1], quiet=1)  # the tool as installed (module docstring)
        prc3cfg = [sys.executable, "-m", "prc3cfg"]
        plan = [*prc3cfg, "plan", str(plant), "--actual", str(actual)]
        script = Path(sys.executable).with_name("prc3cfg")  # what a user runs: the script pip installed beside python
        commands = {"prc3cfg --help": [str(script), "--help"] if script.exists() else [*prc3cfg, "--help"],
                    "validate": [*prc3cfg, "validate", str(plant)], "plan --actual": plan,
                    "plan --actual --json": [*plan, "--json"], "plan --actual --markdown": [*plan, "--markdown"]}
        for name, command in commands.items():
            run = median_run(command, args.runs)
            print(f"  {name:<26} {run.wall:6.2f} s wall  {run.cpu:6.2f} s CPU  {run.rss_mb:6.1f} MiB max RSS")
        in_process(plant, actual)  # warm-up: imports, pydantic's schemas
        parts = [in_process(plant, actual) for _ in range(args.runs)]
        print("  in process:")
        for name in parts[0]:
            print(f"    {name:<24} {statistics.median(p[name] for p in parts):6.2f} s")
        if args.one_profile:
            one = folder / "one-profile"
            one.mkdir(exist_ok=True)
            plant, commissioning, drifted = write_one_profile_plant(one)
            print(f"{ONE_PROFILE_BUSES} buses × {MODULES} modules from one profile, plan --actual:")
            for name, images in (("commissioning (factory images)", commissioning), ("programs of their own", drifted)):
                run = median_run([*prc3cfg, "plan", str(plant), "--actual", str(images)], args.runs)
                print(f"  {name:<32} {run.cpu:6.2f} s CPU  {run.rss_mb:6.1f} MiB max RSS  ({run.wall:.2f} s wall)")
        if args.worst:
            print("validate at the limits:")
            for name, path in worst_files(folder).items():
                run = median_run([*prc3cfg, "validate", str(path)], args.runs, ok=(0, 1))
                print(f"  {name:<52} {path.stat().st_size / 1e6:5.1f} MB  {run.wall:6.2f} s wall  "
                      f"{run.rss_mb:6.1f} MiB max RSS  {run.said.removeprefix(str(path))[:90]}")


if __name__ == "__main__":
    main()
