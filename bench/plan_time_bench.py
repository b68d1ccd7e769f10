"""`plan --actual` of the largest plant: 8 buses × 30 fully managed modules, every program changed.

    python bench/plan_time_bench.py [--runs 3] [--keep DIR] [--worst] [--one-profile] [--mixes]

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

`--mixes` also plans, the same way, 8 × 30 modules for each kind of change (`MIXES`): the bench's
plant, then plants as `prc3cfg import` writes them — every module a recipe of its own, with dwells,
relative speeds and outputs on some programs and chains — against read-backs that differ in the
relative speed, the outputs F1 and F2, the jump addresses, the system parameters (a longer stroke
held: programs clamped), some of each, or a seeded random subset of the fields on a random share
of the programs. Each prints `plan --actual`'s CPU time and max RSS, and the CPU time of planning
alone (in this process, from loaded files), in all and per module: the planner's cost per module
should not depend on the kind of change (issue 29: `plan --actual` ≤ 2 s CPU for every mix).

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
from prc3cfg.core.image import (
    DEFAULT_SYSTEM,
    PROGRAM_COUNT,
    PROGRAM_FIELDS,
    PROGRAM_NUMBERS,
    ModuleImage,
    Program,
)
from prc3cfg.plant.document import MAX_NODES
from prc3cfg.plant.importer import module_entry, plant_yaml
from prc3cfg.plant.loader import MAX_PART_NODES

BUSES, MODULES = 8, 30
SYSTEM = replace(DEFAULT_SYSTEM, S1=2000, S4=500)
PROGRAM = "{{position: {P:.3f}, speed: {V:.3f}, dwell: {T:.1f}, relative_speed: {Vr:.3f}}}"
FULL_PROGRAM = ("{{position: {P:.3f}, speed: {V:.3f}, dwell: {T:.1f}, relative_speed: {Vr:.3f}, "
                "f1: {{action: set, distance: 0.010}}, f2: {{action: reset, distance: 0.050}}, "
                "next: {next}}}")


def write_plant(folder: Path, program: str = PROGRAM) -> tuple[Path, Path]:
    """The plant file and an images file in which every program differs; their paths."""
    rnd = random.Random(1)
    text, images = ["plant: big\nbuses:\n"], []
    for b in range(BUSES):
        text.append(f"  - name: bus{b}\n    port: socket://127.0.0.1:{7000 + b}\n    modules:\n")
        for address in range(1, MODULES + 1):
            programs = "".join(
                f"          {n}: " + program.format(P=rnd.randrange(100, 1900) / 1000,
                                                    V=rnd.randrange(20, 480) / 1000,
                                                    T=rnd.randrange(0, 50) / 10,
                                                    Vr=rnd.randrange(-50, 50) / 1000,
                                                    next=n % 64 + 1) + "\n"
                for n in PROGRAM_NUMBERS
            )
            text.append(f"      - address: {address}\n        name: b{b}m{address}\n        "
                        "unmanaged_programs: reset\n"
                        f"        system: {{upper_reversing_point: 2.000, max_speed: 0.500}}\n        "
                        f"programs:\n{programs}")
            held = tuple(Program(P=rnd.randrange(100, 1900), V=rnd.randrange(20, 480), T=rnd.randrange(0, 50))
                         for _ in PROGRAM_NUMBERS)
            images.append({"bus": f"bus{b}", **ModuleImage(address, SYSTEM, held).to_json()})
    plant, actual = folder / "plant.yaml", folder / "actual.json"
    plant.write_text("".join(text))
    actual.write_text(json.dumps(images))
    return plant, actual


@dataclass(frozen=True)
class Mix:
    """A kind of change: the fields in which the read-back differs from the plant file, on a share
    of the programs, and a share of the modules whose system parameters differ. `random_fields`:
    each module changes a random subset of the fields (seeded), on a random share of its programs."""

    fields: tuple[str, ...]
    share: float = 1.0
    system: float = 0.0
    random_fields: bool = False


#: The change mixes of `--mixes`, besides the bench's own plant (P, V, T, Vr of every program).
MIXES = {
    "relative speed": Mix(("Vr",)),
    "function outputs F1, F2": Mix(("F1", "F2")),
    "jump addresses (chains)": Mix(("A",)),
    "system differences": Mix((), system=0.5),
    "Vr, F1, chains, system": Mix(("Vr", "F1", "A"), system=0.3),
    "half of P, V; T": Mix(("P", "V", "T"), share=0.5),
    "random fields (seeded)": Mix(PROGRAM_FIELDS, system=0.3, random_fields=True),
}
#: The system parameters a module of a mix with a system difference holds: a longer stroke (its
#: programs beyond the plant's S1 are clamped by the plan's 20h), another S2 (another default
#: position, so an init before the 20h differs from one after it) and S4.
OTHER_SYSTEM = replace(SYSTEM, S1=2400, S2=120, S4=600)


def chained(rnd: random.Random) -> list[int]:
    """Jump addresses of chains of 1..8 programs, a third of them loops (a chain of one: A = 0)."""
    jumps, first = [0] * PROGRAM_COUNT, 1
    while first <= PROGRAM_COUNT:
        last = min(first + rnd.randrange(8), PROGRAM_COUNT)
        for n in range(first, last):
            jumps[n - 1] = n + 1
        jumps[last - 1] = first if last > first and rnd.random() < 1 / 3 else 0
        first = last + 1
    return jumps


def recipe(rnd: random.Random) -> tuple[Program, ...]:
    """64 programs as a recipe sets them: a position and a speed each, a dwell on half of them, a
    relative speed on a quarter, outputs switched at a distance on a third, programs in chains."""
    def sometimes(share: float, value: int) -> int:
        return value if rnd.random() < share else 0

    return tuple(Program(P=rnd.randrange(100, 1900), V=rnd.randrange(20, 480),
                         Vr=sometimes(0.25, rnd.randrange(1, 50)),
                         T=sometimes(0.5, rnd.randrange(1, 50)), F1=sometimes(1 / 3, rnd.randrange(1, 2000)),
                         F2=sometimes(1 / 3, rnd.randrange(1, 2000)), A=a)
                 for a in chained(rnd))


def mixed_module(rnd: random.Random, address: int, mix: Mix) -> tuple[ModuleImage, ModuleImage]:
    """A module of `mix`: the plant file's image, and the read-back — the plant's programs with the
    mix's fields taken from another recipe (its chains, where the jump addresses change)."""
    desired = ModuleImage(address, SYSTEM, recipe(rnd))
    fields, share = mix.fields, mix.share
    if mix.random_fields:
        fields = tuple(rnd.sample(fields, rnd.randrange(1, len(fields) + 1)))
        share = rnd.choice([0.1, 0.3, 0.6, 1.0])
    held = []
    for program, other in zip(desired.complete(), recipe(rnd)):
        changed = [name for name in fields if name == "A" or rnd.random() < share]
        for name in changed:
            program = program.with_field(name, getattr(other, name))
        held.append(program)
    system = SYSTEM
    if rnd.random() < mix.system:
        system = OTHER_SYSTEM
        held = [p.with_field("P", p.P + 500) if p.P > 1500 and rnd.random() < 0.5 else p for p in held]
    return desired, ModuleImage(address, system, tuple(held))


def write_mix(folder: Path, name: str) -> tuple[Path, Path]:
    """The plant file (as `prc3cfg import` writes one) and the images file of the change mix `name`
    (`MIXES`): 8 buses × 30 modules, each with programs of its own."""
    rnd = random.Random(name)
    buses, images = [], []
    for b in range(BUSES):
        entries = []
        for address in range(1, MODULES + 1):
            desired, held = mixed_module(rnd, address, MIXES[name])
            entries.append(module_entry(desired, f"b{b}m{address}"))
            images.append({"bus": f"bus{b}", **held.to_json()})
        buses.append(({"name": f"bus{b}", "port": f"socket://127.0.0.1:{7000 + b}"}, entries))
    slug = "".join(c if c.isalnum() else "-" for c in name)
    plant, actual = folder / f"mix-{slug}.yaml", folder / f"mix-{slug}.json"
    plant.write_text(plant_yaml("mix", buses))
    actual.write_text(json.dumps(images))
    return plant, actual


def planning_cpu(plant: Path, actual: Path) -> float:
    """CPU seconds of planning alone (`api.plan` from loaded images), in this process."""
    loaded = api.load(plant)
    images = api.load_images(actual, loaded)
    start = time.process_time()
    api.plan(loaded, images=images)
    return time.process_time() - start


ONE_PROFILE_BUSES = 32


def write_one_profile_plant(folder: Path) -> tuple[Path, Path, Path]:
    """A plant of 32 × 30 modules taking one profile, factory images, images of programs of their own."""
    rnd = random.Random(2)
    programs = "".join(f"      {n}: "
                       + PROGRAM.format(P=rnd.randrange(100, 1900) / 1000, V=rnd.randrange(20, 480) / 1000,
                                                      T=rnd.randrange(0, 50) / 10, Vr=0) + "\n"
                       for n in PROGRAM_NUMBERS)
    text = ["plant: one-profile\nprofiles:\n  line:\n    unmanaged_programs: reset\n",
            f"    system: {{upper_reversing_point: 2.000, max_speed: 0.500}}\n    "
            f"programs:\n{programs}buses:\n"]
    factory, own = [], []
    for b in range(ONE_PROFILE_BUSES):
        text.append(f"  - name: bus{b}\n    port: socket://127.0.0.1:{7000 + b}\n    modules:\n")
        for address in range(1, MODULES + 1):
            text.append(f"      - {{address: {address}, name: b{b}m{address}, profiles: line}}\n")
            factory.append({"bus": f"bus{b}", **ModuleImage.factory(address).to_json()})
            held = tuple(Program(P=rnd.randrange(100, 1900), V=rnd.randrange(20, 480), T=rnd.randrange(0, 50))
                         for _ in PROGRAM_NUMBERS)
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
        tail = err.read_bytes()[:4000] or out.read_bytes()[:4000]
        said = tail.decode(errors="replace").partition("\n")[0]
    if code not in ok:
        sys.exit(f"{' '.join(command)} ended with {code}: {said}")
    return Run(wall, cpu, rss_kib / 1024, said)


def median_run(command: list[str], runs: int, ok: tuple[int, ...] = (0,)) -> Run:
    results = [run_process(command, ok) for _ in range(runs)]
    return Run(*(statistics.median(getattr(r, f) for r in results) for f in ("wall", "cpu", "rss_mb")),
               results[0].said)


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
        f"{MAX_PART_NODES:,} one-character list items": "plant: x\nbuses: [" + "a, " * (MAX_PART_NODES - 10)
             + "]\n",
        f"{profiles} profiles of {keys:,} keys 'on'": "plant: x\nprofiles:\n"
        + "".join(f"  p{p}:\n" + "".join(f"    k{k}: on\n" for k in range(keys)) for p in range(profiles))
             + one,
        f"{profiles} profiles of {keys:,} keys, all different": "plant: x\nprofiles:\n"
        + "".join(f"  p{p}:\n" + "".join(f"    k{p}_{k}: v{p}_{k}\n" for k in range(keys))
                  for p in range(profiles)) + one,
        "the largest plant with every speed out of range": largest.read_text().replace("speed: 0.",
                                                                                       "speed: 9."),
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
    parser.add_argument("--one-profile", action="store_true",
                        help="also plan 32 × 30 modules that take one profile")
    parser.add_argument("--mixes", action="store_true", help="also plan every change mix (MIXES)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as temporary:
        folder = args.keep or Path(temporary)
        folder.mkdir(parents=True, exist_ok=True)
        plant, actual = write_plant(folder)
        print(f"{BUSES} buses × {MODULES} modules, 64 programs each: plant file "
              f"{plant.stat().st_size / 1e6:.2f} MB, "
              f"images {actual.stat().st_size / 1e6:.2f} MB; median of {args.runs} runs")
        # the tool as installed (module docstring)
        compileall.compile_dir(Path(api.__file__).parents[1], quiet=1)
        prc3cfg = [sys.executable, "-m", "prc3cfg"]
        plan = [*prc3cfg, "plan", str(plant), "--actual", str(actual)]
        # what a user runs: the script pip installed beside python
        script = Path(sys.executable).with_name("prc3cfg")
        commands = {"prc3cfg --help": [str(script), "--help"] if script.exists() else [*prc3cfg, "--help"],
                    "validate": [*prc3cfg, "validate", str(plant)], "plan --actual": plan,
                    "plan --actual --json": [*plan, "--json"],
                    "plan --actual --markdown": [*plan, "--markdown"]}
        for name, command in commands.items():
            run = median_run(command, args.runs)
            print(f"  {name:<26} {run.wall:6.2f} s wall  {run.cpu:6.2f} s CPU  {run.rss_mb:6.1f} MiB max RSS")
        in_process(plant, actual)  # warm-up: imports, pydantic's schemas
        parts = [in_process(plant, actual) for _ in range(args.runs)]
        print("  in process:")
        for name in parts[0]:
            print(f"    {name:<24} {statistics.median(p[name] for p in parts):6.2f} s")
        if args.mixes:
            print(f"change mixes, {BUSES} × {MODULES} modules: plan --actual in a fresh process, and "
                  "planning alone in "
                  f"this one (issue 29: ≤ 2 s CPU each)")
            mixes = folder / "mixes"
            mixes.mkdir(exist_ok=True)
            files = {"P, V, T, Vr (the bench's plant)": (plant, actual)} | {name: write_mix(mixes, name)
                                                                            for name in MIXES}
            for name, (mix_plant, images) in files.items():
                run = median_run([*prc3cfg, "plan", str(mix_plant), "--actual", str(images)], args.runs)
                alone = statistics.median(planning_cpu(mix_plant, images) for _ in range(args.runs))
                print(f"  {name:<34} {run.cpu:6.2f} s CPU  {run.rss_mb:6.1f} MiB max RSS  planning "
                      f"{alone:5.2f} s CPU, "
                      f"{alone / (BUSES * MODULES) * 1e3:5.1f} ms a module")
        if args.one_profile:
            one = folder / "one-profile"
            one.mkdir(exist_ok=True)
            plant, commissioning, drifted = write_one_profile_plant(one)
            print(f"{ONE_PROFILE_BUSES} buses × {MODULES} modules from one profile, plan --actual:")
            for name, images in (("commissioning (factory images)", commissioning),
                                 ("programs of their own", drifted)):
                run = median_run([*prc3cfg, "plan", str(plant), "--actual", str(images)], args.runs)
                print(f"  {name:<32} {run.cpu:6.2f} s CPU  {run.rss_mb:6.1f} MiB max RSS  "
                      f"({run.wall:.2f} s wall)")
        if args.worst:
            print("validate at the limits:")
            for name, path in worst_files(folder).items():
                run = median_run([*prc3cfg, "validate", str(path)], args.runs, ok=(0, 1))
                print(f"  {name:<52} {path.stat().st_size / 1e6:5.1f} MB  {run.wall:6.2f} s wall  "
                      f"{run.rss_mb:6.1f} MiB max RSS  {run.said.removeprefix(str(path))[:90]}")


if __name__ == "__main__":
    main()
