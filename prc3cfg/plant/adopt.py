"""Adopting what the modules hold into the plant file: the Teach-In round trip (issue 13).

Teach In changes positions on the floor (manual §2.6, docs/protocol.md "Readings of the manual"), and the
plant file then says otherwise. `adopt` works out the plant file that describes what the modules hold,
changing only the values that drifted, in the layer they came from:

    adoption = adopt(plant, images, text)   # images: api.read's; text: the plant file as loaded
    adoption.adopted                        # each value adopted, `Adopted.text` says it
    adoption.text                           # the plant file, rewritten (not written anywhere)

What is adopted: every field of every managed program of the chosen modules (those in
`images`) that holds something other than the plant file says — position above all, and
speed, relative speed, dwell, F1 and F2 alike — and the system parameters; with `programs`,
only those programs (and no system parameter). A program that `unmanaged_programs: reset`
leaves unlisted and that no longer holds factory defaults is listed, with all it holds.

Where each value goes is where its effective value came from (`profiles.Sourced`):
- the module: changed in place;
- a profile: changed in the profile when every module that takes the value from it was read
  and holds the same new value; otherwise an override on each module that drifted;
- the factory default: an override on the module.

Refused in one line, with nothing adopted: a jump address (A) that drifted — jumps are
`chains` (which come whole from one layer) and `next:`, so they are edited by hand; and a
value the plant file cannot hold — a position above the module's upper reversing point, a
speed outside min_speed..max_speed, anything outside its range — naming module and program.

The file is rewritten by `prc3cfg.plant.splice`: spliced, never dumped, every other byte kept.
The new text is then loaded as a plant (`parse_plant` of the text, as if it were the file) and
must describe exactly what the modules hold — the adopted values in the chosen modules, every
other module, bus and setting as before — or nothing is adopted (`AdoptRefused`: a bug of the
rewriter, said as one). Pure: text and images in, text out.
"""

from __future__ import annotations

import hashlib
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from typing import Any

from prc3cfg.core.device import value_range
from prc3cfg.core.image import SYSTEM_KEYS, ModuleImage, SystemParameters, default_program
from prc3cfg.core.render import FieldChange, differences, field_name, format_value
from prc3cfg.core.units import BY_SYMBOL, PROGRAM_QUANTITIES, plant_value
from prc3cfg.errors import UserError
from prc3cfg.plant import Bus, Module, Plant, splice
from prc3cfg.plant.loader import parse_plant
from prc3cfg.plant.problems import Path_, PlantError
from prc3cfg.plant.profiles import DEFAULT, MODULE, Sourced

Key = tuple[str, int]  # (bus name, module address)
#: Program fields as a plant file names them (A is `chains` and `next`, never adopted).
FIELD_KEYS = {q.symbol: q.key for q in PROGRAM_QUANTITIES} | {"F1": "f1", "F2": "f2"}
#: How `profiles` names a profile as a source: "profile NAME".
PROFILE = "profile "


@dataclass(frozen=True, slots=True)
class Adopted:
    """One value written into the plant file.

    `modules`: "bus/name" of each module whose drift it is; `what`: "program 3 position
    1.200 m → 1.150 m", "system max speed …", or for a program newly listed "program 7
    position 0.900 m, speed 0.050 m/s"; `layer`: where it is written, "module" or "profile
    NAME"; `override`: a new key in the module, for a value that came from `source` (a
    profile, or "default").
    """

    modules: tuple[str, ...]
    what: str
    layer: str
    override: bool
    source: str

    @property
    def text(self) -> str:
        """One line: "~ booth-a/booth-a-right: program 1 position 2.000 m → 1.987 m (in the module)"."""
        if self.layer != MODULE:
            return (f"~ {self.layer}: {self.what} (every module that takes it from there holds it: "
                    f"{', '.join(self.modules)})")
        if not self.override:
            return f"~ {self.modules[0]}: {self.what} (in the module)"
        why = ("the plant file left it at its default" if self.source == DEFAULT
               else f"{self.source} keeps its value")
        return f"+ {self.modules[0]}: {self.what} (new in the module: {why})"


@dataclass(frozen=True, slots=True)
class AdoptedText:
    """What `adopt` found: the values adopted, in the order of their modules in the file, the new text, and
    the buses of the modules adopted from (by name: a "bus/name" of `Adopted.modules` cannot say which part
    is the bus's where a name holds a "/")."""

    adopted: tuple[Adopted, ...]
    text: str
    buses: tuple[str, ...] = ()


class AdoptRefused(UserError):
    """A drift the plant file cannot take as it is: nothing was adopted."""


@dataclass(frozen=True, slots=True)
class _Drift:
    """A value a module holds other than the plant file says."""

    name: str                # "bus/module"
    bus: str
    path: Path_              # the module in the file
    # in a layer: ("programs", 3, "position"), ("system", "max_speed"), ("programs", 7)
    within: Path_
    value: Any               # in human units: a number, {action, distance}, or a whole program
    what: str
    sourced: Sourced | None  # None: a program no layer lists

    @property
    def profile(self) -> Path_ | None:
        """Where the value is in its profile, if it came from one."""
        return (self.sourced.path if self.sourced is not None and self.sourced.source.startswith(PROFILE)
                else None)


def adopt(plant: Plant, images: dict[Key, ModuleImage], text: str,
          programs: Iterable[int] | None = None) -> AdoptedText:
    """The plant file `text` (of `plant`, as loaded) rewritten to describe what the modules in
    `images` hold — only `programs` of them, if given; `AdoptRefused` for what it cannot say."""
    if hashlib.sha256(text.encode("utf-8")).hexdigest() != plant.sha256:
        raise UserError(f"{plant.path}: the plant file changed since it was loaded — nothing was adopted: "
                        "adopt again")
    scope = None if programs is None else frozenset(programs)
    chosen = [(bus, module, path) for bus, module, path in _modules(plant)
              if (bus.name, module.address) in images]
    if (scope is not None
        and not any(scope.intersection(module.managed_programs()) for _, module, _ in chosen)):
        raise UserError(f"program {', '.join(map(str, sorted(scope)))}: no chosen module manages "
                        f"{'it' if len(scope) == 1 else 'any of them'} — name a program the plant file lists")
    drifts = [d for bus, module, path in chosen
              for d in _drifts(bus, module, path, images[(bus.name, module.address)], scope)]
    wanted: dict[Any, Any] = {}
    adopted = []
    for target, found in _placed(plant, drifts).items():
        first = found[0]
        _want(wanted, target, first.value)
        source = DEFAULT if first.sourced is None else first.sourced.source
        layer = MODULE if target[0] == "buses" else source
        adopted.append(Adopted(tuple(d.name for d in found), first.what, layer, layer == MODULE
                               and source != MODULE, source))
    if not wanted:
        return AdoptedText((), text)
    rewritten = splice.rewrite(text, wanted)
    _check_rewritten(plant, {key: _adopted_image(module, images.get(key), scope)
                             for key, module in _keyed(plant)}, rewritten)
    return AdoptedText(tuple(adopted), rewritten, tuple(sorted({d.bus for d in drifts})))


def _keyed(plant: Plant) -> Iterator[tuple[Key, Module]]:
    return (((bus.name, module.address), module) for bus, module in plant.modules())


def _adopted_image(module: Module, have: ModuleImage | None, scope: frozenset[int] | None) -> ModuleImage:
    """What the plant file says of `module` once what it holds (`have`, if it was read) is adopted
    within `scope`: its managed programs as held, and its system parameters too without a scope."""
    desired = module.desired_image()
    if have is None:
        return desired
    numbers = [n for n in module.managed_programs() if (scope is None or n in scope)
               and have.program(n) is not None]
    return replace(desired.with_programs({n: have.known(n) for n in numbers}), system=have.system
                   if scope is None else desired.system)


def _check_rewritten(plant: Plant, adopted: dict[Key, ModuleImage], text: str) -> None:
    """`AdoptRefused` unless `text`, loaded as the plant file, has the same buses, modules and
    settings as `plant`, and each module's image is the one `adopted` names."""
    try:
        after = parse_plant(plant.path, text.encode("utf-8"))
    except PlantError as error:
        raise _rewriter_bug(plant, f"it would not load: {error.problems[0]}") from None
    def buses(of: Plant) -> list[dict[str, Any]]:
        return [bus.model_dump(exclude={"modules"}) for bus in of.buses]

    def names(of: Plant) -> list[tuple[Key, str]]:
        return [(k, m.name) for k, m in _keyed(of)]

    if after.name != plant.name or buses(plant) != buses(after) or names(plant) != names(after):
        raise _rewriter_bug(plant, "its plant, buses or modules would differ")
    for (bus, address), module in _keyed(after):
        if (said := module.desired_image()) != (held := adopted[(bus, address)]):
            found = "; ".join(differences(held, said)) or "the programs it manages"
            raise _rewriter_bug(plant, f"bus {bus}, module {address} ({module.name}): {found} (held "
                                       "→ written)")


def _rewriter_bug(plant: Plant, what: str) -> AdoptRefused:
    return AdoptRefused(f"{plant.path}: the rewritten plant file would not describe what the modules hold "
                        f"— {what}; "
                        "nothing was adopted: this is a bug in prc3cfg, please report it with the plant file")


def _modules(plant: Plant) -> Iterator[tuple[Bus, Module, Path_]]:
    """Every module with its path in the file (the loader keeps the file's order)."""
    for b, bus in enumerate(plant.buses):
        for m, module in enumerate(bus.modules):
            yield bus, module, ("buses", b, "modules", m)


# -- what drifted -------------------------------------------------------------------------


def _drifts(bus: Bus, module: Module, path: Path_, have: ModuleImage,
            scope: frozenset[int] | None) -> list[_Drift]:
    """What `module` holds (`have`) other than the plant file says, within `scope`; refused when
    it cannot be adopted (a jump, a value a plant file cannot hold)."""
    name, where = f"{bus.name}/{module.name}", f"bus {bus.name}, module {module.address} ({module.name})"
    desired, settings = module.desired_image(), module.settings
    numbers = [n for n in module.managed_programs() if (scope is None or n in scope)
               and have.program(n) is not None]
    for number in numbers:
        jumps, said_jumps = have.known(number).A, desired.known(number).A
        if jumps != said_jumps:
            raise AdoptRefused(f"{where}: program {number} jumps to {jumps or 'no program'} on the module "
                               "where the plant "
                               f"file says {said_jumps or 'no program'} — adopt leaves jumps (chains, "
                               "next:) alone: edit them "
                               "in the plant file by hand, or apply it to set the jump back, then "
                               "adopt again")
    system = have.system if scope is None else desired.system
    _check(_adopted_image(module, have, scope), numbers, where)
    drifts = [_Drift(name, bus.name, path, ("system", BY_SYMBOL[c.symbol].key),
                     plant_value(c.symbol, c.after), f"system {c.text}",
                     settings.system[BY_SYMBOL[c.symbol].key])
              for c in _changes(desired.system, system, SYSTEM_KEYS)]
    for number in numbers:
        held = have.program(number)
        if number in settings.programs:
            drifts += [_Drift(name, bus.name, path, ("programs", number, FIELD_KEYS[c.symbol]),
                              plant_value(c.symbol, c.after),
                              f"program {number} {c.text}", settings.programs[number][FIELD_KEYS[c.symbol]])
                       for c in _changes(desired.program(number), held, FIELD_KEYS)]
        elif held != default_program(system):  # unlisted under reset: listed now, with all it holds
            symbols = [s for s in FIELD_KEYS if s in ("P", "V") or getattr(held, s)]
            said = ", ".join(f"{field_name(s)} {format_value(s, getattr(held, s))}" for s in symbols)
            value = {FIELD_KEYS[s]: plant_value(s, getattr(held, s)) for s in symbols}
            drifts.append(_Drift(name, bus.name, path, ("programs", number), value,
                                 f"program {number} {said}", None))
    return drifts


def _changes(said: Any, held: Any, symbols: Iterable[str]) -> list[FieldChange]:
    """The fields `symbols` of two programs, or of two sets of system parameters, that differ."""
    return [FieldChange.of(None, s, getattr(said, s), getattr(held, s)) for s in symbols
            if getattr(said, s) != getattr(held, s)]


def _check(after: ModuleImage, numbers: list[int], where: str) -> None:
    """`AdoptRefused` for a value of `after` — the module as the plant file would describe it —
    that a plant file cannot hold: the device's own checks (docs/protocol.md "What a module does")."""
    system = after.system
    for key in SYSTEM_KEYS:
        _in_range(key, getattr(system, key), system, f"{where}: system")
    if system.S4 < system.S5:
        raise AdoptRefused(f"{where}: system max speed {format_value('S4', system.S4)} is below min speed "
                           f"{format_value('S5', system.S5)} — a plant file cannot say that: "
                           "set the module's system parameters right, then adopt again")
    for number in numbers:
        for symbol in FIELD_KEYS:
            _in_range(symbol, getattr(after.program(number), symbol), system, f"{where}: program {number}")


def _in_range(symbol: str, device: int, system: SystemParameters, where: str) -> None:
    low, high, _, _ = value_range(symbol, system)
    if not low <= device <= high:
        said = (f"{format_value(symbol, device)}, outside "
                f"{format_value(symbol, low)}..{format_value(symbol, high)}"
                if symbol in ("P", "V") else f"{device} (device units), outside {low}..{high}")
        raise AdoptRefused(f"{where} holds {field_name(symbol)} {said} — a plant file cannot say that: set "
                           "it right on "
                           "the module (teach it again), then adopt again")


# -- where each drift goes ----------------------------------------------------------------


def _placed(plant: Plant, drifts: list[_Drift]) -> dict[Path_, list[_Drift]]:
    """Each place to write, with the drifts written there: a profile's value when every module
    that takes it from there drifted to one new value, else the module (in place or an override)."""
    users = Counter(v.path for _, module, _ in _modules(plant) for v in _values(module)
                    if v.source.startswith(PROFILE))
    alike: dict[Path_, list[_Drift]] = {}
    for drift in drifts:
        if drift.profile is not None:
            alike.setdefault(drift.profile, []).append(drift)
    placed: dict[Path_, list[_Drift]] = {}
    for drift in drifts:
        place, profile = drift.path + drift.within, drift.profile
        if (profile is not None and (shared := alike[profile]) and len(shared) == users[profile]
            and all(d.value == drift.value for d in shared)):
            place = profile
        placed.setdefault(place, []).append(drift)
    return placed


def _values(module: Module) -> Iterator[Sourced]:
    """The module's effective system parameters and program fields, each with its source."""
    settings = module.settings
    yield from settings.system.values()
    for fields in settings.programs.values():
        yield from (fields[key] for key in FIELD_KEYS.values())


def _want(trie: dict[Any, Any], path: Path_, value: Any) -> None:
    """`trie[path[0]][path[1]]… = value`."""
    for part in path[:-1]:
        trie = trie.setdefault(part, {})
    trie[path[-1]] = value
