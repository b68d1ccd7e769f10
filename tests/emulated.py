"""Test support: the demo plant on real emulators behind socket://, and the CLI run in-process."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from prc3cfg.cli import main
from prc3cfg.device import ModuleState
from prc3cfg.emulator import Emulator, FaultInjection
from prc3cfg.plant import load_plant

from lossy import LossyProxy, Rule

DEMO = Path(__file__).resolve().parent.parent / "plants" / "demo-line.yaml"


@dataclass
class EmulatedPlant:
    path: Path
    emulators: dict[str, Emulator]  # by bus name

    def images(self) -> dict[tuple[str, int], object]:
        return {(bus, a): s.image for bus, e in self.emulators.items() for a, s in e.modules().items()}

    def matches_plant(self) -> bool:
        """Every module holds exactly what the plant file says (managed programs, system)."""
        plant = load_plant(self.path)
        for bus in plant.buses:
            for module in bus.modules:
                held = self.emulators[bus.name].module(module.address).image
                desired = module.desired_image()
                if held.system != desired.system:
                    return False
                if any(want is not None and have != want for have, want in zip(held.programs, desired.programs)):
                    return False
        return True


@contextlib.contextmanager
def emulated_plant(
    directory: Path, *, faults: FaultInjection = FaultInjection(), timeout: float = 0.1, framing: str = "crc16",
    line_speed: bool = False, source: Path = DEMO, lossy: dict[str, Rule] | None = None, zvz: float = 0.020,
) -> Iterator[EmulatedPlant]:
    """`source` with every bus on an in-process emulator (factory-default modules) via socket://;
    a bus named in `lossy` is reached through a `LossyProxy` with that rule."""
    document = yaml.safe_load(source.read_text())
    plant = load_plant(source)
    with contextlib.ExitStack() as stack:
        emulators = {}
        for bus_doc, bus in zip(document["buses"], plant.buses):
            modules = {m.address: ModuleState.factory(m.address) for m in bus.modules}
            emulator = stack.enter_context(
                Emulator(modules, framing=framing, faults=faults, line=bus.line, line_speed=line_speed, zvz=zvz)
            )
            host, port = emulator.listen()
            url = f"socket://{host}:{port}"
            if lossy and bus.name in lossy:
                proxy = stack.enter_context(LossyProxy((host, port), lossy[bus.name], framing=framing, line=bus.line, zvz=zvz))
                url = proxy.listen()
            bus_doc.update(port=url, timeout=timeout, framing=framing, zvz=zvz)
            emulators[bus.name] = emulator
        path = directory / "plant.yaml"
        path.write_text(yaml.safe_dump(document, sort_keys=False))
        yield EmulatedPlant(path, emulators)


@dataclass
class Result:
    code: int
    out: str
    err: str

    @property
    def problems(self) -> list[str]:
        """stderr without its notes (a busy test machine can make a line repeat an exchange)."""
        return [line for line in self.err.splitlines() if not line.startswith("note: ")]


def run_cli(capsys: pytest.CaptureFixture, *args: str) -> Result:
    """Run `prc3cfg ARGS` in this process, as the console script does."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        main([str(a) for a in args])
    captured = capsys.readouterr()
    code = exit_info.value.code
    return Result(0 if code is None else int(code), captured.out, captured.err)
