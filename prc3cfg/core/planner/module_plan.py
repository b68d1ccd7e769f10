"""A module's plan as data: the steps to send, what they cost, what they are predicted to do.

Owns `Step`, `ModulePlan`, the `Action` of each change, the one-line device-terms summary of a step, and the
planner's errors. Does not own how a plan is found (`prc3cfg.core.planner.init_search`), how it is rendered
for people (`prc3cfg.core.render`) or the plant-wide plan file (`prc3cfg.core.plant_plan`). Pure.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from prc3cfg.core import codec
from prc3cfg.core.image import PROGRAM_COUNT, SYSTEM_KEYS, ModuleImage, SystemParameters, default_program


class UnreachableImage(ValueError):
    """The desired image cannot be reached by any plan (a value outside what the module accepts)."""


class PlanVerificationError(AssertionError):
    """A bug in the planner: the plan it made, run on the device model, does not give the desired image."""


class Action(enum.StrEnum):
    """What a change does, as Terraform's plans say it (`plans.Action`): to a module, to one of its
    programs or to a jump. The value is the mark a plan shows beside the change (`render.LEGEND`)."""

    NO_OP = " "  # a module the plan leaves as it is
    UPDATE = "~"  # changed
    CREATE = "+"  # a program set up from factory defaults; a jump made
    DELETE = "-"  # a program put back to factory defaults; a jump no longer made

    @classmethod
    def of_module(cls, steps: int) -> Action:
        """A module's: it changes when its plan has steps."""
        return cls.UPDATE if steps else cls.NO_OP

    @classmethod
    def of_programs(cls, actual: ModuleImage, desired: ModuleImage,
                    numbers: Iterable[int]) -> dict[int, Action]:
        """Each changed program's (by number): CREATE when it holds the factory defaults, DELETE
        when it is to hold them (of the system parameters before, and after), UPDATE otherwise."""
        was, will = default_program(actual.system), default_program(desired.system)
        create, delete, update = cls.CREATE, cls.DELETE, cls.UPDATE  # locals: a plan shows thousands
        return {n: create if actual.programs[n - 1] == was else delete if desired.programs[n - 1] == will
                else update
                for n in numbers}


@dataclass(frozen=True, slots=True)
class Step:
    """One message of a plan, exactly as it is sent, with a one-line summary in device terms."""

    message: codec.Message
    summary: str
    releases_axes: bool


@dataclass(frozen=True, slots=True)
class ModulePlan:
    """The steps that take one module from its read-back to its desired image.

    `bus_time` is the estimated bus time of the steps (docs/line.md "Bus time"); `naive_bus_time`
    that of the naive download (20h if the system differs, one 21h per changed program).
    `predicted` is the device model's result of the steps: every managed program, and every
    unmanaged one that was read, as the module's own clamping leaves it (`check.run_steps`).
    """

    address: int
    steps: tuple[Step, ...]
    bus_time: float
    naive_bus_time: float
    releases_axes: bool
    predicted: ModuleImage

    @property
    def action(self) -> Action:
        return Action.of_module(len(self.steps))


def program_list(numbers: Iterable[int]) -> str:
    """Program numbers as people read them: "3, 7, 9" or "1..12, 20"; runs of three or more joined."""
    numbers = sorted(numbers)
    parts: list[str] = []
    start = 0
    while start < len(numbers):
        end = start
        while end + 1 < len(numbers) and numbers[end + 1] == numbers[end] + 1:
            end += 1
        if end - start >= 2:
            parts.append(f"{numbers[start]}..{numbers[end]}")
        else:
            parts.extend(str(n) for n in numbers[start : end + 1])
        start = end + 1
    return ", ".join(parts)


def _programs(message: codec.Message) -> str:
    numbers = tuple(message.touched_programs())
    return f"program {numbers[0]}" if len(numbers) == 1 else f"programs {program_list(numbers)}"


def _range(message: Any) -> str:
    return f"programs {message.first}..{message.last}"


_SUMMARIES: dict[type[codec.Message], Callable[[Any], str]] = {
    codec.InitSystem: lambda m: "initialise system parameters to factory defaults",
    codec.InitAllPrograms: lambda m: f"initialise all {PROGRAM_COUNT} programs",
    codec.InitProgram: lambda m: f"initialise {_programs(m)}",
    codec.InitProgramsFrom: lambda m: f"initialise programs {m.pn}..{PROGRAM_COUNT}",
    codec.InitPrograms: lambda m: f"initialise {_range(m)}",
    codec.WriteProgram: lambda m: f"write {_programs(m)}",
    codec.LinkPrograms: lambda m: f"link {_range(m)}",
    codec.UnlinkPrograms: lambda m: f"unlink {_range(m)}",
    codec.WritePartProgram: lambda m: f"write P, V of {_programs(m)}",
    codec.WritePartPrograms: lambda m: f"write P, V of {_programs(m)}",
    codec.WriteAddresses: lambda m: f"write A of {_programs(m)}",
    **{cls: (lambda m: f"write {m.FIELD} of {_programs(m)}") for cls in codec.FIELD_MESSAGES.values()},
}


def summarise(message: codec.Message, system_before: SystemParameters) -> str:
    """One line in device terms, e.g. "write P of programs 3, 7, 9 (40h)"."""
    if isinstance(message, codec.WriteSystem):
        changed = [key for key, old, new in zip(
            SYSTEM_KEYS, system_before.values(), message.system.values()) if old != new]
        text = f"write system parameters {', '.join(changed)}"
    else:
        text = _SUMMARIES[type(message)](message)
    return f"{text} ({message.ID:02X}h)"
