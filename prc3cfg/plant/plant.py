"""A loaded, valid plant: `Plant` → `Bus` → `Module`, and each module's desired image.

What the rest of prc3cfg uses: a bus's port, framing, line settings and times; a module's
address, name, the programs the plant manages, and its desired `ModuleImage` in device
units (docs/files.md "Module image"), converted once and kept. A `Module` also keeps its effective settings
with their sources (`profiles.Effective`) for `prc3cfg show`. Built only by `loader.parse_plant`,
after every rule passed — so converting to device units cannot fail here.
"""

from __future__ import annotations

import functools
from pathlib import Path

from pydantic import BaseModel, ConfigDict

from prc3cfg.core.framing import detects_damage
from prc3cfg.core.image import PROGRAM_NUMBERS, ModuleImage, Program, SystemParameters, default_program
from prc3cfg.core.line import LineSettings
from prc3cfg.core.units import PROGRAM_QUANTITIES, SYSTEM_QUANTITIES, function_output
from prc3cfg.plant.models import BusLine, UnmanagedPrograms
from prc3cfg.plant.profiles import Effective


class Module(BaseModel):
    """One module of a plant, with its settings after profiles."""

    model_config = ConfigDict(frozen=True, extra="forbid", arbitrary_types_allowed=True)

    address: int
    name: str
    profiles: tuple[str, ...]
    unmanaged_programs: UnmanagedPrograms
    settings: Effective

    def managed_programs(self) -> tuple[int, ...]:
        """The program numbers the plant manages: the listed ones, or all 64 with `reset`."""
        if self.unmanaged_programs == "reset":
            return tuple(PROGRAM_NUMBERS)
        return tuple(self.settings.programs)

    def desired_system(self) -> SystemParameters:
        return self.desired_image().system

    def desired_programs(self) -> dict[int, Program]:
        """The listed programs in device units, A from chains and `next` (0 if neither)."""
        image = self.desired_image()
        return {number: image.known(number) for number in self.settings.programs}

    def desired_image(self) -> ModuleImage:
        """What the module should hold. Unlisted programs: `None` with keep, factory defaults with reset."""
        return self._desired_image

    @functools.cached_property
    def _desired_image(self) -> ModuleImage:
        derived = self.settings.derived
        if "desired" not in derived:
            derived["desired"] = _in_device_units(self.settings)
        system, programs = derived["desired"]
        return ModuleImage(address=self.address, system=system, programs=programs)


def _in_device_units(settings: Effective) -> tuple[SystemParameters, tuple[Program | None, ...]]:
    """The system parameters and the 64 programs that `settings` describe, in device units: unlisted
    programs `None` with keep, factory defaults with reset."""
    system = SystemParameters(**{q.symbol: q.to_device(settings.system[q.key].value)
                                 for q in SYSTEM_QUANTITIES})
    jumps = settings.jumps()
    programs = {}
    for number, fields in settings.programs.items():
        values = fields.plain_values()
        f1, f2 = values["f1"], values["f2"]
        jump = jumps.get(number)
        programs[number] = Program(
            **{q.symbol: q.to_device(values[q.key]) for q in PROGRAM_QUANTITIES},
            F1=function_output(f1.action, f1.distance),
            F2=function_output(f2.action, f2.distance),
            A=0 if jump is None else jump.value,
        )
    unlisted = default_program(system) if settings.unmanaged_programs.value == "reset" else None
    return system, tuple(programs.get(number, unlisted) for number in PROGRAM_NUMBERS)


class Bus(BusLine):
    """One RS-422 line: port, framing, line settings, times, optional gateway, and its modules."""

    modules: tuple[Module, ...]

    @property
    def line(self) -> LineSettings:
        return LineSettings(baud=self.baud, data_bits=self.data_bits, parity=self.parity,
                            stop_bits=self.stop_bits)

    @property
    def detects_damage(self) -> bool:
        """Whether a damaged frame on this line is detected — by its framing's check or by parity
        (`framing.detects_damage`): where not, a damaged frame can become another write, and an apply refuses
        unless `accept_undetected_damage`."""
        return detects_damage(self.framing, self.parity)


class Plant(BaseModel):
    """A plant file, loaded: its name, its buses, the file, the SHA-256 of its bytes and the policy file it
    names."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str
    buses: tuple[Bus, ...]
    path: Path
    sha256: str
    policy: str | None = None  # the policy file the plant file names, relative to it (docs/policy.md)

    @property
    def policy_path(self) -> Path | None:
        """The policy file this plant file names, as a path (relative to the plant file's folder as given)."""
        return None if self.policy is None else self.path.parent / self.policy

    def modules(self) -> tuple[tuple[Bus, Module], ...]:
        """Every module of the plant with its bus, in file order."""
        return tuple((bus, module) for bus in self.buses for module in bus.modules)
