"""What a PRC 3 module holds, in device units: system parameters, programs, the module image.

Owns the value types shared by the codec, the device model, plant files, read-back and the
planner, their factory defaults (docs/protocol.md "What a module does") and the module image JSON
(docs/files.md "Module image"), which the dataclasses' own fields check as it is read (pydantic,
`images_from_json`). Owns no behaviour of a module: what a module *does* with a message is
`prc3cfg.core.device`. Pure: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Annotated, Any, Protocol

from pydantic import TypeAdapter, ValidationError

from prc3cfg.core.contract import LATER, Whole, every_key, exactly, json_path, said

PROGRAM_COUNT = 64
PROGRAM_NUMBERS = range(1, PROGRAM_COUNT + 1)
MAX_MODULE_ADDRESS = 30

#: System parameters in message order (20h, 50h), S9 excluded: it is read-only.
SYSTEM_KEYS = ("S1", "S2", "S3", "S4", "S5", "S6", "S7", "S8", "S10", "S11", "S12")
#: Program fields in message order (21h, 51h, 52h).
PROGRAM_FIELDS = ("P", "V", "Vr", "T", "F1", "F2", "A")
FIELD_INDEX = {name: k for k, name in enumerate(PROGRAM_FIELDS)}


@dataclass(frozen=True, slots=True)
class SystemParameters:
    """S1..S12 without S9, in device units (mm, mm/s, mm/s², 0.001 m/s², …)."""

    S1: Whole
    S2: Whole
    S3: Whole
    S4: Whole
    S5: Whole
    S6: Whole
    S7: Whole
    S8: Whole
    S10: Whole
    S11: Whole
    S12: Whole

    def values(self) -> tuple[int, ...]:
        return tuple(getattr(self, key) for key in SYSTEM_KEYS)

    def to_json(self) -> dict[str, int]:
        return dict(zip(SYSTEM_KEYS, self.values()))


@dataclass(frozen=True, slots=True)
class Program:
    """One program: position, speed, relative speed, dwell, function outputs, jump address."""

    P: Whole
    V: Whole
    Vr: Whole = 0
    T: Whole = 0
    F1: Whole = 0
    F2: Whole = 0
    A: Whole = 0

    def values(self) -> tuple[int, ...]:
        return (self.P, self.V, self.Vr, self.T, self.F1, self.F2, self.A)

    def with_field(self, name: str, value: int) -> Program:
        """This program with one field changed — built from its values, not by `dataclasses.replace`,
        which costs three times as much (the device model runs it for every item a plan writes)."""
        values = list(self.values())
        values[FIELD_INDEX[name]] = value
        return Program(*values)

    def with_position_and_speed(self, position: int, speed: int) -> Program:
        return Program(position, speed, self.Vr, self.T, self.F1, self.F2, self.A)

    def to_json(self) -> dict[str, int]:
        return dict(zip(PROGRAM_FIELDS, self.values()))


#: Factory defaults after 10h (docs/protocol.md "What a module does"). (reading) S2 = 50, not the
#: "0.500 m" printed in manual §2.3.1, which contradicts its own example words.
DEFAULT_SYSTEM = SystemParameters(
    S1=400, S2=50, S3=754, S4=600, S5=10, S6=1500, S7=1000, S8=0, S10=583, S11=1100, S12=10
)
DEFAULT_SPEED = 50


def default_program(system: SystemParameters) -> Program:
    """The program an init (11h..14h) leaves: P = Def_Pos, V = 50, everything else 0.

    Def_Pos = min(S2 + 100, S1) (manual §2.2.1). (reading) "SP_2 + 0.0100" in manual §2.3.2
    is the same rule with a misprinted unit. (reading) V = 50 is clamped into [S5, S4]
    like any speed.
    """
    return Program(P=min(system.S2 + 100, system.S1), V=min(max(DEFAULT_SPEED, system.S5), system.S4))


@dataclass(frozen=True, slots=True)
class ModuleImage:
    """A module's contents (docs/files.md "Module image"): S9 as `address`, system parameters, 64 programs.

    `programs[i]` is program i + 1; `None` marks a program that was not read (or, in a
    desired image, is not managed).
    """

    address: Whole
    system: SystemParameters
    programs: Annotated[tuple[Annotated[Program, every_key(PROGRAM_FIELDS)] | None, ...],
                        exactly(PROGRAM_COUNT)]

    def __post_init__(self) -> None:
        if len(self.programs) != PROGRAM_COUNT:
            raise ValueError(f"a module image holds {PROGRAM_COUNT} programs, not {len(self.programs)}")

    def program(self, number: int) -> Program | None:
        return self.programs[number - 1]

    def known(self, number: int) -> Program:
        """Program `number` where the image is known to hold it (read, managed, a module's own);
        ValueError if it is None here."""
        if (program := self.programs[number - 1]) is None:
            raise ValueError(f"program {number} is not in this image (not read, or not managed)")
        return program

    def complete(self) -> tuple[Program, ...]:
        """The 64 programs of an image that holds them all (a module's own, the emulator's, one read
        whole); ValueError if one is None."""
        programs = tuple(p for p in self.programs if p is not None)
        if len(programs) != PROGRAM_COUNT:
            raise ValueError(f"program {self.programs.index(None) + 1} is not in this image (not read, or "
                             "not managed)")
        return programs

    def with_programs(self, changes: dict[int, Program]) -> ModuleImage:
        """This image with the given programs (by number) replaced."""
        programs = list(self.programs)
        for number, program in changes.items():
            programs[number - 1] = program
        return ModuleImage(self.address, self.system, tuple(programs))

    def to_json(self) -> dict[str, Any]:
        return {
            "address": self.address,
            "system": self.system.to_json(),
            "programs": [None if p is None else p.to_json() for p in self.programs],
        }

    @classmethod
    def from_json(cls, data: Any) -> ModuleImage:
        """The image a JSON object holds (docs/files.md "Module image"); ValueError saying where and what in
        words."""
        try:
            return _IMAGES.validate_python([data])[0]
        except ValidationError as error:
            raise ValueError(said(error, lambda loc: json_path(loc[1:], "the image"), _Images)) from None

    @classmethod
    def factory(cls, address: int) -> ModuleImage:
        """A module as it leaves the factory: default system parameters, default programs."""
        program = default_program(DEFAULT_SYSTEM)
        return cls(address=address, system=DEFAULT_SYSTEM, programs=(program,) * PROGRAM_COUNT)


assert tuple(f.name for f in fields(SystemParameters)) == SYSTEM_KEYS
assert tuple(f.name for f in fields(Program)) == PROGRAM_FIELDS

_Images = list[ModuleImage]
_IMAGES = TypeAdapter(_Images, config=LATER)


def images_from_json(data: Any, at: str = "") -> list[ModuleImage]:
    """The module images a JSON list holds — `read --json`'s file, a snapshot's modules (their other
    keys, such as "bus", are not the image's) — the list at `at` in its document ("modules"), or
    the document; ValueError saying where and what in words: 'modules[0].system has no "S2"',
    "[0].programs[3] is a list, where an object or null belongs"."""
    try:
        return _IMAGES.validate_python(data)
    except ValidationError as error:
        raise ValueError(said(error, lambda loc: json_path([at, *loc], "the list"), _Images)) from None


Key = tuple[str, int]  # a module on the plant's buses: (bus name, module address)


class Placed(Protocol):
    """A module where the plant file has it, as what reads of a module's plan-file entry names it by
    (`what_to_read.PlanEntry`)."""

    @property
    def bus(self) -> str: ...
    @property
    def address(self) -> int: ...
    @property
    def name(self) -> str: ...


@dataclass(frozen=True, slots=True)
class Wanted:
    """One module to plan: where it is, its name, and the image it should hold."""

    bus: str
    address: int
    name: str
    desired: ModuleImage

    @property
    def key(self) -> Key:
        return (self.bus, self.address)
