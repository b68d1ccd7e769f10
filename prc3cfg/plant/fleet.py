"""Fleet files (`prc3cfg-fleet/1`, docs/fleet.md): read and validated with file:line:col.

    format: prc3cfg-fleet/1
    plants:
      - plant: plants/paint-shop.yaml
        lines:
          - {bus: booth-a, runner: line-booth-a, environment: booth-a}
          - {bus: booth-b, runner: line-booth-b}

`parse_fleet` reads the bytes with the plant file's YAML reader (`document`: positions, no aliases, no tags)
and the models here (`fleet_schema`: `schemas/fleet.schema.json`); `lines` then checks each line against its
plant file (the bus is one of its buses) and builds `core.fleet.FleetLine`s, or raises `PlantError` with one
line per problem, at the fleet file's key or value. Plant file paths are relative to the fleet file. Pure: the
shell reads the files (`prc3cfg.cli.fleet_commands`).
"""

from __future__ import annotations

import json
import posixpath
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

from pydantic import Field, ValidationError

from prc3cfg.core.fleet import FleetLine
from prc3cfg.plant.document import Document, parse_document
from prc3cfg.plant.models import Draft07, FileModel, Name, Text
from prc3cfg.plant.plant import Plant
from prc3cfg.plant.problems import PlantError, Problem

FORMAT = "prc3cfg-fleet/1"


class LineSpec(FileModel):
    """One bus of the plant file, and where its jobs run."""

    bus: Name = Field(description="the bus, as the plant file names it", examples=["booth-a"])
    runner: Text = Field(description="the label of the self-hosted runner beside the line",
                         examples=["line-booth-a"])
    environment: Name | None = Field(None, description="the GitHub environment whose required reviewers "
                                                       "approve an apply to "
                                                       "the line (default: the bus's name)")


class FleetPlant(FileModel):
    """A plant file and its lines."""

    plant: Text = Field(description="the plant file, relative to the fleet file",
                        examples=["plants/paint-shop.yaml"])
    lines: tuple[LineSpec, ...] = Field(min_length=1, description="its buses, each a line")


class FleetSpec(FileModel):
    """A fleet file: every plant file's lines and the runner at each."""

    format: Literal["prc3cfg-fleet/1"] = Field(description="the format of this file")
    plants: tuple[FleetPlant, ...] = Field(min_length=1, description="the plant files of the fleet")


@dataclass(frozen=True)
class Fleet:
    """A fleet file read: its specification and its document (for places)."""

    spec: FleetSpec
    document: Document

    def plant_paths(self) -> list[str]:
        """Each plant file's path relative to the fleet file's folder, normalised (POSIX)."""
        folder = posixpath.dirname(self.document.name.replace("\\", "/"))
        return [posixpath.normpath(posixpath.join(folder, p.plant)) for p in self.spec.plants]


def parse_fleet(path: str, data: bytes) -> Fleet:
    """The fleet in `data`, the bytes of the file `path`; `PlantError` with one line per problem otherwise."""
    document = parse_document(path, data)
    problems = list(document.problems)
    try:
        spec = FleetSpec.model_validate(document.data)
    except ValidationError as error:
        errors = error.errors(include_url=False)
        # a list too short *after* an item of it failed says that item's problem again
        # the places an error is inside of
        within = [e["loc"][:n] for e in errors for n in range(len(e["loc"]))]
        problems += [_problem(e) for e in errors if not (e["type"] == "too_short" and e["loc"] in within)]
        raise PlantError([text for _, text in sorted(document.lines(problems))]) from None
    if problems:
        raise PlantError([text for _, text in sorted(document.lines(problems))])
    return Fleet(spec, document)


def lines(fleet: Fleet, load: Callable[[str], Plant]) -> list[FleetLine]:
    """The fleet's lines, each bus checked against its plant file (`load`: the plant file at a path the fleet
    gives, relative to the current folder); `PlantError` naming the fleet file's place of every bus no plant
    file has, or of a line named twice."""
    found: list[FleetLine] = []
    problems: list[Problem] = []
    seen: dict[str, tuple[str | int, ...]] = {}
    for p, (spec, path) in enumerate(zip(fleet.spec.plants, fleet.plant_paths(), strict=True)):
        plant = load(path)
        buses: Mapping[str, Any] = {bus.name: bus for bus in plant.buses}
        policy = (None if plant.policy_path is None
                  else posixpath.normpath(str(plant.policy_path).replace("\\", "/")))
        for n, line in enumerate(spec.lines):
            at = ("plants", p, "lines", n, "bus")
            if line.bus not in buses:
                problems.append(Problem(at, f"bus '{line.bus}' is not in {path} — it has "
                                            f"{', '.join(sorted(buses))}"))
                continue
            made = FleetLine(path, line.bus, line.runner, line.environment or line.bus,
                             tuple(m.name for m in buses[line.bus].modules), policy)
            if made.id in seen:
                problems.append(Problem(at, f"line {made.name} is named twice (or its id {made.id} is "
                                            "another line's) — name each line once",
                                        first=seen[made.id]))
                continue
            seen[made.id] = at
            found.append(made)
    if problems:
        raise PlantError([text for _, text in sorted(fleet.document.lines(problems))])
    return found


def _problem(error: Any) -> Problem:
    """A pydantic error about a fleet file in words, at its key or value."""
    loc, kind = tuple(error["loc"]), error["type"]
    key = loc[-1] if loc else "the file"
    if kind == "missing":
        return Problem(loc, f"'{key}' is missing — see docs/fleet.md", at_key=True)
    if kind == "extra_forbidden":
        return Problem(loc, f"unknown key '{key}' — see schemas/fleet.schema.json", at_key=True)
    if kind == "literal_error":
        return Problem(loc, f"'{key}' is {error['input']!r} — it is {error.get('ctx', {}).get('expected')}")
    return Problem(loc, f"'{key}' is not valid ({error['msg'].lower()}) — see schemas/fleet.schema.json")


def fleet_schema() -> dict[str, Any]:
    """The JSON Schema of a fleet file (draft-07)."""
    schema = FleetSpec.model_json_schema(ref_template="#/definitions/{model}", schema_generator=Draft07)
    return schema | {"$id": "urn:prc3cfg:fleet", "title": FORMAT}


def fleet_schema_text() -> str:
    """The schema as `schemas/fleet.schema.json` holds it."""
    return json.dumps(fleet_schema(), indent=2, ensure_ascii=False) + "\n"
