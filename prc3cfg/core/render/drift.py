"""What `read` and drift say of modules: a module as read (`image_lines`), and a module that holds something
other than the plant file says (`Drift`), as lines (`drift_lines`) and as a document (`drift_json`; the
comment is `prc3cfg.core.render.comment`'s). Pure: returns strings and dicts.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from prc3cfg.core.image import ModuleImage
from prc3cfg.core.render.words import field_name, format_value, plural
from prc3cfg.core.text import number_runs


def image_lines(bus: str, name: str, image: ModuleImage) -> list[str]:
    """A module as `prc3cfg read` shows it: where it is, its system parameters, each program read — and the
    programs it did not read, which `read` leaves alone (the plant file does not manage them, and its system
    parameters cannot clamp them)."""
    lines = [f"bus {bus}, module {image.address} ({name})",
             "  system: "
             + ", ".join(f"{field_name(k)} {format_value(k, v)}" for k, v in image.system.to_json().items())]
    for number, program in enumerate(image.programs, start=1):
        if program is not None:
            values = ", ".join(f"{field_name(k)} {format_value(k, v)}"
                               for k, v in program.to_json().items() if k != "A")
            lines.append(f"  program {number}: {values}" + (f", next {program.A}" if program.A else ""))
    unread = [number for number, program in enumerate(image.programs, start=1) if program is None]
    if unread:
        lines.append(f"  not read: program{'s' if len(unread) > 1 else ''} {number_runs(unread)} — the plant "
                     "file leaves them alone, and its system parameters cannot clamp them")
    return lines


@dataclass(frozen=True)
class Drift:
    """A module that holds something other than the plant file says (Teach In, work on the
    floor): each difference one line in human units, what the file says → what the module holds,
    "program 3 position 1.200 m → 1.150 m" (as `adopt` shows it)."""

    bus: str
    address: int
    name: str
    differences: tuple[str, ...]
    #: the same differences as fields, before and after (`drift_changes`)
    changes: tuple[dict[str, Any], ...] = ()


def drift_lines(drifts: Sequence[Drift], modules: int) -> list[str]:
    """Drift as drift, not as a plan: each module that drifted, its differences, and how many of the
    `modules` read drifted."""
    lines = []
    for found in drifts:
        lines.append(f"~ bus {found.bus}, module {found.address} ({found.name}) drifted from the plant file "
                     "(file → module):")
        lines.extend(f"    {text}" for text in found.differences)
    if drifts:
        lines.append(f"Drift: {len(drifts)} of {plural(modules, 'module')} "
                     f"hold{'s' if len(drifts) == 1 else ''} "
                     "something other than the plant file says.")
    else:
        lines.append("No drift: every module holds what the plant file says.")
    return lines


#: Marks the pull-request comment drift is posted as (`plan --refresh-only --markdown`).
DRIFT_MARKER = "<!-- prc3cfg-drift -->"
DRIFT_FORMAT = "prc3cfg-drift/1"


def drift_json(plant: str, drifts: Sequence[Drift], modules: int) -> dict[str, Any]:
    """Drift as a document (`plan --refresh-only --json`, `--out`): the plant, how many modules were
    read, and each module that drifted with its differences (file → module): in human units, and as
    `changes` of a field from before to after (`drift_changes`)."""
    return {"format": DRIFT_FORMAT, "plant": plant, "modules": modules,
            "drifted": [{"bus": d.bus, "address": d.address, "name": d.name,
                         "differences": list(d.differences),
                         "changes": list(d.changes)} for d in drifts]}
