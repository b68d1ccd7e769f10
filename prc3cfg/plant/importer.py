"""A plant file written from live modules (`prc3cfg import`).

Human units from `prc3cfg.core.units`; only non-default system parameters and programs
(plus every program a jump starts or ends at); `unmanaged_programs: reset`, so planning
the written file against the same bus is empty. Jumps become chains where a chain can say
them — a path that ends in A = 0, or a loop — and `next:` on the program otherwise (a
program that two others continue with, a path running into a loop or into another chain).
Pure: images in, YAML text out.
"""

from __future__ import annotations

from decimal import Decimal
from typing import Any

import yaml

from prc3cfg.core.chains import jumps_as_chains
from prc3cfg.core.image import DEFAULT_SYSTEM, SYSTEM_KEYS, ModuleImage, Program, default_program
from prc3cfg.core.units import BY_SYMBOL, split_function_output

PROGRAM_KEYS = {"P": "position", "V": "speed", "Vr": "relative_speed", "T": "dwell"}


def _human(symbol: str, device: int) -> Decimal | int | bool:
    return BY_SYMBOL[symbol].to_human(device)


def _program_entry(program: Program, next_program: int | None) -> dict[str, Any]:
    entry: dict[str, Any] = {PROGRAM_KEYS[k]: _human(k, getattr(program, k)) for k in ("P", "V")}
    entry.update({PROGRAM_KEYS[k]: _human(k, getattr(program, k)) for k in ("Vr", "T") if getattr(program, k)})
    for key in ("F1", "F2"):
        if value := getattr(program, key):
            action, distance = split_function_output(value)
            entry[key.lower()] = {"action": action, "distance": distance}
    if next_program is not None:
        entry["next"] = next_program
    return entry


def module_entry(image: ModuleImage, name: str) -> dict[str, Any]:
    """One module of a plant file, from its complete image."""
    system = {
        BY_SYMBOL[key].key: _human(key, getattr(image.system, key))
        for key in SYSTEM_KEYS
        if getattr(image.system, key) != getattr(DEFAULT_SYSTEM, key)
    }
    programs = dict(enumerate(image.complete(), start=1))
    chains, nexts = jumps_as_chains(programs)
    jumping = set(nexts) | set(nexts.values()) | {
        n for c in chains for n in (c["programs"] if isinstance(c, dict) else c)
    }
    default = default_program(image.system)
    listed = {n: p for n, p in programs.items() if p != default or n in jumping}
    entry: dict[str, Any] = {"address": image.address, "name": name}
    if system:
        entry["system"] = system
    if listed:
        entry["programs"] = {n: _program_entry(p, nexts.get(n)) for n, p in listed.items()}
    if chains:
        entry["chains"] = chains
    entry["unmanaged_programs"] = "reset"
    return entry


class _Dumper(yaml.SafeDumper):
    pass


_Dumper.add_representer(Decimal, lambda dumper, value: dumper.represent_scalar("tag:yaml.org,2002:float", str(value)))


def plant_yaml(plant: str, bus: dict[str, Any], modules: list[dict[str, Any]], schema: str | None = None) -> str:
    """The YAML text of a one-bus plant file."""
    document = {"plant": plant, "buses": [{**bus, "modules": modules}]}
    head = f"# yaml-language-server: $schema={schema}\n" if schema else ""
    return head + yaml.dump(document, Dumper=_Dumper, sort_keys=False, default_flow_style=None, width=110)
