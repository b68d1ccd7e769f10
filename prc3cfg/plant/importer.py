"""A plant file written from live modules (`prc3cfg import`).

Human units from `prc3cfg.core.units`; only non-default system parameters and programs
(plus every program a jump starts or ends at); `unmanaged_programs: reset`, so planning
the written file against the same bus is empty. Jumps become chains where a chain can say
them — a path that ends in A = 0, or a loop — and `next:` on the program otherwise (a
program that two others continue with, a path running into a loop or into another chain).
What every module holds alike (a system parameter, a program's field, the chains) goes once
into the profile `common` (`shared_profile`), and each module keeps only what differs: each
module's effective settings are exactly its own entry's. The file starts with the schema line
for editors (`plant.schema.json` beside it: `prc3cfg schema > plant.schema.json`).
Pure: images in, YAML text out.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from decimal import Decimal
from typing import Any

import yaml

from prc3cfg.core.chains import jumps_as_chains
from prc3cfg.core.image import DEFAULT_SYSTEM, SYSTEM_KEYS, ModuleImage, Program, default_program
from prc3cfg.core.line import LineSettings
from prc3cfg.core.units import BY_SYMBOL, FUNCTION_OUTPUTS, PROGRAM_QUANTITIES, plant_value
from prc3cfg.plant.profiles import PROGRAM_DEFAULTS


def _program_entry(program: Program, next_program: int | None) -> dict[str, Any]:
    entry: dict[str, Any] = {q.key: plant_value(q.symbol, getattr(program, q.symbol))
                             for q in PROGRAM_QUANTITIES
                             # an omitted key means 0
                             if q.key not in PROGRAM_DEFAULTS or getattr(program, q.symbol)}
    for symbol in FUNCTION_OUTPUTS:
        if value := getattr(program, symbol):
            entry[symbol.lower()] = plant_value(symbol, value)
    if next_program is not None:
        entry["next"] = next_program
    return entry


#: The name of the profile of what every imported module holds alike.
SHARED = "common"
#: The schema the written file names for editors, beside it (`prc3cfg schema` prints it).
SCHEMA = "plant.schema.json"


def module_entry(image: ModuleImage, name: str) -> dict[str, Any]:
    """One module of a plant file, from its complete image."""
    system = {
        BY_SYMBOL[key].key: plant_value(key, getattr(image.system, key))
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


def _alike(mappings: list[dict[Any, Any]]) -> dict[Any, Any]:
    """The keys every mapping has with the same value, in the first's order."""
    first, *rest = mappings
    return {key: value for key, value in first.items()
            if all(key in other and other[key] == value for other in rest)}


def shared_profile(entries: list[dict[str, Any]]) -> tuple[dict[str, Any] | None, list[dict[str, Any]]]:
    """What every module entry (`module_entry`) holds alike, as a profile, and the entries using it with
    only what differs; with fewer than two modules, no profile and the entries as they are."""
    if len(entries) < 2:
        return None, entries
    profile = _common(entries)
    return profile, [_own(entry, profile) for entry in entries]


def _common(entries: list[dict[str, Any]]) -> dict[str, Any]:
    """The profile of what every module entry holds alike: system parameters, each program's fields
    (of a program every entry lists), the chains and `unmanaged_programs`."""
    profile: dict[str, Any] = {}
    if system := _alike([entry.get("system", {}) for entry in entries]):
        profile["system"] = system
    listed = [entry.get("programs", {}) for entry in entries]
    programs = {number: fields for number in listed[0] if all(number in other for other in listed[1:])
                and (fields := _alike([other[number] for other in listed]))}
    if programs:
        profile["programs"] = programs
    profile |= {key: value for key, value in _alike(entries).items()
                if key in ("chains", "unmanaged_programs")}
    return profile


def _own(entry: dict[str, Any], profile: dict[str, Any]) -> dict[str, Any]:
    """A module entry that uses `profile`: what it holds that the profile does not."""
    system, programs = profile.get("system", {}), profile.get("programs", {})
    module: dict[str, Any] = {"address": entry["address"], "name": entry["name"], "profiles": [SHARED]}
    if own := {key: value for key, value in entry.get("system", {}).items() if key not in system}:
        module["system"] = own
    own = {number: rest for number, fields in entry.get("programs", {}).items()
           if (rest := {key: value for key, value in fields.items() if key not in programs.get(number, {})})}
    if own:
        module["programs"] = own
    module |= {key: entry[key] for key in ("chains", "unmanaged_programs") if key in entry
               and key not in profile}
    return module


class _Dumper(yaml.SafeDumper):
    pass


class _OneLine(dict):
    """A mapping written on one line: a module with nothing of its own but its profile."""


_Dumper.add_representer(Decimal, lambda dumper,
                        value: dumper.represent_scalar("tag:yaml.org,2002:float", str(value)))
_Dumper.add_representer(_OneLine, lambda dumper,
                        value: dumper.represent_mapping("tag:yaml.org,2002:map", value, flow_style=True))


def bus_entry(name: str, port: str, framing: str, line: LineSettings, timeout: float,
              zvz: float) -> dict[str, Any]:
    """A bus of a plant file, without its modules: the line the modules were read on (its `zvz` on
    open-driver only, where it counts)."""
    bus: dict[str, Any] = {"name": name, "port": port, "framing": framing, "baud": line.baud,
                           "parity": line.parity,
                           "data_bits": line.data_bits, "stop_bits": line.stop_bits,
                           "timeout": Decimal(str(timeout))}
    if framing == "open-driver":
        bus["zvz"] = Decimal(str(zvz))
    return bus


def imported_plant(plant: str, buses: Sequence[tuple[dict[str, Any], Iterable[ModuleImage]]]) -> str:
    """The plant file of these buses (`bus_entry`) holding these modules, each named BUS-ADDRESS."""
    return plant_yaml(plant, [(bus, [module_entry(image, f"{bus['name']}-{image.address}")
                                     for image in images])
                              for bus, images in buses])


def plant_yaml(plant: str, buses: Sequence[tuple[dict[str, Any], list[dict[str, Any]]]],
               schema: str = SCHEMA) -> str:
    """The YAML text of a plant file of buses with their `module_entry`s: what every module of every bus
    holds alike in one profile."""
    profile, modules = shared_profile([module for _, entries in buses for module in entries])
    document: dict[str, Any] = {"plant": plant}
    if profile is not None:
        document["profiles"] = {SHARED: profile}
    document["buses"] = []
    for bus, entries in buses:
        own, modules = modules[: len(entries)], modules[len(entries) :]
        one_line = [_OneLine(m) if m.keys() <= {"address", "name", "profiles"} else m for m in own]
        document["buses"].append({**bus, "modules": one_line})
    head = f"# yaml-language-server: $schema={schema}\n"
    return head + yaml.dump(document, Dumper=_Dumper, sort_keys=False, default_flow_style=None, width=110)
