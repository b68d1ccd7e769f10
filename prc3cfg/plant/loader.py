"""`load_plant`: read a plant file, find every problem in it at once, or build the `Plant`.

    read YAML (`document`)  →  pydantic on the whole file (`models`, worded by `messages`)
                            →  rules on every part that is valid on its own (`rules`,
                               after `profiles`)  →  `Plant`, or `PlantError`

The rules run on the parts that validated even when others did not: each profile, each
bus's line settings and each module is validated on its own, so that one unknown key
does not hide a P > S1 three modules further down. A module whose profiles are unknown
or invalid is not checked further (its profile's problems are reported already).
All problems come back sorted by line and column, one line each. Where the reading itself
found a problem (`010`, `on`, a decimal comma), that is the one said there; the models'
objection to the same value only lends it their "what to do" when the reading's problem
asks for that (`Problem.models_fix`: "… read as true by YAML 1.1 and as text by YAML 1.2 —
give a number in m").
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

from prc3cfg.plant import rules
from prc3cfg.plant.document import Document, Position, mappings_in, read_document
from prc3cfg.plant.messages import from_pydantic
from prc3cfg.plant.models import BusLine, ModuleSpec, PlantSpec, ProfileSpec
from prc3cfg.plant.plant import Bus, Module, Plant
from prc3cfg.plant.problems import Path_, PlantError, Problem
from prc3cfg.plant.profiles import module_layers, resolve

M = TypeVar("M", bound=BaseModel)


def load_plant(path: str | Path) -> Plant:
    """The plant in `path`; `PlantError` with every problem ("file:line:column: …") otherwise."""
    path = Path(path)
    document = read_document(path)
    problems: list[Problem] = []
    try:
        PlantSpec.model_validate(document.data)
    except ValidationError as error:
        problems += filter(None, (from_pydantic(e, document.data) for e in error.errors(include_url=False)))
    problems += rules.check_unique(document.data)
    profiles = dict(_profiles(document.data))
    buses = []
    for bus_path, raw_bus in mappings_in(document.data, ("buses",)):
        line = _valid(BusLine, {k: v for k, v in raw_bus.items() if k != "modules"})
        problems += rules.check_bus(bus_path, line) if line else []
        modules = []
        for module_path, raw_module in mappings_in(raw_bus, bus_path + ("modules",)):
            module = _valid(ModuleSpec, raw_module)
            if module is not None:
                found, built = _module(module, module_path, profiles)
                problems += found
                modules.append(built)
        buses.append((line, modules))
    if problems or document.problems:
        raise PlantError(_lines(document, problems))
    return Plant(
        name=document.data["plant"],
        buses=tuple(Bus(**{k: getattr(line, k) for k in line.model_fields_set}, modules=tuple(modules)) for line, modules in buses),
        path=path,
        sha256=document.sha256,
    )


def _lines(document: Document, problems: list[Problem]) -> list[str]:
    """Every problem as one line, sorted; at a place where reading found one, the models' only lend a fix."""
    read = {document.format(p): p for p in document.problems}
    places = {at for at, _ in read}
    fixes: dict[Position, str] = {}
    lines = set()
    for at, text in sorted(map(document.format, problems)):
        if at in places:
            fixes.setdefault(at, text.partition(" — ")[2])
        else:
            lines.add((at, text))
    for (at, text), problem in read.items():
        if problem.models_fix and at in fixes:
            text = f"{text.partition(' — ')[0]} — {fixes[at]}"
        lines.add((at, text))
    return [text for _, text in sorted(lines)]


def _module(module: ModuleSpec, path: Path_, profiles: Mapping[str, ProfileSpec | None]) -> tuple[list[Problem], Module | None]:
    """The problems of one module, and the module when it has none."""
    unknown = [
        Problem(path + ("profiles", k), f"unknown profile '{name}' — "
                + (f"the profiles are {', '.join(profiles)}" if profiles else "the file has no profiles: section"))
        for k, name in enumerate(module.profiles) if name not in profiles
    ]
    if unknown or any(profiles[name] is None for name in module.profiles):
        return unknown, None
    settings = resolve(module_layers(module, path, profiles))
    problems = rules.check_module(module.name, path, settings)
    built = Module(address=module.address, name=module.name, profiles=module.profiles,
                   unmanaged_programs=settings.unmanaged_programs.value, settings=settings)
    return problems, built


def _profiles(data: dict[Any, Any]) -> Iterator[tuple[str, ProfileSpec | None]]:
    """Every profile name, with the profile or None when it is not valid."""
    profiles = data.get("profiles")
    for name, raw in (profiles.items() if isinstance(profiles, dict) else ()):
        if isinstance(name, str):
            yield name, _valid(ProfileSpec, raw)


def _valid(model: type[M], data: Any) -> M | None:
    try:
        return model.model_validate(data)
    except ValidationError:
        return None
