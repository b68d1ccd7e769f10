"""A plan for a whole plant, and the plan file `prc3cfg-plan/1` (interfaces.md §4).

A plan is data: per bus, per module, the steps to send (the PRC 3 message, exactly as it
goes on the line), what they were planned from (the plant file's hash and each module's
read-back hash, so a stale plan can be refused) and what they are predicted to do. The
optimiser that makes a module's steps is `prc3cfg.planner`; rendering is `prc3cfg.render`.
Pure.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Any

from prc3cfg import codec
from prc3cfg.image import ModuleImage
from prc3cfg.planner import ModulePlan, Step

FORMAT = "prc3cfg-plan/1"


def image_sha256(image: ModuleImage) -> str:
    """The hash of a read-back, over its canonical JSON."""
    text = json.dumps(image.to_json(), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True, slots=True)
class ModuleChange:
    """One module of a plant plan: where it is, what it holds, what it should hold, the steps."""

    bus: str
    name: str
    actual: ModuleImage
    desired: ModuleImage
    plan: ModulePlan

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
                for step in self.steps
            ],
        }


@dataclass(frozen=True, slots=True)
class PlantPlan:
    plant: str
    plant_path: str
    plant_sha256: str
    modules: tuple[ModuleChange, ...]

    @property
    def changes(self) -> tuple[ModuleChange, ...]:
        return tuple(m for m in self.modules if m.steps)

    @property
    def bus_time(self) -> float:
        return sum(m.plan.bus_time for m in self.modules)

    @property
    def naive_bus_time(self) -> float:
        return sum(m.plan.naive_bus_time for m in self.modules)

    @property
    def message_count(self) -> int:
        return sum(len(m.steps) for m in self.modules)

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
            "plant": self.plant,
            "plant_path": self.plant_path,
            "plant_sha256": self.plant_sha256,
            "buses": [
                {"name": bus, "modules": [m.to_json() for m in modules]} for bus, modules in self.buses().items()
            ],
            "estimated_bus_time_s": round(self.bus_time, 4),
            "naive_bus_time_s": round(self.naive_bus_time, 4),
            "message_count": self.message_count,
            "axis_releases": [f"{m.bus}/{m.name}" for m in self.axis_releases],
        }


@dataclass(frozen=True, slots=True)
class PlannedModule:
    """A module's entry of a plan file, as `apply --plan` reads it back."""

    bus: str
    address: int
    name: str
    state_sha256: str
    steps: tuple[codec.Message, ...]
    releases_axes: bool


class PlanFileError(ValueError):
    pass


def read_plan_file(data: dict[str, Any]) -> tuple[str, str, list[PlannedModule]]:
    """(plant, plant_sha256, modules) of a parsed plan file; raises PlanFileError."""
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise PlanFileError(f'not a plan file — expected "format": "{FORMAT}"')
    try:
        modules = [
            PlannedModule(
                bus=bus["name"],
                address=int(module["address"]),
                name=module["name"],
                state_sha256=module["state_sha256"],
                steps=tuple(codec.decode_message(bytes.fromhex(step["message"])) for step in module["steps"]),
                releases_axes=bool(module["releases_axes"]),
            )
            for bus in data["buses"]
            for module in bus["modules"]
        ]
        return data["plant"], data["plant_sha256"], modules
    except (KeyError, TypeError, ValueError, codec.Rejected) as error:
        raise PlanFileError(f"damaged plan file ({type(error).__name__}: {error}) — make the plan again") from None
