"""`parse_plant`: read a plant file's bytes, find its problems at once, or build the `Plant`.

    read YAML (`document`)  →  pydantic, part by part (`models`, worded by `messages`)
                            →  rules on every part that is valid on its own (`rules`,
                               after `profiles`)  →  `Plant`, or `PlantError`

Each part of a plant file is validated once, on its own: every profile, every module, and the
rest of the file with a valid stand-in for each of those. The rules run on the parts that
validated even when others did not, so that one unknown key does not hide a P > S1 three
modules further down — and within a part that did not, on what is valid in it (`_salvaged`:
the part without the values its problems are about), each rule only where every value it needs
is valid (`rules.Unknown`): a speed out of range in program 1 does not hide a P > S1 in program
2, nor an S4 below S5 a position above S1. A module whose profiles are unknown, or whose
`profiles:` list itself is wrong, is not checked further.

pydantic keeps every error of one call (some 400 bytes each, and a mapping that lacks three
required keys has three), so what one call costs is bounded: a part of more than
`MAX_PART_NODES` keys, values, lists and mappings is refused where that is reached — no valid
module or profile comes near it. All problems come back sorted by line and column, one line
each; once there are more than `MAX_PROBLEMS`, the file is checked no further and the last
line says so. Where the reading itself found a problem (`010`, `on`, a decimal comma), that is
the one said there; the models' objection to the same value only lends it their "what to do"
when the reading's problem asks for that (`Problem.models_fix`: "… read as true by YAML 1.1
and as text by YAML 1.2 — give a number in m").
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

from prc3cfg.plant import rules
from prc3cfg.plant.document import Document, Position, mappings_in, parse_document
from prc3cfg.plant.messages import from_pydantic, what
from prc3cfg.plant.models import BusLine, ModuleSpec, PlantSpec, ProfileSpec
from prc3cfg.plant.plant import Bus, Module, Plant
from prc3cfg.plant.problems import MAX_PROBLEMS, Path_, PlantError, Problem
from prc3cfg.plant.profiles import Effective, module_layers, resolve

M = TypeVar("M", bound=BaseModel)
#: Keys, values, lists and mappings in one part: a module or profile with every field of all
#: 64 programs and a chain of all of them written out has about 2,000; the rest of a plant
#: of 8 buses × 30 modules, about 1,300, and 2 more for each profile.
MAX_PART_NODES = 10_000
#: What stands for a module or a profile while the rest of the file is validated.
_MODULE_STAND_IN = {"address": 1, "name": "-"}
#: A module's own settings, each laid over its profiles' (`profiles.resolve`): a module that gives none has
#: theirs.
_SETTINGS = tuple(ProfileSpec.model_fields)
_PROFILE_STAND_IN: dict[str, Any] = {}


def parse_plant(path: str | Path, data: bytes, *,
                pseudo_terminal: Callable[[str], bool] = lambda port: False) -> Plant:
    """The plant in `data`, the bytes of the file `path` (read by the shell, `prc3cfg.shell.plant_files`,
    or a file before it is written); `PlantError` with its problems ("file:line:column: …") otherwise.
    `pseudo_terminal`: whether a port is one on this machine (the shell's to know: it carries no parity)."""
    path = Path(path)
    document = parse_document(str(path), data)
    _check_sizes(document)
    problems = _Problems(MAX_PROBLEMS - len(document.problems))
    try:
        buses = _checked(document.data, problems, pseudo_terminal)
    except _Enough:
        raise PlantError(_lines(document, _one_per_cause(problems), stopped=True)) from None
    if problems or document.problems:
        raise PlantError(_lines(document, _one_per_cause(problems), stopped=False))
    return Plant(
        name=document.data["plant"],
        buses=tuple(Bus(**{k: getattr(line, k) for k in line.model_fields_set if k != "modules"},
                        modules=tuple(modules))
                    for line, modules in buses),
        path=path,
        sha256=document.sha256,
        policy=document.data.get("policy"),
    )


class _Enough(Exception):
    """More problems than are listed: the file is checked no further."""


class _Problems(list[Problem]):
    """The problems found so far; `add` stops the checking (`_Enough`) once there are more than `room`."""

    def __init__(self, room: int) -> None:
        super().__init__()
        self.room = room

    def add(self, found: Iterable[Problem]) -> None:
        self.extend(found)
        if len(self) > self.room:
            raise _Enough


def _checked(data: dict[Any, Any], problems: _Problems,
             pseudo_terminal: Callable[[str], bool]) -> list[tuple[BusLine, list[Module]]]:
    """Every bus's line and its modules that have no problem; the problems go to `problems`."""
    problems.add(())  # the reading may have found enough already
    spec, found = _validated(PlantSpec, _with_stand_ins(data), (), data)
    problems.add(found)
    problems.add(rules.check_unique(data))
    profiles: dict[str, tuple[ProfileSpec | None, rules.Unknown]] = {}
    for profile_path, raw in _profiles(data):
        profile, found = _validated(ProfileSpec, raw, profile_path, data)
        problems.add(found)
        if isinstance(profile_path[1], str):
            salvaged = (profile, frozenset()) if profile is not None else _salvaged(ProfileSpec, raw)
            profiles[profile_path[1]] = salvaged
    buses = []
    # the settings of modules that add nothing to their profiles, checked
    alike: dict[tuple[str, ...], Effective] = {}
    for bus_path, raw_bus in mappings_in(data, ("buses",)):
        line = spec.buses[int(bus_path[1])] if spec is not None else _line(raw_bus)
        problems.add(rules.check_bus(bus_path, line, pseudo_terminal) if line else ())
        modules = []
        for module_path, raw_module in mappings_in(raw_bus, bus_path + ("modules",)):
            module, found = _validated(ModuleSpec, raw_module, module_path, data)
            problems.add(found)
            checked, unknown = ((module, frozenset()) if module is not None
                                else _salvaged(ModuleSpec, raw_module))
            if checked is not None:
                found, built = _module(checked, module_path, profiles, unknown, alike)
                problems.add(found)
                modules += [built] if built is not None else []
        if line is not None:
            buses.append((line, modules))
    return buses


def _one_per_cause(problems: list[Problem]) -> list[Problem]:
    """The problems, those of one profile's value in several modules said once: "in modules m1, m2 and m3, …"
    (a mistake in a profile thirty modules use is one mistake, not thirty lines)."""
    causes: dict[Problem, list[str]] = {}
    for problem in problems:
        causes.setdefault(replace(problem, modules=()), []).extend(problem.modules)
    out = []
    for cause, names in causes.items():
        if names:
            listed = (f"module {names[0]}" if len(names) == 1
                      else f"modules {', '.join(names[:-1])} and {names[-1]}")
            cause = replace(cause, message=f"in {listed}, {cause.message}")
        out.append(cause)
    return out


def _lines(document: Document, problems: list[Problem], *, stopped: bool) -> list[str]:
    """Every problem as one line, sorted; at a place where reading found one, the models' only lend a fix.

    After `MAX_PROBLEMS` lines (or when the checking `stopped` early), a last one says there are more.
    """
    located = document.lines([*document.problems, *problems])
    read = dict(zip(located, document.problems))
    places = {at for at, _ in read}
    fixes: dict[Position, str] = {}
    lines = set()
    for at, text in sorted(located[len(document.problems):]):
        if at in places:
            fixes.setdefault(at, text.partition(" — ")[2])
        else:
            lines.add((at, text))
    for (at, text), problem in read.items():
        if problem.models_fix and at in fixes:
            text = f"{text.partition(' — ')[0]} — {fixes[at]}"
        lines.add((at, text))
    ordered = sorted(lines)
    if stopped or len(ordered) > MAX_PROBLEMS:
        ordered = ordered[:MAX_PROBLEMS]
        (line, column), _ = ordered[-1]
        ordered.append(((line, column),
                        f"{document.name}:{line}:{column}: more than {MAX_PROBLEMS} problems, the "
                        "file was checked no further — fix those listed and check it again"))
    return [text for _, text in ordered]


def _check_sizes(document: Document) -> None:
    """`PlantError` at the node where a part passes `MAX_PART_NODES`: the rest of the file, a profile, a
    module."""
    data = document.data
    parts = [((), _with_stand_ins(data)), *_profiles(data), *_modules(data)]
    for path, value in parts:
        if _size(value) > MAX_PART_NODES:
            reached, at_key = _node_past(value, path, MAX_PART_NODES)
            nodes = f"more than {MAX_PART_NODES:,} keys, values, lists and mappings"
            message = (f"{what(path, data)} has {nodes} — a module with every field of all 64 programs "
                       "written out "
                       "has about 2,000" if path else
                       f"the plant file has {nodes} besides its modules and profiles — 8 buses of 30 "
                       "modules have "
                       "about 1,300")
            problem = Problem(reached, f"{message}: check that this is the plant file", at_key=at_key)
            raise PlantError([text for _, text in document.lines([problem])])


def _size(value: Any) -> int:
    """The nodes of `value`: itself, and each key and value in it."""
    if isinstance(value, dict):
        return 1 + len(value) + sum(map(_size, value.values()))
    if isinstance(value, list):
        return 1 + sum(map(_size, value))
    return 1


def _node_past(value: Any, path: Path_, limit: int) -> tuple[Path_, bool]:
    """The node of `value` (at `path`) after the first `limit`, in file order: its path, and whether it is a
    key."""
    count, stack = 0, [(path, value, False)]
    while stack:
        at, item, is_key = stack.pop()
        count += 1
        if count > limit:
            return at, is_key
        if isinstance(item, dict) and not is_key:
            for key, child in reversed(item.items()):
                stack += [(at + (key,), child, False), (at + (key,), key, True)]
        elif isinstance(item, list):
            stack += [(at + (index,), child, False) for index, child in reversed(list(enumerate(item)))]
    raise ValueError(f"{path} has at most {limit} nodes")


def _with_stand_ins(data: dict[Any, Any]) -> dict[Any, Any]:
    """The file with a valid stand-in for each profile and module that is a mapping (validated on their
    own)."""
    result = dict(data)
    if isinstance(data.get("profiles"), dict):
        result["profiles"] = {name: _PROFILE_STAND_IN if isinstance(p, dict) else p
                              for name, p in data["profiles"].items()}
    if isinstance(data.get("buses"), list):
        result["buses"] = [
            {**bus, "modules": [_MODULE_STAND_IN if isinstance(m, dict) else m for m in bus["modules"]]}
            if isinstance(bus, dict) and isinstance(bus.get("modules"), list) else bus
            for bus in data["buses"]
        ]
    return result


def _profiles(data: dict[Any, Any]) -> Iterator[tuple[Path_, dict[Any, Any]]]:
    """Every profile that is a mapping, with its path."""
    profiles = data.get("profiles")
    for name, raw in (profiles.items() if isinstance(profiles, dict) else ()):
        if isinstance(raw, dict):
            yield ("profiles", name), raw


def _modules(data: dict[Any, Any]) -> Iterator[tuple[Path_, dict[Any, Any]]]:
    """Every module that is a mapping, with its path."""
    for bus_path, bus in mappings_in(data, ("buses",)):
        yield from mappings_in(bus, bus_path + ("modules",))


def _module(module: ModuleSpec, path: Path_, profiles: Mapping[str, tuple[ProfileSpec | None, rules.Unknown]],
            unknown: rules.Unknown,
            alike: dict[tuple[str, ...], Effective]) -> tuple[list[Problem], Module | None]:
    """The problems of one module, and the module when it has none (`unknown`: what its problems took out of
    it).

    A module that adds nothing to its profiles has their settings, and their problems: its profiles'
    settings are resolved and checked once for all such modules (`alike`, by profiles) — where they
    have none; where they have some, each module says them in its own name."""
    not_found = [
        Problem(path + ("profiles", k), f"unknown profile '{name}' — "
                + (f"the profiles are {', '.join(profiles)}" if profiles
                   else "the file has no profiles: section"))
        for k, name in enumerate(module.profiles) if name not in profiles
    ]
    if not_found or any(profiles[name][0] is None for name in module.profiles):
        return not_found, None
    unknown = unknown.union(*(profiles[name][1] for name in module.profiles))
    adds_nothing = not unknown and all(getattr(module, key) is None for key in _SETTINGS)
    if adds_nothing and module.profiles in alike:
        settings, problems = alike[module.profiles], []
    else:
        settings = resolve(module_layers(module, path,
                                         {name: p for name, (p, _) in profiles.items() if p is not None}))
        problems = rules.check_module(module.name, path, settings, unknown)
        if adds_nothing and not problems:
            alike[module.profiles] = settings
    if unknown:
        return problems, None
    built = Module(address=module.address, name=module.name, profiles=module.profiles,
                   unmanaged_programs=settings.unmanaged_programs.value, settings=settings)
    return problems, built


def _line(raw_bus: dict[Any, Any]) -> BusLine | None:
    """A bus's line, for its rules (`rules.check_bus`): valid whole, or without the keys that are not, where
    the rules need none of them (a wrong `timeout` does not hide a ZVZ the Open Driver refuses)."""
    raw = {key: value for key, value in raw_bus.items() if key != "modules"}
    try:
        return BusLine.model_validate(raw)
    except ValidationError as error:
        wrong = {e["loc"][0] for e in error.errors(include_url=False) if e["loc"]}
    if wrong & rules.LINE_KEYS:
        return None
    line = {key: value for key, value in raw.items() if key not in wrong}
    return _valid(BusLine, line | {"name": "-", "port": "emulator://-"})


def _salvaged(model: type[M], raw: dict[Any, Any]) -> tuple[M | None, rules.Unknown]:
    """A module or profile that has problems, without the values they are about — as `model`, with what was
    taken out (`rules.Unknown`) — so that the rules check what is valid in it; None where nothing can be
    taken out for them (its `profiles:` list) or what is left still fails."""
    data, unknown = copy.deepcopy(raw), set[tuple[Any, ...]]()
    # a value taken out can leave its mapping empty or a required key missing: a round each
    for _ in range(3):
        try:
            return model.model_validate(data), frozenset(unknown)
        except ValidationError as error:
            for loc in {tuple(e["loc"]) for e in error.errors(include_url=False)}:
                if not _take_out(data, loc, unknown):
                    return None, frozenset()
    return None, frozenset()


def _take_out(data: dict[Any, Any], loc: tuple[Any, ...], unknown: set[tuple[Any, ...]]) -> bool:
    """Take the value at `loc` (a pydantic error's) out of a module or profile, and say in `unknown` what the
    rules cannot know now; False where the part cannot be checked without it."""
    head, rest = (loc[0], loc[1:]) if loc else (None, ())
    if head in _MODULE_STAND_IN:  # address, name: the rules need neither's value
        data[head] = _MODULE_STAND_IN[head]
    elif head == "system" and rest and rest[0] != "[key]" and isinstance(data.get("system"), dict):
        data["system"].pop(rest[0], None)
        unknown.add(("system", rest[0]))
    elif (head == "programs" and rest and isinstance(data.get("programs"), dict)
          and rest[0] in data["programs"]):
        program = data["programs"][rest[0]]
        if len(rest) > 1 and rest[1] != "[key]" and isinstance(program, dict):
            program.pop(rest[1], None)
            unknown.add((rest[0], rest[1]))
        else:  # the program itself, or its number: every jump to it, and what it lists, unknown
            del data["programs"][rest[0]]
            unknown.update({(rest[0], "*"), ("programs", "*")})
    elif head in ("system", "programs", "chains", "unmanaged_programs"):
        data.pop(head, None)
        unknown.add((head, "*"))
    elif head == "profiles" or head not in data:
        return False
    else:  # a key the part may not have
        data.pop(head, None)
    return True


def _validated(model: type[M], data: Any, path: Path_, document: Any) -> tuple[M | None, list[Problem]]:
    """`data` (at `path` in `document`) as `model`, or None and its problems."""
    try:
        return model.model_validate(data), []
    except ValidationError as error:
        found = (from_pydantic({**e, "loc": path + tuple(e["loc"])}, document)
                 for e in error.errors(include_url=False))
        return None, [problem for problem in found if problem is not None]


def _valid(model: type[M], data: Any) -> M | None:
    try:
        return model.model_validate(data)
    except ValidationError:
        return None
