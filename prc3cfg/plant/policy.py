"""Policy files (`prc3cfg-policy/1`, docs/policy.md): read, validated with file:line:col, and their findings
placed.

    format: prc3cfg-policy/1
    envelopes:
      - {name: booth speeds, level: hard, buses: [booth-*], limits: {speed: {max: 0.400}}}
    windows:
      - {name: production, kind: deny, level: soft, cron: "0 6 * * 1-5", duration: 10h, time_zone:
        Europe/Berlin}

The plant file names its policy (`policy: line-rules.yaml`, relative to it). `parse_policy` reads the bytes
with the plant file's YAML reader (`document`: exact numbers, no aliases, positions) and the models here
(`policy_schema`: `schemas/policy.schema.json`), and builds `core.policy.Policy`, or raises `PlantError`
with one line per problem. `plant_values` gives the values of modules' desired images with their places;
`placed` says a finding as one line at the plant file's value (or the rule) naming the other place too.
`approvers:` is documentation only (docs/policy.md: the forge's CODEOWNERS and environments enforce it).
Pure: the shell reads the files (`prc3cfg.shell.plant_files.load_policy`).
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Set
from dataclasses import dataclass
from datetime import timedelta
from decimal import Decimal
from pathlib import Path
from typing import Annotated, Any, Literal
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from pydantic import AfterValidator, Field, PlainValidator, ValidationError, WithJsonSchema

from prc3cfg.core import motion, policy
from prc3cfg.core.units import QUANTITIES
from prc3cfg.plant.document import Document, parse_document
from prc3cfg.plant.models import Draft07, FileModel, Name, Text
from prc3cfg.plant.plant import Bus, Module
from prc3cfg.plant.problems import Finding, Path_, PlantError, Problem

FORMAT = "prc3cfg-policy/1"
POSITION = QUANTITIES["position"]
#: A duration: whole days, hours and minutes, in that order ("10h", "1h30m", "2d").
_DURATION = re.compile(r"(?:(\d+)d)?(?:(\d+)h)?(?:(\d+)m)?")
#: Longest a window may last: a start is looked for this far back.
MAX_DURATION = timedelta(days=31)
LimitKey = Literal["position", "speed", "relative_speed", "dwell", "function_distance",
                   "upper_reversing_point", "reference_point",
                   "max_speed", "min_speed", "acceleration", "sync_conveyor_sequence", "stroke_length",
                   "pass_time"]


def _number(value: Any) -> Decimal:
    if isinstance(value, bool) or not isinstance(value, Decimal | int):
        raise ValueError(f"{value!r} is not a number — give one in the plant file's units (m, m/s, s)")
    return Decimal(value)


Number = Annotated[Decimal, PlainValidator(_number), WithJsonSchema({"type": "number"})]
Globs = tuple[Annotated[Text, Field(description="a name, or a glob (booth-*)")], ...]


def _cron(text: str) -> str:
    policy.parse_cron(text)
    return text


def _duration(text: str) -> str:
    match = _DURATION.fullmatch(text)
    if not text or match is None:
        raise ValueError("a duration is days, hours and minutes as 2d, 10h, 1h30m")
    if not timedelta(minutes=1) <= _as_timedelta(text) <= MAX_DURATION:
        raise ValueError("a window lasts from 1m to 31d")
    return text


def _as_timedelta(text: str) -> timedelta:
    match = _DURATION.fullmatch(text)
    assert match is not None
    days, hours, minutes = (int(part or 0) for part in match.groups())
    return timedelta(days=days, hours=hours, minutes=minutes)


def _zone(text: str) -> str:
    try:
        ZoneInfo(text)
    except (ZoneInfoNotFoundError, ValueError):
        raise ValueError(f"'{text}' is not an IANA time zone — write one such as Europe/Berlin or "
                         "America/New_York") from None
    return text


class LimitSpec(FileModel):
    """Bounds in the plant file's human units (m, m/s, s)."""

    min: Number | None = Field(None, description="the lowest value allowed")
    max: Number | None = Field(None, description="the highest value allowed")


class EnvelopeSpec(FileModel):
    """Limits the modules it covers may reach: program fields in every managed program, system parameters."""

    name: Name = Field(description="what the rule is called in findings", examples=["booth speeds"])
    level: Literal["advisory", "soft",
                   "hard"] = Field("hard", description="advisory: warn; soft: refused unless overridden; "
                                                       "hard: refused")
    buses: Globs = Field((), description="the buses covered (all when left out)")
    modules: Globs = Field((), description="the modules covered, by name or glob (all when left out)")
    limits: dict[LimitKey, LimitSpec] = Field(min_length=1, description="bounds by plant-file key")


class WindowSpec(FileModel):
    """A time a change may not (deny) or may only (allow) be applied in."""

    name: Name = Field(description="what the window is called in findings", examples=["production"])
    kind: Literal["deny", "allow"] = Field(description="deny: apply refused while open (deny wins); allow: "
                                                       "refused outside every allow window")
    level: Literal["advisory", "soft", "hard"] = Field(
        "soft", description="soft: --override-window REASON applies anyway")
    cron: Annotated[Text, AfterValidator(_cron)] = Field(
        description="when it opens: minute hour day-of-month month day-of-week", examples=["0 6 * * 1-5"])
    duration: Annotated[Text, AfterValidator(_duration)] = Field(
        description="how long it stays open: 10h, 1h30m, 2d", examples=["10h"])
    time_zone: Annotated[Text, AfterValidator(_zone)] = Field(
        description="the IANA time zone the cron is read in", examples=["Europe/Berlin"])
    buses: Globs = Field((), description="the buses covered (all when left out)")


class PolicySpec(FileModel):
    """A policy file: envelopes, windows and (as documentation) approvers."""

    format: Literal["prc3cfg-policy/1"] = Field(description="the format of this file")
    envelopes: tuple[EnvelopeSpec, ...] = ()
    windows: tuple[WindowSpec, ...] = ()
    approvers: dict[Name, tuple[Text, ...]] | None = Field(
        None, description="teams that approve a change to each bus — documentation: enforced by CODEOWNERS "
                          "and environments")


@dataclass(frozen=True)
class LoadedPolicy:
    """A policy file: its rules, its name and SHA-256 (shown in every plan), and its document (for places)."""

    path: Path
    sha256: str
    rules: policy.Policy
    document: Document


def parse_policy(path: str | Path, data: bytes) -> LoadedPolicy:
    """The policy in `data`, the bytes of the file `path`; `PlantError` with one line per problem
    otherwise."""
    document = parse_document(str(path), data)
    problems = list(document.problems)
    try:
        spec = PolicySpec.model_validate(document.data)
    except ValidationError as error:
        problems += [_problem(e) for e in error.errors(include_url=False)]
        raise PlantError([text for _, text in sorted(document.lines(problems))]) from None
    if problems:
        raise PlantError([text for _, text in sorted(document.lines(problems))])
    envelopes = tuple(policy.Envelope(e.name, e.level, e.buses, e.modules, _limits(e, n), ("envelopes", n))
                      for n, e in enumerate(spec.envelopes))
    windows = tuple(_window(w, n) for n, w in enumerate(spec.windows))
    return LoadedPolicy(Path(path), document.sha256, policy.Policy(envelopes, windows), document)


def _limits(envelope: EnvelopeSpec, n: int) -> tuple[policy.Limit, ...]:
    return tuple(policy.Limit(key, limit.min, limit.max, ("envelopes", n, "limits", key))
                 for key, limit in envelope.limits.items())


def _window(window: WindowSpec, n: int) -> policy.Window:
    return policy.Window(window.name, window.level, window.kind, policy.parse_cron(window.cron),
                         _as_timedelta(window.duration),
                         ZoneInfo(window.time_zone), window.buses, ("windows", n))


def _problem(error: Any) -> Problem:
    """A pydantic error about a policy file in a plant engineer's words, at its key or value."""
    loc, kind, ctx = tuple(error["loc"]), error["type"], error.get("ctx", {})
    key = loc[-1] if loc else "the file"
    if kind == "missing":
        return Problem(loc, f"'{key}' is missing — see docs/policy.md", at_key=True)
    if kind == "extra_forbidden":
        return Problem(loc, f"unknown key '{key}' — see schemas/policy.schema.json", at_key=True)
    if kind in ("literal_error", "enum"):
        return Problem(loc, f"'{key}' is {error['input']!r} — it is one of {ctx.get('expected')}")
    if kind == "value_error":
        return Problem(loc, f"'{key}': {ctx.get('error')}")
    return Problem(loc, f"'{key}' is not valid ({error['msg'].lower()}) — see schemas/policy.schema.json")


def plant_values(pairs: Iterable[tuple[Bus, Module]], keys: Set[str]) -> list[policy.Value]:
    """Every value of the limited `keys` each module's settings reach (its desired image in human units), with
    its place: a default the file does not write is placed at the module, a chain's motion at its first
    program."""
    values = []
    for bus, module in pairs:
        settings = module.settings
        module_at = _module_at(bus, module)
        for key, sourced in settings.system.items():
            values.append(policy.Value(bus.name, module.name, key, None, Decimal(sourced.value),
                                       sourced.path or module_at))
        for number, fields in settings.programs.items():
            program_at = settings.program_paths.get(number, module_at)
            for key in policy.PROGRAM_KEYS:
                if key in fields:
                    sourced = fields[key]
                    values.append(policy.Value(bus.name, module.name, key, number, Decimal(sourced.value),
                                               sourced.path or program_at))
            for output in ("f1", "f2"):
                sourced = fields[output]
                values.append(policy.Value(bus.name, module.name, "function_distance", number,
                                           sourced.value.distance,
                                           sourced.path or program_at))
        if keys & policy.CHAIN_KEYS.keys():
            values += _chain_values(bus, module, module_at)
    return [v for v in values if v.key in keys]


def _chain_values(bus: Bus, module: Module, module_at: Path_) -> list[policy.Value]:
    """What each chain's motion reaches (`policy.CHAIN_KEYS`), placed at its first program: the stroke from
    the programs' positions (exact), the pass time as the motion works it out, to its step (0.01 s)."""
    image, values = module.desired_image(), []
    for chain in motion.chain_motions(image):
        at = module.settings.program_paths.get(chain.programs[0], module_at)
        reversing = [image.known(number).P for number in chain.programs]
        seconds = chain.cycle_time if chain.loops else chain.duration
        reached = {"stroke_length": POSITION.in_unit(max(reversing) - min(reversing)),
                   "pass_time": Decimal(repr(seconds)).quantize(policy.CHAIN_KEYS["pass_time"].step)}
        values += [policy.Value(bus.name, module.name, key, chain.programs[0], value, at, chain.label)
                   for key, value in reached.items()]
    return values


def _module_at(bus: Bus, module: Module) -> Path_:
    return ("buses", bus.name, "modules", module.name)  # resolved by `placed` through names, see `_in_plant`


def placed(finding: policy.RuleFinding, plant_document: Document | None, loaded: LoadedPolicy) -> Finding:
    """Where a finding is said: at the plant file's value where there is one (`plant_document` given), naming
    the rule's place; else at the rule."""
    (line, column), _ = loaded.document.lines([Problem(finding.rule_at, "")])[0]
    said = f"{finding.level}: {finding.message}"
    if finding.value_at is None or plant_document is None:
        return Finding(loaded.document.name, line, column, said)
    at = _in_plant(plant_document, finding.value_at)
    (at_line, at_column), _ = plant_document.lines([Problem(at, "")])[0]
    return Finding(plant_document.name, at_line, at_column,
                   f"{said} (rule at {loaded.document.name}:{line}:{column})")


def _in_plant(document: Document, path: Path_) -> Path_:
    """A path with bus and module names (`_module_at`) as the indexes the file has them at."""
    if len(path) == 4 and path[0] == "buses" and isinstance(path[1], str):
        for b, bus in enumerate(document.data["buses"]):
            if bus.get("name") == path[1]:
                for m, module in enumerate(bus["modules"]):
                    if module.get("name") == path[3]:
                        return ("buses", b, "modules", m)
    return path


def policy_schema() -> dict[str, Any]:
    """The JSON Schema of a policy file (draft-07)."""
    schema = PolicySpec.model_json_schema(ref_template="#/definitions/{model}", schema_generator=Draft07)
    return schema | {"$id": "urn:prc3cfg:policy", "title": FORMAT}


def policy_schema_text() -> str:
    """The schema as `schemas/policy.schema.json` holds it."""
    return json.dumps(policy_schema(), indent=2, ensure_ascii=False) + "\n"
