"""Testing a plant repository: every bus of a plant file on an emulator, and a pytest fixture.

    def test_the_plant_applies_cleanly(prc3cfg_emulated):
        emulated = prc3cfg_emulated("plant.yaml")          # modules at factory defaults
        api.apply(emulated.plant, gates=api.Gates(allow_axis_release=True))
        assert not api.plan(emulated.plant).changes

`emulate(plant_path, directory)` starts one emulator (`prc3cfg.shell.emulator.server.Emulator`, the same code
as `prc3cfg emulator serve`) per bus of the plant file, its modules at factory defaults or as a
module-image file (`prc3cfg read --json`) says, and writes a copy of the plant file into
`directory` (as `plant.yaml`) whose buses' ports point at the emulators (`socket://127.0.0.1:PORT`); the
`EmulatedPlant` gives the loaded plant for `prc3cfg.api`, the emulators (to change a module as
the floor would: `teach_in`, `update`) and what the modules hold.

The pytest plugin `prc3cfg.shell.pytest_plugin` (entry point `pytest11`, registered when prc3cfg is
installed) gives tests the fixture `prc3cfg_emulated` built on this. Shell: sockets, threads.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import yaml

from prc3cfg.core.device import ModuleState
from prc3cfg.core.image import PROGRAM_NUMBERS, ModuleImage, default_program
from prc3cfg.errors import UserError
from prc3cfg.plant import Plant
from prc3cfg.shell.emulator.server import Emulator, FaultInjection
from prc3cfg.shell.files import FileProblem, read_json
from prc3cfg.shell.plant_files import load_plant
from prc3cfg.shell.platform import resolved


@dataclass
class EmulatedPlant:
    """A plant file whose buses run on emulators: the rewritten file, the plant, the emulators by bus."""

    path: Path
    plant: Plant
    emulators: dict[str, Emulator]

    def images(self) -> dict[tuple[str, int], ModuleImage]:
        """What every module holds now, by (bus, address)."""
        return {(bus, a): s.image for bus, e in self.emulators.items() for a, s in e.modules().items()}

    def matches_plant(self) -> bool:
        """Every module holds what the plant file says (system parameters and managed programs)."""
        for bus, module in load_plant(self.path).modules():
            held, desired = self.emulators[bus.name].module(module.address).image, module.desired_image()
            if held.system != desired.system or any(w is not None and h != w
                                                    for h, w in zip(held.programs, desired.programs)):
                return False
        return True


def seeded(images: Path) -> dict[tuple[str | None, int], ModuleState]:
    """Module states from a `prc3cfg read --json` file, by (bus or None, address); programs it
    did not read hold their defaults."""
    remedy = "give the file prc3cfg read --json wrote"
    try:
        entries = read_json(images)
    except FileProblem as problem:
        raise UserError(f"{problem.where(images)}: {problem} — {remedy}") from None
    if not isinstance(entries, list):
        raise UserError(f"{images}: not a list of module images — {remedy}")
    states = {}
    for entry in entries:
        try:
            image = ModuleImage.from_json(entry)
        except (ValueError, KeyError, TypeError, AttributeError) as error:
            raise UserError(f"{images}: not a module image as prc3cfg read --json writes it ({error}) "
                            f"— {remedy}") from None
        filler = default_program(image.system)
        complete = image.with_programs({n: filler for n in PROGRAM_NUMBERS if image.program(n) is None})
        states[(entry.get("bus"), image.address)] = ModuleState(complete)
    return states


@contextlib.contextmanager
def emulate(
    plant_path: str | Path,
    directory: Path,
    *,
    images: Path | None = None,
    faults: FaultInjection = FaultInjection(),
    line_speed: bool = False,
    route: Callable[[str, str, int], str] | None = None,
    unlisted: dict[str, Iterable[int]] | None = None,
    **bus_settings: Any,
) -> Iterator[EmulatedPlant]:
    """Every bus of the plant file on an emulator, and a copy of the file in `directory` that uses them.

    `bus_settings` (e.g. `timeout=0.1`, `framing="stx"`) are written into every bus of the copy;
    `route(bus, host, port)` may put something between the link and the emulator (a URL to use
    instead of `socket://host:port`); `unlisted` puts factory modules the plant file does not list
    on a bus's line, at the given addresses (a plant file wrong about its line)."""
    source = Path(plant_path)
    plant = load_plant(source)  # refused here, with its own lines, if it is not a valid plant file
    document = yaml.safe_load(source.read_text())
    seeds = seeded(images) if images is not None else {}
    with contextlib.ExitStack() as stack:
        emulators = {}
        for bus_document, bus in zip(document["buses"], plant.buses):
            bus_document.update(bus_settings)
            modules = {}
            for module in bus.modules:
                state = seeds.get((bus.name, module.address)) or seeds.get((None, module.address))
                modules[module.address] = state or ModuleState.factory(module.address)
            for address in (unlisted or {}).get(bus.name, ()):
                modules[address] = ModuleState.factory(address)
            line = replace(bus.line,
                           **{key: bus_document[key]
                              for key in ("baud", "parity", "data_bits", "stop_bits") if key in bus_settings})
            emulator = stack.enter_context(Emulator(
                modules, framing=bus_document.get("framing", bus.framing), line=line, line_speed=line_speed,
                zvz=bus_document.get("zvz", bus.zvz), turnaround=bus.turnaround, faults=faults,
            ))
            host, port = emulator.listen("127.0.0.1", 0)
            bus_document["port"] = route(bus.name, host, port) if route else f"socket://{host}:{port}"
            emulators[bus.name] = emulator
        copy = directory / "plant.yaml"
        if resolved(copy) == resolved(source):
            raise UserError(f"{source}: the emulated copy would overwrite the plant file — give another "
                            "directory")
        copy.write_text(yaml.safe_dump(document, sort_keys=False))
        yield EmulatedPlant(copy, load_plant(copy), emulators)
