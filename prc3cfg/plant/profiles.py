"""Profiles: how a module's effective settings are layered, and where each value came from.

Precedence, lowest first — fixed:

    factory defaults  <  each profile in the module's `profiles:` list, in order  <  the module

- `system`: per key; the last layer that gives a key wins.
- `programs`: per program number and per field; a module may give only `position` for
  program 3 and take the rest of program 3 from its profile. A program is listed if any
  layer lists it. Fields no layer gives: relative_speed 0, dwell 0, f1 and f2 reset at 0;
  position and speed have no default (`rules` reports them missing).
- `chains`: the last layer that gives `chains` wins whole; chains are never merged
  (`chains: []` in a module drops its profile's chains).
- `unmanaged_programs`: the last layer that gives it wins; default `keep`.

Every effective value is a `Sourced`: the value in human units, its source (`default`,
`profile NAME` or `module`) and its path in the file. A program's fields are kept as each
layer gives them (`ProgramFields`), and a field's `Sourced` is made when it is asked for: a
plant of 240 modules has 60,000 of them. Does not check anything (`rules`) and does not
convert to device units (`plant`). Pure.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from decimal import Decimal
from typing import Any

from prc3cfg.core.image import DEFAULT_SYSTEM
from prc3cfg.core.units import SYSTEM_QUANTITIES
from prc3cfg.plant.models import FunctionOutputSpec, ModuleSpec, ProfileSpec
from prc3cfg.plant.problems import Path_

DEFAULT = "default"
MODULE = "module"


@dataclass(frozen=True, slots=True)
class Sourced:
    """A value and where it came from: `source` is "default", "profile NAME" or "module"."""

    value: Any
    source: str = DEFAULT
    path: Path_ | None = None

    @property
    def place(self) -> Path_:
        """Where a value the file gives is (a default is nowhere: ValueError)."""
        if self.path is None:
            raise ValueError(f"a default ({self.value!r}) has no place in the file")
        return self.path


_RESET_AT_ZERO = FunctionOutputSpec(action="reset", distance=Decimal(0))
#: The program fields an omitted key stands for (position and speed have none).
PROGRAM_DEFAULTS = {
    "relative_speed": Sourced(Decimal(0)),
    "dwell": Sourced(Decimal(0)),
    "f1": Sourced(_RESET_AT_ZERO),
    "f2": Sourced(_RESET_AT_ZERO),
}
_DEFAULT_VALUES = {key: default.value for key, default in PROGRAM_DEFAULTS.items()}
SYSTEM_DEFAULTS = {q.key: Sourced(q.to_human(getattr(DEFAULT_SYSTEM, q.symbol))) for q in SYSTEM_QUANTITIES}


@dataclass(frozen=True, slots=True)
class Layer:
    """One layer of a module's settings: a profile or the module itself, and where it is."""

    source: str
    path: Path_
    spec: ProfileSpec


class ProgramFields(Mapping[str, Sourced]):
    """One program's fields after layering, each with where it came from."""

    __slots__ = ("_layers",)

    def __init__(self, layers: tuple[tuple[str, Path_, Mapping[str, Any]], ...]) -> None:
        # each layer that lists the program, lowest first: (source, its path, the fields it gives)
        self._layers = layers

    def __getitem__(self, key: str) -> Sourced:
        found = self._given(key)
        return PROGRAM_DEFAULTS[key] if found is None else found

    def __contains__(self, key: object) -> bool:  # Mapping's would build the Sourced and catch a KeyError
        return key in PROGRAM_DEFAULTS or self._layer(key) is not None

    def get(self, key: str, default: Any = None) -> Any:  # likewise: 46,000 calls for 8 × 30 modules
        found = self._given(key)
        return PROGRAM_DEFAULTS.get(key, default) if found is None else found

    def plain_values(self) -> dict[str, Any]:
        """Every field's value alone, the highest layer's, else its default — their `Sourced` not made (a
        module's image in device units needs only values), the layers gone through once for all of them."""
        found = dict(_DEFAULT_VALUES)
        for _, _, given in self._layers:
            found.update(given)
        return found

    def _given(self, key: str) -> Sourced | None:
        """The field as the highest layer that gives it has it; None where none does."""
        layer = self._layer(key)
        if layer is None:
            return None
        source, path, given = layer
        return Sourced(given[key], source, path + (key,))

    def _layer(self, key: object) -> tuple[str, Path_, Mapping[str, Any]] | None:
        """The highest layer that gives the field; None where none does."""
        for layer in reversed(self._layers):
            if key in layer[2]:
                return layer
        return None

    def __iter__(self) -> Iterator[str]:
        return iter(self._keys())

    def __len__(self) -> int:
        return len(self._keys())

    def _keys(self) -> dict[str, None]:
        return dict.fromkeys([*PROGRAM_DEFAULTS, *(key for _, _, given in self._layers for key in given)])


@dataclass(frozen=True, slots=True)
class Effective:
    """A module's settings after layering, in human units, each value with its source."""

    system: Mapping[str, Sourced]
    programs: Mapping[int, ProgramFields]
    program_paths: Mapping[int, Path_]  # each program's key in the last layer that lists it
    chains: Sourced                     # tuple[ChainSpec, ...]
    unmanaged_programs: Sourced         # "keep" | "reset"
    #: What is worked out from these settings once for every module that has them (`plant.Module`'s
    #: image in device units): the loader gives the modules that add nothing to their profiles one
    #: `Effective` (32 × 30 modules of one profile would convert 60,000 programs alike).
    derived: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)

    def jumps(self) -> dict[int, Sourced]:
        """The jump address A of each program that jumps: from its chain, or from its `next`."""
        result: dict[int, Sourced] = {}
        for chain in self.chains.value:
            targets = chain.programs[1:] + ((chain.programs[0],) if chain.loop else (0,))
            for number, target in zip(chain.programs, targets):
                result[number] = Sourced(target, self.chains.source, self.chains.path)
        for number, fields in self.programs.items():
            if "next" in fields:
                result[number] = fields["next"]
        return result


def module_layers(module: ModuleSpec, path: Path_, profiles: Mapping[str, ProfileSpec]) -> tuple[Layer, ...]:
    """The layers of `module` at `path`, lowest first; every name in `module.profiles` must exist."""
    used = tuple(Layer(f"profile {name}", ("profiles", name), profiles[name]) for name in module.profiles)
    return (*used, Layer(MODULE, path, module))


def resolve(layers: tuple[Layer, ...]) -> Effective:
    """Lay `layers` over the factory defaults, lowest first."""
    system = dict(SYSTEM_DEFAULTS)
    programs: dict[int, list[tuple[str, Path_, dict[str, Any]]]] = {}
    program_paths: dict[int, Path_] = {}
    chains = Sourced(())
    unmanaged = Sourced("keep")
    for layer in layers:
        spec, source = layer.spec, layer.source
        if spec.system is not None:
            for key in spec.system.model_fields_set:
                system[key] = Sourced(getattr(spec.system, key), source, layer.path + ("system", key))
        for number, program in (spec.programs or {}).items():
            path = layer.path + ("programs", number)
            programs.setdefault(number, []).append((source, path,
                                                    {key: getattr(program, key)
                                                     for key in program.model_fields_set}))
            program_paths[number] = path
        if spec.chains is not None:
            chains = Sourced(spec.chains, source, layer.path + ("chains",))
        if spec.unmanaged_programs is not None:
            unmanaged = Sourced(spec.unmanaged_programs, source, layer.path + ("unmanaged_programs",))
    return Effective(
        system=system,
        programs={n: ProgramFields(tuple(programs[n])) for n in sorted(programs)},
        program_paths=program_paths,
        chains=chains,
        unmanaged_programs=unmanaged,
    )
