"""Configuration status: what prc3cfg's records say of each module, and the health that follows from it —
the `prc3cfg-status/1` document of `prc3cfg status --json` (`schemas/status.schema.json`) and the values
`prc3cfg status serve` publishes on OPC UA.

Health is the OPC UA for Devices (DI) `DeviceHealthEnumeration`, decided by one table (`RULES`), first
row that holds wins:

    an apply runs on the line (its lock held)               CHECK_FUNCTION      ("change of configuration")
    the module's last apply failed on it                     FAILURE
    reference travel pending, drift seen, evidence too old   MAINTENANCE_REQUIRED
    otherwise                                                NORMAL

Owns the facts a module's status is made of, the table and the document's shape. Pure: the values come
from `prc3cfg.shell.status`, which reads the records; nothing here touches a file or the bus.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

from prc3cfg.core.image import ModuleImage

FORMAT = "prc3cfg-status/1"


class Health(IntEnum):
    """DI's DeviceHealthEnumeration: the values are the ones OPC UA clients show."""

    NORMAL = 0
    FAILURE = 1
    CHECK_FUNCTION = 2
    OFF_SPEC = 3
    MAINTENANCE_REQUIRED = 4


@dataclass(frozen=True, slots=True)
class LastVerified:
    """The last verified apply or restore that changed a module, as its journal's header says it (text: a
    record may say anything; None where it says nothing)."""

    time: str
    by: str | None
    plant_file: str | None
    plant_sha256: str | None
    commit: str | None


@dataclass(frozen=True, slots=True)
class ModuleFacts:
    """What the records say of one module. `evidence_age` and `evidence_bound` in seconds: how old the
    oldest value the line's record holds of it is, and the bus's `record_max_age` (age None: no record)."""

    bus: str
    address: int
    name: str
    revision: int  # verified applies and restores that changed it
    last_verified: LastVerified | None
    last_failed: bool  # the newest run that wrote it did not verify it
    apply_running: bool
    travel_pending: bool
    drift_seen: bool
    evidence_age: float | None
    evidence_bound: float
    firmware: str = ""  # no PRC 3 message names it: empty until a module can tell (docs/status.md)


def _evidence_too_old(facts: ModuleFacts) -> bool:
    return facts.evidence_age is None or facts.evidence_age > facts.evidence_bound


#: (what holds, the health it gives, the reason in words): the first row that holds decides.
RULES: tuple[tuple[Callable[[ModuleFacts], bool], Health, str], ...] = (
    (lambda f: f.apply_running, Health.CHECK_FUNCTION, "an apply runs on the line"),
    (lambda f: f.last_failed, Health.FAILURE, "the last apply that wrote it did not verify it"),
    (lambda f: f.travel_pending, Health.MAINTENANCE_REQUIRED, "reference travel pending"),
    (lambda f: f.drift_seen, Health.MAINTENANCE_REQUIRED, "drift seen at the last read"),
    (_evidence_too_old, Health.MAINTENANCE_REQUIRED, "no evidence within record_max_age"),
)


def health(facts: ModuleFacts) -> tuple[Health, str]:
    """The module's health and why (NORMAL: "")."""
    for holds, value, why in RULES:
        if holds(facts):
            return value, why
    return Health.NORMAL, ""


def drifted(desired: ModuleImage, recorded: ModuleImage) -> bool:
    """Whether what the record says the module holds differs from the plant file where both say something
    (a program the record does not know, or the plant file does not manage, is no drift)."""
    return desired.system != recorded.system or any(d is not None and r is not None and d != r
                                                    for d, r in zip(desired.programs, recorded.programs))


def worst(values: Sequence[Health]) -> Health:
    """A line's health: its modules' most pressing (CHECK_FUNCTION over FAILURE over MAINTENANCE_REQUIRED over
    NORMAL)."""
    order = [value for _, value, _ in RULES] + [Health.NORMAL]
    return min(values, key=order.index, default=Health.NORMAL)


def module_json(facts: ModuleFacts) -> dict[str, Any]:
    value, why = health(facts)
    last = facts.last_verified
    return {"bus": facts.bus, "address": facts.address, "name": facts.name, "health": value.name,
            "health_value": int(value),
            "why": why, "revision_counter": facts.revision, "software_revision": facts.firmware,
            "last_verified": None if last is None
            else {"time": last.time, "by": last.by, "plant_file": last.plant_file,
                                                         "plant_sha256": last.plant_sha256,
                  "commit": last.commit},
            "apply_running": facts.apply_running, "last_failed": facts.last_failed,
            "travel_pending": facts.travel_pending,
            "drift_seen": facts.drift_seen, "evidence_age_s": facts.evidence_age,
            "evidence_bound_s": facts.evidence_bound}


def document(plant_file: str, plant_sha256: str, modules: Sequence[ModuleFacts],
             notes: Sequence[str] = ()) -> dict[str, Any]:
    """`prc3cfg status --json`: the plant file, and per line (bus) its health and its modules' status."""
    lines: dict[str, list[ModuleFacts]] = {}
    for facts in modules:
        lines.setdefault(facts.bus, []).append(facts)
    return {"format": FORMAT, "plant_file": plant_file, "plant_sha256": plant_sha256,
            "lines": [{"bus": bus, "health": worst([health(f)[0] for f in found]).name,
                       "apply_running": any(f.apply_running for f in found),
                       "modules": [module_json(f) for f in found]} for bus, found in lines.items()],
            "notes": list(notes)}
