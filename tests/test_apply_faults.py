"""The acceptance run of `apply` under line faults: every framing, 40 seeds each in the soak tier
(2 in the fast tier).

Emulators start from seeded, non-factory modules — programs the plant does not manage
among them, some of which the plant's lower upper reversing point makes the module clamp —
and lose 5–40 % of exchanges and damage 5–10 % (a flipped bit, which a line with parity
turns into a lost character). Whatever happens, an apply must end without a traceback,
and never with a wrong value on a module — a managed one, or an unmanaged program beyond
the module's own clamping — that its account does not name; every module whose axes were
released must be on the reference-travel list.
"""

from __future__ import annotations

import contextlib
import os
import random
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import pytest
from emulated import emulated_plant, travel_list

from prc3cfg.core import codec, device
from prc3cfg.core.image import PROGRAM_COUNT, ModuleImage, Program
from prc3cfg.shell.emulator.server import FaultInjection
from prc3cfg.shell.plant_files import load_plant

#: Seeds per framing: a few in the fast tier, the acceptance's 40 in the soak tier.
SEEDS = [2, pytest.param(40, marks=pytest.mark.soak)]

def seeded_image(chooser: random.Random, address: int) -> ModuleImage:
    """A module as found on the floor: a high upper reversing point, programs anywhere below it."""
    factory = ModuleImage.factory(address)
    system = replace(factory.system, S1=chooser.randrange(1900, 3000), S4=chooser.randrange(300, 601),
                     S5=chooser.randrange(5, 30))

    def program() -> Program:
        return Program(P=chooser.randrange(0, system.S1 + 1), V=chooser.randrange(system.S5, system.S4 + 1),
                       T=chooser.randrange(0, 100),
                       A=chooser.choice([0, 0, chooser.randrange(1, 65)]))

    return ModuleImage(address, system, tuple(program() for _ in range(PROGRAM_COUNT)))


def check(plant, initial, returncode: int, out: str, err: str) -> list[str]:
    """What is wrong with one faulty run (nothing, when the run kept every promise)."""
    if returncode not in (0, 1) or "Traceback" in err:
        return [f"exit {returncode}:\n{err}"]
    if not all(line.startswith(("✗", "    ", "error: ", "note: ")) for line in err.splitlines()):
        return [f"stderr is not one line per problem:\n{err}"]
    problems = []
    named = {line.split(":")[0].removeprefix("✗ ") for line in err.splitlines() if line.startswith("✗ bus")}
    travel = travel_list(out)
    for bus, module in load_plant(plant.path).modules():
        state = plant.emulators[bus.name].module(module.address)
        held, was, want = state.image, initial[(bus.name, module.address)], module.desired_image()
        where = f"bus {bus.name}, module {module.address} ({module.name})"
        # an unmanaged program may only be what the module's own clamping made of it
        kept = (device.execute(device.ModuleState(was), codec.WriteSystem(held.system)).image
                if held.system != was.system else was)
        wrong = held.system != want.system or any(
            h != (k if w is None else w) for h, w, k in zip(held.programs, want.programs, kept.programs)
        )
        if wrong and (returncode == 0 or (held != was and where not in named)):
            problems.append(f"{where} holds a wrong value the account does not name")
        if not state.referenced and f"{bus.name}/{module.name}" not in travel:
            problems.append(f"{where} released its axes, and is not on the reference-travel list")
    return [f"{p}:\n{out}\n{err}" for p in problems]


@pytest.mark.parametrize("seeds", SEEDS)
@pytest.mark.parametrize("framing", ["crc16", "stx", "open-driver"])
def test_apply_under_faults_never_leaves_an_unreported_wrong_value(tmp_path, framing, seeds):
    """Seeded runs of real `prc3cfg apply` processes, eight at a time, each on its own emulated plant."""
    # loopback answers within a millisecond: short time-outs keep the runs quick
    timeout, zvz = (0.05, 0.005) if framing == "open-driver" else (0.02, 0.020)
    with contextlib.ExitStack() as stack:
        runs = []
        for seed in range(seeds):
            chooser = random.Random(f"{framing}/{seed}")
            faults = FaultInjection(drop_rate=chooser.uniform(0.05, 0.40),
                                    corrupt_rate=chooser.uniform(0.05, 0.10), seed=seed)
            directory = tmp_path / str(seed)
            directory.mkdir()
            plant = stack.enter_context(emulated_plant(directory, faults=faults, framing=framing,
                                                       timeout=timeout, zvz=zvz))
            initial = {
                (bus, address): emulator.update(address, image=seeded_image(chooser, address)).image
                for bus, emulator in plant.emulators.items()
                for address in emulator.modules()
            }
            runs.append((seed, plant, initial))

        def apply(plant) -> subprocess.CompletedProcess:
            command = [sys.executable, "-m", "prc3cfg", "apply", str(plant.path), "--auto-approve",
                       "--allow-axis-release", "--retries", "8"]
            env = {**os.environ, "PRC3CFG_LOCK_DIR": str(plant.path.parent / "locks")}
            return subprocess.run(command, capture_output=True, text=True, env=env, timeout=600)

        with ThreadPoolExecutor(max_workers=8) as pool:
            results = list(pool.map(apply, [plant for _, plant, _ in runs]))
        failures = [
            f"seed {seed}: {problem}"
            for (seed, plant, initial), result in zip(runs, results)
            for problem in check(plant, initial, result.returncode, result.stdout, result.stderr)
        ]
        verified = sum(result.returncode == 0 for result in results)
    assert not failures, "\n\n".join(failures)
    assert verified >= max(1, seeds // 4), (f"only {verified} of {seeds} runs got through: the faults are "
                                            "too heavy to test anything")
