"""A plan for a whole plant, and the plan file `prc3cfg-plan/1` (interfaces.md §4).

A plan is data: per bus, per module, the steps to send (the PRC 3 message, exactly as it
goes on the line), what they were planned from (the plant file's hash and each module's
read-back hash, so a stale plan can be refused) and what they are predicted to do. The
optimiser that makes a module's steps is `prc3cfg.core.planner`; rendering is `prc3cfg.core.render`.

A bus may start with broadcasts (`prc3cfg.core.sharing`): steps sent once to address 0 that
every module of the line processes. In the plan file they are the leading steps of every
module of that bus, marked `"broadcast": true` — so each module's steps still say, in
order, everything that reaches it (a reader that sent them addressed would do the same,
only slower) — and the bus lists them once under `"broadcasts"`. Pure.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Any

from prc3cfg import __version__
from prc3cfg.core import codec
from prc3cfg.core.image import ModuleImage
from prc3cfg.core.planner import ModulePlan, Step
from prc3cfg.core.planner.check import MAX_STEPS

FORMAT = "prc3cfg-plan/1"


def image_sha256(image: ModuleImage) -> str:
    """The hash of a read-back, over its canonical JSON."""
    text = json.dumps(image.to_json(), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True, slots=True)
class ModuleChange:
    """One module of a plant plan: where it is, what it holds, what it should hold, the steps.

    The first `broadcasts` steps are its bus's broadcasts; `plan.bus_time` counts its own steps only."""

    bus: str
    name: str
    actual: ModuleImage
    desired: ModuleImage
    plan: ModulePlan
    broadcasts: int = 0

    @property
    def address(self) -> int:
        return self.plan.address

    @property
    def steps(self) -> tuple[Step, ...]:
        return self.plan.steps

    @property
    def releases_axes(self) -> bool:
        return self.plan.releases_axes

    def to_json(self) -> dict[str, Any]:
        return {
            "address": self.address,
            "name": self.name,
            "state_sha256": image_sha256(self.actual),
            "releases_axes": self.releases_axes,
            "estimated_bus_time_s": round(self.plan.bus_time, 4),
            "steps": [
                {"message": step.message.hex(), "summary": step.summary, "releases_axes": step.releases_axes}
                | ({"broadcast": True} if index < self.broadcasts else {})
                for index, step in enumerate(self.steps)
            ],
        }


@dataclass(frozen=True, slots=True)
class PlantPlan:
    """Every module's change, the broadcasts of each bus, and what they cost on the line."""

    plant: str
    plant_path: str
    plant_sha256: str
    modules: tuple[ModuleChange, ...]
    broadcast_time: float = 0.0  # every bus's broadcasts, once each
    unshared_bus_time: float | None = None  # the same changes without broadcasts, where some were shared

    @property
    def changes(self) -> tuple[ModuleChange, ...]:
        return tuple(m for m in self.modules if m.steps)

    @property
    def bus_time(self) -> float:
        return sum(m.plan.bus_time for m in self.modules) + self.broadcast_time

    def broadcasts(self, bus: str) -> tuple[Step, ...]:
        """The steps sent once to address 0 on `bus`, before any module's own steps."""
        return next((m.steps[: m.broadcasts] for m in self.modules if m.bus == bus and m.broadcasts), ())

    @property
    def naive_bus_time(self) -> float:
        return sum(m.plan.naive_bus_time for m in self.modules)

    @property
    def message_count(self) -> int:
        """Messages on the lines: every module's own steps, and each broadcast once."""
        return sum(len(m.steps) - m.broadcasts for m in self.modules) + sum(len(self.broadcasts(b)) for b in self.buses())

    @property
    def axis_releases(self) -> tuple[ModuleChange, ...]:
        return tuple(m for m in self.modules if m.releases_axes)

    def buses(self) -> dict[str, list[ModuleChange]]:
        grouped: dict[str, list[ModuleChange]] = {}
        for module in self.modules:
            grouped.setdefault(module.bus, []).append(module)
        return grouped

    def to_json(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "prc3cfg_version": __version__,
            "plant": self.plant,
            "plant_path": self.plant_path,
            "plant_sha256": self.plant_sha256,
            "buses": [
                {"name": bus, "modules": [m.to_json() for m in modules]}
                | ({"broadcasts": [
                    {"message": step.message.hex(), "summary": step.summary, "releases_axes": step.releases_axes,
                     "modules": [m.address for m in modules if m.broadcasts]}
                    for step in self.broadcasts(bus)
                ]} if self.broadcasts(bus) else {})
                for bus, modules in self.buses().items()
            ],  # fmt: skip
            "estimated_bus_time_s": round(self.bus_time, 4),
            "naive_bus_time_s": round(self.naive_bus_time, 4),
            "message_count": self.message_count,
            "axis_releases": [f"{m.bus}/{m.name}" for m in self.axis_releases],
        } | ({"without_broadcasts_bus_time_s": round(self.unshared_bus_time, 4)} if self.unshared_bus_time is not None else {})


@dataclass(frozen=True, slots=True)
class PlannedModule:
    """A module's entry of a plan file, as `apply --plan` reads it back (not yet proved:
    `prc3cfg.core.planner.plan_from_steps` runs the steps on the device model from the read-back)."""

    bus: str
    address: int
    name: str
    state_sha256: str
    steps: tuple[codec.Message, ...]
    broadcasts: int  # how many of the leading steps are the bus's broadcasts


class PlanFileError(ValueError):
    pass


@dataclass(frozen=True, slots=True)
class PlanFile:
    """A plan file as read: what it was made from, by which prc3cfg, and its modules."""

    plant: str
    plant_path: str
    plant_sha256: str
    version: str
    modules: tuple[PlannedModule, ...]
    document: dict[str, Any]  # as read: `apply --plan` holds it against what prc3cfg writes for the plan it proves


def read_plan_file(data: dict[str, Any]) -> PlanFile:
    """A parsed plan file; raises PlanFileError.

    Refused here, before the line is touched: a damaged file, a module listed twice, more
    steps than any plan needs (`MAX_STEPS`), a message not in the bytes prc3cfg sends for
    it (a "don't care" byte changed), and `releases_axes` flags that are not what the
    steps' bytes say.
    """
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise PlanFileError(f'not a plan file — expected "format": "{FORMAT}"')
    try:
        modules = []
        seen: set[tuple[str, int]] = set()
        for bus in data["buses"]:
            for module in bus["modules"]:
                entry = _planned_module(bus["name"], module)
                if (entry.bus, entry.address) in seen:
                    raise PlanFileError(f"bus {entry.bus}, module {entry.address} is listed twice — make the plan again")
                seen.add((entry.bus, entry.address))
                modules.append(entry)
        fields = (data["plant"], data["plant_path"], data["plant_sha256"], data.get("prc3cfg_version", "before 0.1.0"))
        if not all(isinstance(f, str) for f in fields):
            raise PlanFileError("damaged plan file (plant, plant_path, plant_sha256 and prc3cfg_version are texts) — make the plan again")
        return PlanFile(*fields, tuple(modules), data)
    except (KeyError, TypeError, ValueError, codec.Rejected) as error:
        if isinstance(error, PlanFileError):
            raise
        raise PlanFileError(f"damaged plan file ({type(error).__name__}: {error}) — make the plan again") from None


def _planned_module(bus: str, module: dict[str, Any]) -> PlannedModule:
    address = module["address"]
    if type(address) is not int or type(bus) is not str:
        raise PlanFileError(f"bus {json.dumps(bus)}: module address {json.dumps(address)} is not a bus name and "
                            "a whole number — make the plan again")  # fmt: skip
    where = f"bus {bus}, module {address}"
    steps = module["steps"]
    if len(steps) > MAX_STEPS:
        raise PlanFileError(f"{where}: {len(steps)} steps, more than any plan of one module needs ({MAX_STEPS}) — make the plan again")
    messages, flags = [], []
    for index, step in enumerate(steps, start=1):
        flags.append(step.get("broadcast", False))
        if flags[-1] not in (True, False) or (flags[-1] and not all(flags)):
            raise PlanFileError(f"{where}: step {index} ({step['message']}) is marked broadcast after a step that is not — "
                                "broadcasts lead a module's steps: make the plan again")  # fmt: skip
        message = codec.decode_message(bytes.fromhex(step["message"]))
        if message.hex() != step["message"]:  # "don't care" bytes that are not 00h, upper-case digits
            raise PlanFileError(f"{where}: step {index} ({step['message']}) is not written as prc3cfg writes that "
                                f"message ({message.hex()}) — make the plan again")  # fmt: skip
        if step["releases_axes"] is not message.RELEASES_AXES:
            raise PlanFileError(
                f"{where}: step {index} ({step['message']}) says releases_axes: {json.dumps(step['releases_axes'])}, "
                f"but {message.ID:02X}h {'releases' if message.RELEASES_AXES else 'does not release'} the axes — make the plan again"
            )
        messages.append(message)
    if module["releases_axes"] is not any(m.RELEASES_AXES for m in messages):
        raise PlanFileError(f"{where}: releases_axes: {json.dumps(module['releases_axes'])} is not what its steps do — make the plan again")
    return PlannedModule(bus, address, str(module["name"]), str(module["state_sha256"]), tuple(messages), sum(flags))
