"""Issue 17's adversarial runs, seeded and bounded: a plant that lies about its line, applies killed at
points seen on their frame trace, an open-driver line without parity that damages 5–30 % of the
exchanges, modules changed on the floor while an apply runs. Each crosses the real link client and a
real emulator (a real `prc3cfg` process where one is killed) and holds apply to its two promises:

- no axis release on a module that is neither named in the run's account nor reported by the next
  command on the line;
- no module called verified whose system block differs from the plant file's.

The first few seeds of each run in the fast tier; all 30 under `-m soak`.
"""

from __future__ import annotations

import os
import random
import subprocess
import sys
import threading
from dataclasses import replace

import pytest
import yaml
from emulated import PLANNED_TRAVEL, emulated_plant, run_cli, travel_list
from test_broadcast import declared, full_line

from prc3cfg.core.device import ModuleState
from prc3cfg.shell.emulator.server import FaultInjection
from prc3cfg.shell.plant_files import load_plant

FAST = 2  # seeds in the fast tier


def seeds(count: int = 30) -> list:
    return [seed if seed < FAST else pytest.param(seed, marks=pytest.mark.soak) for seed in range(count)]


def unreferenced(plant) -> set[tuple[str, int]]:
    return {(bus, a) for bus, emulator in plant.emulators.items() for a, s in emulator.modules().items()
            if not s.referenced}


def named(plant, *texts: str) -> set[tuple[str, int]]:
    """The modules the texts put on a reference-travel list or warn of: by name, or every module of a
    line a broadcast release was recorded on."""
    found = set()
    lines = [travel_list(text) for text in texts] + [line for text in texts for line in text.splitlines()
                                                     if "warning" in line]
    for bus in load_plant(plant.path).buses:
        for module in bus.modules:
            if any(f"{bus.name}/{module.name}" in line
                   or f"bus {bus.name}, module {module.address} " in line for line in lines):
                found.add((bus.name, module.address))
        if any(f"bus {bus.name}, every module on the line" in line for line in lines):
            found |= {(bus.name, a) for a in plant.emulators[bus.name].modules()}
    return found


def referenced_again(plant) -> None:
    """Every module travelled to its reference point (as the operator does after an apply)."""
    for emulator in plant.emulators.values():
        for address in emulator.modules():
            emulator.update(address, referenced=True)


@pytest.mark.parametrize("seed", seeds())
def test_a_plant_that_lies_about_its_line_never_reaches_the_modules_it_does_not_list(tmp_path, capsys, seed):
    chooser = random.Random(seed)
    listed = chooser.randint(24, 29)
    strangers = sorted(chooser.sample(range(listed + 1, 31), chooser.randint(1, 30 - listed)))
    speed = chooser.choice(["0.250", "0.300", "0.310"])
    with emulated_plant(tmp_path, source=declared(full_line(tmp_path, speed=speed, modules=listed)),
                        unlisted={"line": strangers}) as plant:
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert result.code == 0, result.err
        for address in strangers:
            held = plant.emulators["line"].module(address)
            assert held == ModuleState.factory(address), f"module {address} was reached"
        assert "which the plant file does not list" in result.out
        assert unreferenced(plant) <= named(plant, result.out)


@pytest.mark.parametrize("seed", seeds())
def test_an_apply_killed_anywhere_leaves_every_possibly_released_module_named_by_the_next_command(
    tmp_path, capsys, seed
):
    chooser = random.Random(seed)
    fifo = tmp_path / "trace.fifo"
    os.mkfifo(fifo)
    with emulated_plant(tmp_path) as plant:
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
        referenced_again(plant)
        # a 20h on most modules
        plant.path.write_text(plant.path.read_text().replace("max_speed: 0.5\n", "max_speed: 0.49\n"))
        requests = chooser.randint(1, 60)  # killed as its n-th request is on the line
        process = subprocess.Popen([sys.executable, "-m", "prc3cfg", "apply", str(plant.path),
                                    "--auto-approve",
                                    "--allow-axis-release", "--trace", str(fifo)], text=True,
                                   stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        with fifo.open() as trace:
            seen = 0
            for line in trace:
                seen += "\t>\t" in line
                if seen == requests:
                    process.kill()
                    break
            threading.Thread(target=trace.read, daemon=True).start()
            out, _ = process.communicate()
        after = run_cli(capsys, "plan", plant.path)
        assert unreferenced(plant) <= named(plant, out, after.err), after.err


@pytest.mark.parametrize("seed", seeds())
def test_open_driver_without_parity_damaging_exchanges_hides_no_release_and_verifies_no_wrong_system(
    tmp_path, capsys, seed
):
    chooser = random.Random(seed)
    faults = FaultInjection(corrupt_rate=chooser.uniform(0.05, 0.30), seed=seed)
    # ZVZ, the gap that ends an open-driver frame and is waited after each: 8 ms (over seven characters at
    # 9600 8N1), not 20
    with emulated_plant(tmp_path, faults=faults, framing="open-driver", parity="none",
                        accept_undetected_damage=True, zvz=0.008) as plant:
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release", "--retries",
                         "8")
        # what the apply left, before the plan's own reads: one of them may arrive damaged as a write (the
        # plan says so)
        held = {(bus, address): state.image.system for bus, emulator in plant.emulators.items()
                for address, state in emulator.modules().items()}
        after = run_cli(capsys, "plan", plant.path)
        assert "Traceback" not in result.err + after.err
        assert unreferenced(plant) <= named(plant, result.out, result.err, after.err)
        for bus, module in load_plant(plant.path).modules():
            if f"✓ bus {bus.name}, module {module.address} ({module.name}): " in result.out:
                assert held[bus.name,
                            module.address] == module.desired_system(), (f"{bus.name}/{module.name} "
                                                                         "verified with another system block")


@pytest.mark.parametrize("seed", seeds())
def test_consent_holds_per_module_while_the_floor_changes_modules_mid_apply(tmp_path, capsys, seed):
    """The plan releases one module of booth-a; while the apply runs, the floor changes the system block
    or a program of random modules. No module outside the plan's releases is sent a 10h/20h."""
    chooser = random.Random(seed)
    changes: list[int] = []

    def floor(frame, _):
        if armed and frame.address and chooser.random() < 0.15:
            address = chooser.choice([1, 2, 5])
            emulator = plant.emulators["booth-a"]
            image = emulator.module(address).image
            if chooser.random() < 0.5:
                emulator.update(address, image=replace(image, system=replace(image.system,
                                                                             S7=chooser.randint(800, 1500))))
            else:
                emulator.teach_in(address, chooser.randint(1, 3), chooser.randint(100, 1800))
            changes.append(address)
        return set()

    armed = False
    with emulated_plant(tmp_path, lossy={"booth-a": floor}) as plant:
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
        referenced_again(plant)
        released = chooser.choice([(1, "booth-a-left"), (2, "booth-a-right"), (5, "booth-a-top")])
        document = yaml.safe_load(plant.path.read_text())
        module = next(m for m in document["buses"][0]["modules"] if m["name"] == released[1])
        module.setdefault("system", {})["sync_increment"] = 600  # a 20h for this module alone
        plant.path.write_text(yaml.safe_dump(document, sort_keys=False))
        armed = True
        result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release", "--verify",
                         "full")
        armed = False
        # what the operator agreed to: the plan as shown (the floor may have changed a module before it was
        # read)
        shown = travel_list(result.out, PLANNED_TRAVEL)
        for address, name in ((1, "booth-a-left"), (2, "booth-a-right"), (5, "booth-a-top")):
            if f"booth-a/{name}" not in shown:
                assert plant.emulators["booth-a"].module(address).referenced, (f"{name} released "
                                                                               "without consent")
        assert f"booth-a/{released[1]}" in shown, result.out + result.err
        assert "Traceback" not in result.err
