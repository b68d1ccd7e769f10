"""A plan for a whole plant, and the plan file `prc3cfg-plan/1` (interfaces.md §4).

A plan is data: per bus, per module, the steps to send (the PRC 3 message, exactly as it
goes on the line), what they were planned from (the plant file's hash and each module's
read-back hash, so a stale plan can be refused) and what they are predicted to do. The
optimiser that makes a module's steps is `prc3cfg.core.planner`; rendering is `prc3cfg.core.render`.

A bus may start with broadcasts (`prc3cfg.core.sharing`): steps sent once to address 0 that
every module of the line processes. In the plan file they are the leading steps of every
module of that bus, marked `"broadcast": true` — so each module's steps still say, in
order, everything that reaches it (a reader that sent them addressed would do the same,
only slower) — and the bus lists them once under `"broadcasts"`. A plan file read back, checked
and proved is `prc3cfg.core.planfile`. Pure.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from math import fsum
from typing import Any

from prc3cfg import __version__
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.image import ModuleImage
from prc3cfg.core.planner import ModulePlan, Step
from prc3cfg.core.what_to_read import read_messages, verification_time, with_known

FORMAT = "prc3cfg-plan/1"


def image_sha256(image: ModuleImage) -> str:
    """The hash of a read-back, over its canonical JSON."""
    text = json.dumps(image.to_json(), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True, slots=True)
class ModuleChange:
    """One module of a plant plan: where it is, what it holds, what it should hold, the steps.

    The first `broadcasts` steps are its bus's broadcasts; `plan.bus_time` counts its own steps only.
    `cost` prices its line's exchanges: what reading it back and verifying it take."""

    bus: str
    name: str
    actual: ModuleImage
    desired: ModuleImage
    plan: ModulePlan
    broadcasts: int = 0
    system_unset: bool = False  # the module reported E12: its plan writes the system parameters first
    cost: LineCost | None = None
    #: a targeted read's: the plant file's whole image, `desired` being cut to what was read — its other
    #: programs the line's record showed held (`prc3cfg.core.what_to_read`)
    wanted: ModuleImage | None = None

    def as_known(self, image: ModuleImage) -> ModuleImage:
        """`image` (the read-back, or what the plan leaves) with the programs taken as known filled in:
        what a picture of the module's chains shows, never a chain cut where a program was not read."""
        return image if self.wanted is None else with_known(image, self.wanted)

    @property
    def reading_time(self) -> float:
        """Seconds the read-back it was planned from took on the line: a 50h and the fewest 51h/52h."""
        read = [n for n, program in enumerate(self.actual.programs, 1) if program is not None]
        return 0.0 if self.cost is None else fsum(self.cost.message_time(self.address, m) for m in read_messages(read))

    @property
    def verifying_time(self) -> float:
        """Seconds the verifying read-back takes on the line (`Verify.FLOOR`: what the steps can change)."""
        return 0.0 if self.cost is None else verification_time(self.actual, self.plan.predicted, self.steps, self.cost)

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
class LineProof:
    """What a line's probes found at the addresses its plant file does not list (before a broadcast):
    `silent` — none answered, the broadcasts reach only the plan's modules; `answered` — modules the
    plant file does not know are on the line, so it gets no broadcast."""

    bus: str
    silent: tuple[int, ...] = ()
    answered: tuple[int, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return ({"proven_silent": list(self.silent)} if self.silent else {}) | (
            {"unlisted_modules": list(self.answered)} if self.answered else {})


@dataclass(frozen=True, slots=True)
class Reading:
    """How a plan's read-back was targeted (`prc3cfg.core.what_to_read`): the record it was compared with,
    in words, the modules not read at all (none: every module's system block is read), per module read
    the managed programs not read — taken as known from the record, with who verified them when
    (`taken`, "bus/name" → words) — and the modules read in full, each with why. A plan without one
    read every chosen module in full."""

    base: str
    modules_not_read: tuple[str, ...]  # "bus/name"
    programs_not_read: dict[tuple[str, int], tuple[int, ...]]
    not_as_verified: tuple[str, ...] = ()  # "bus/name (why)": read in full, not taken from the record
    taken: dict[str, str] = field(default_factory=dict)  # "bus/name" → whose read or verification its unread programs rest on, when

    def to_json(self) -> dict[str, Any]:
        return {"base": self.base, "modules_not_read": list(self.modules_not_read), "not_as_verified": list(self.not_as_verified),
                "taken": dict(self.taken)}  # fmt: skip

    def module_json(self, change: ModuleChange) -> dict[str, Any]:
        read = [n for n, program in enumerate(change.actual.programs, 1) if program is not None]
        return {"programs": read, "programs_not_read": list(self.programs_not_read.get((change.bus, change.address), ()))}


@dataclass(frozen=True, slots=True)
class PlantPlan:
    """Every module's change, the broadcasts of each bus, and what they cost on the line."""

    plant: str
    plant_path: str
    plant_sha256: str
    modules: tuple[ModuleChange, ...]
    broadcast_time: float = 0.0  # every bus's broadcasts, once each, and the probes that proved them safe
    unshared_bus_time: float | None = None  # the same changes without broadcasts, where some were shared
    proofs: tuple[LineProof, ...] = ()  # per line probed: what answered at the addresses the plant does not list
    reading: Reading | None = None  # a targeted read-back: what was read, what was taken as last verified

    def proof(self, bus: str) -> LineProof | None:
        return next((p for p in self.proofs if p.bus == bus), None)

    @property
    def changes(self) -> tuple[ModuleChange, ...]:
        return tuple(m for m in self.modules if m.steps)

    @property
    def bus_time(self) -> float:
        return fsum(m.plan.bus_time for m in self.modules) + self.broadcast_time

    def phases(self) -> dict[str, float]:
        """The time the operator waits for an apply of this plan, by phase — reading back, writing,
        verifying — each the longest of its lines' (the lines run at once, each line's modules one
        after another), by the bus-time model. Writing counts each line's broadcasts once; the
        probes that proved them are not counted."""
        lines = self.buses()

        def longest(seconds: Callable[[str, list[ModuleChange]], float]) -> float:
            return max((seconds(bus, modules) for bus, modules in lines.items()), default=0.0)

        def writing(bus: str, modules: list[ModuleChange]) -> float:
            cost = modules[0].cost
            shared = fsum(cost.broadcast_time(step.message) for step in self.broadcasts(bus)) if cost is not None else 0.0
            return fsum(m.plan.bus_time for m in modules) + shared

        return {
            "reading": longest(lambda _, modules: fsum(m.reading_time for m in modules)),
            "writing": longest(writing),
            "verifying": longest(lambda _, modules: fsum(m.verifying_time for m in modules)),
        }

    def broadcasts(self, bus: str) -> tuple[Step, ...]:
        """The steps sent once to address 0 on `bus`, before any module's own steps."""
        return next((m.steps[: m.broadcasts] for m in self.modules if m.bus == bus and m.broadcasts), ())

    @property
    def naive_bus_time(self) -> float:
        return fsum(m.plan.naive_bus_time for m in self.modules)

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
        phases = self.phases()
        return {
            "format": FORMAT,
            "prc3cfg_version": __version__,
            "plant": self.plant,
            "plant_path": self.plant_path,
            "plant_sha256": self.plant_sha256,
            "buses": [
                {"name": bus, "modules": [m.to_json() | ({"read": self.reading.module_json(m)} if self.reading else {}) for m in modules]}
                | (proof.to_json() if (proof := self.proof(bus)) is not None else {})
                | ({"broadcasts": [
                    {"message": step.message.hex(), "summary": step.summary, "releases_axes": step.releases_axes,
                     "modules": [m.address for m in modules if m.broadcasts]}
                    for step in self.broadcasts(bus)
                ]} if self.broadcasts(bus) else {})
                for bus, modules in self.buses().items()
            ],
            "estimated_bus_time_s": round(self.bus_time, 4),
            "naive_bus_time_s": round(self.naive_bus_time, 4),
            "estimated_phases_s": {phase: round(seconds, 3) for phase, seconds in phases.items()},
            "estimated_time_s": round(fsum(phases.values()), 3),
            "message_count": self.message_count,
            "axis_releases": [f"{m.bus}/{m.name}" for m in self.axis_releases],
        } | ({"without_broadcasts_bus_time_s": round(self.unshared_bus_time, 4)} if self.unshared_bus_time is not None else {}) | (
            {"read": self.reading.to_json()} if self.reading is not None else {})  # fmt: skip
