"""The PRC 3 module: exactly what one module does with a message (docs/protocol.md "What a module does").

This is *the* model of a module. The emulator serves it and the planner runs plans on it
to predict what the modules will do on their own (clamping, defaults, link/unlink), so
there is never a second, slightly different copy of these rules.

Owns: the operating state (mode, active program, fault, referenced), the checks 6–9 of
§4.5 in their order (checks 1–5 are decoding, `prc3cfg.core.codec.decode_message`), atomic
rejection, defaults, clamping after 10h/20h, axis release, and the state-file entry of a
module (docs/files.md "Emulator state"). Does not own bytes on a line (`prc3cfg.core.framing`) or the bus
(`prc3cfg.shell.emulator`). Pure: no I/O; a state is an immutable value and every message gives
a new one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from typing import Any

from prc3cfg.core import codec
from prc3cfg.core.codec import Message, Rejected
from prc3cfg.core.error_codes import ACCEPTED, FAULT_STATES
from prc3cfg.core.exchange import FIRMWARE_ADDED
from prc3cfg.core.image import (
    DEFAULT_SYSTEM,
    PROGRAM_COUNT,
    ModuleImage,
    Program,
    SystemParameters,
    default_program,
)

MODES = ("stop", "run", "manual")
#: A fault condition → the code every write is rejected with (§4.4).
FAULT_CODES: dict[str, int] = {name: code for code, name in FAULT_STATES.items()}

#: Fixed value ranges, kind → (lowest, highest, code below, code above) (§4.5 step 9): the one
#: table of the device's ranges. The plant file's bounds (`prc3cfg.core.units`), the emulator's
#: state file and the rendering of read-backs all derive theirs from it (`widest_range`).
#: A and S8 travel as unsigned bytes, so they are never below their lowest.
VALUE_RANGES: dict[str, tuple[int, int, int, int]] = {
    "Vr": (-600, 600, 50, 51),
    "T": (0, 600, 60, 61),
    "F1": (0, 1999, 70, 71),  # (reading) 71: the manual lists no code for F1 > 1999
    "F2": (0, 1999, 72, 73),  # (reading) 72: the manual lists no code for F2 < 0
    "A": (0, PROGRAM_COUNT, 80, 80),
    "S1": (100, 9999, 100, 101),
    "S2": (50, 500, 102, 103),
    "S3": (1, 9999, 104, 105),
    "S4": (1, 600, 106, 107),
    "S5": (1, 600, 108, 109),
    "S6": (1000, 1500, 112, 113),
    "S7": (800, 1500, 114, 115),
    "S8": (0, 1, 116, 116),
    "S10": (1, 9999, 117, 118),
    "S11": (1, 1500, 119, 120),
    "S12": (5, 50, 121, 122),
}
S4_BELOW_S5 = 110


def value_range(kind: str, system: SystemParameters) -> tuple[int, int, int, int]:
    """The range a value of `kind` must lie in on a module holding `system`.

    P and V are checked against the S1, S4, S5 in force when the message arrives.
    """
    if kind == "P":
        return 0, system.S1, 31, 32
    if kind == "V":
        return system.S5, system.S4, 40, 41
    return VALUE_RANGES[kind]


#: The system parameters under which P and V may take every value any module allows: the highest
#: S1 and S4, the lowest S5.
WIDEST_SYSTEM = replace(DEFAULT_SYSTEM, S1=VALUE_RANGES["S1"][1], S4=VALUE_RANGES["S4"][1],
                        S5=VALUE_RANGES["S5"][0])


def widest_range(kind: str) -> tuple[int, int]:
    """The lowest and highest value of `kind` that some module holds: P 0..9999, V 1..600, the rest their
    fixed range."""
    low, high, _, _ = value_range(kind, WIDEST_SYSTEM)
    return low, high


@dataclass(frozen=True, slots=True)
class ModuleState:
    """One module: its image (all 64 programs present) and its operating state."""

    image: ModuleImage
    mode: str = "stop"
    active_program: int | None = None
    fault: str | None = None
    referenced: bool = True
    #: False for firmware before PRC 3.03.1 (June 1994), which added the read messages 50h..52h: such a
    #: module answers them as it answers any ID it does not know (code 10). (reading: the manual names
    #: the firmware that added them, not how an older one answers; any unknown ID is refused with 10.)
    read_messages: bool = True
    #: False for firmware before PRC 3.02.1 (February 1994), which added function output F2 (45h): such a
    #: module answers 45h with code 10, and — older than 3.03.1 too — its reads as well.
    f2_messages: bool = True

    def __post_init__(self) -> None:
        if not self.f2_messages and self.read_messages:
            raise ValueError("a module without function output F2 (firmware before PRC 3.02.1) has no read "
                             "messages either (PRC 3.03.1)")
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {', '.join(MODES)}, not {self.mode!r}")
        if self.fault is not None and self.fault not in FAULT_CODES:
            raise ValueError(f"fault must be null or one of {', '.join(FAULT_CODES)}, not {self.fault!r}")
        if self.active_program is not None and not 1 <= self.active_program <= PROGRAM_COUNT:
            raise ValueError(f"active program must be 1..{PROGRAM_COUNT}, not {self.active_program}")
        if not all(self.image.programs):  # a Program is always true: only None, a program not held, is not
            raise ValueError("a module holds all 64 programs")

    @classmethod
    def factory(cls, address: int) -> ModuleState:
        return cls(ModuleImage.factory(address))

    @property
    def address(self) -> int:
        return self.image.address

    def to_json(self) -> dict[str, Any]:
        older = ({} if self.read_messages else {"read_messages": False}) | (
            {} if self.f2_messages else {"f2_messages": False})
        return {
            **self.image.to_json(),
            "mode": self.mode,
            "active_program": self.active_program,
            "fault": self.fault,
            "referenced": self.referenced,
        } | older

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> ModuleState:
        return cls(
            image=ModuleImage.from_json(data),
            mode=data.get("mode", "stop"),
            active_program=data.get("active_program"),
            fault=data.get("fault"),
            referenced=data.get("referenced", True),
            read_messages=data.get("read_messages", True),
            f2_messages=data.get("f2_messages", True),
        )


# -- what a message does -----------------------------------------------------------------


def _clamped(system: SystemParameters, programs: tuple[Program, ...]) -> tuple[Program, ...]:
    """§4.2: after new system parameters, P > S1 → S1, V > S4 → S4, V < S5 → S5."""
    out = []
    for p in programs:
        position = min(p.P, system.S1)
        speed = max(min(p.V, system.S4), system.S5)
        out.append(p if (position, speed) == (p.P, p.V) else p.with_position_and_speed(position, speed))
    return tuple(out)


def can_clamp(before: SystemParameters, after: SystemParameters) -> bool:
    """Whether storing `after` over `before` can clamp a program that `before` let stand (§4.2):
    a lower S1 or S4, or a higher S5."""
    return after.S1 < before.S1 or after.S4 < before.S4 or after.S5 > before.S5


def _set_system(state: ModuleState, system: SystemParameters) -> ModuleState:
    """10h/20h: store, clamp every program, release the axes; an E12 fault is cleared (§4.3, §4.4)."""
    image = ModuleImage(state.image.address, system, _clamped(system, state.image.complete()))
    return replace(state, image=image, referenced=False, fault=None)


def _with_image(state: ModuleState, image: ModuleImage) -> ModuleState:
    """`state` holding `image`: what most writes do — built directly, as `dataclasses.replace` costs
    three times as much (a plan's proof and the broadcast search run 100,000 writes for 32 × 30 modules)."""
    return ModuleState(image, state.mode, state.active_program, state.fault, state.referenced,
                       state.read_messages, state.f2_messages)


# `_with_image` names every field of a state: one added would otherwise fall back to its default
# on each write.
assert [f.name for f in fields(ModuleState)] == ["image", "mode", "active_program", "fault", "referenced",
                                                 "read_messages", "f2_messages"]


def _init_programs(state: ModuleState, numbers: range | tuple[int, ...]) -> ModuleState:
    default = default_program(state.image.system)
    return _with_image(state, state.image.with_programs({n: default for n in numbers}))


def _set_fields(state: ModuleState, field: str, items: tuple[tuple[int, int], ...]) -> ModuleState:
    image = state.image
    changes: dict[int, Program] = {}
    for number, value in items:
        current = changes.get(number) or image.known(number)
        changes[number] = current.with_field(field, value)
    return _with_image(state, image.with_programs(changes))


def _set_positions_and_speeds(state: ModuleState, first: int,
                              items: tuple[tuple[int, int], ...]) -> ModuleState:
    image = state.image
    changes = {
        first + i: image.known(first + i).with_position_and_speed(position, speed)
        for i, (position, speed) in enumerate(items)
    }
    return _with_image(state, image.with_programs(changes))


def _link(state: ModuleState, first: int, last: int) -> ModuleState:
    image = state.image
    changes = {n: image.known(n).with_field("A", n + 1 if n < last else 0) for n in range(first, last + 1)}
    return _with_image(state, image.with_programs(changes))


_EFFECTS: dict[type[Message], Callable[[ModuleState, Any], ModuleState]] = {
    codec.InitSystem: lambda s, m: _set_system(s, DEFAULT_SYSTEM),
    codec.WriteSystem: lambda s, m: _set_system(s, m.system),
    codec.InitAllPrograms: lambda s, m: _init_programs(s, m.touched_programs()),
    codec.InitProgram: lambda s, m: _init_programs(s, m.touched_programs()),
    codec.InitProgramsFrom: lambda s, m: _init_programs(s, m.touched_programs()),
    codec.InitPrograms: lambda s, m: _init_programs(s, m.touched_programs()),
    codec.WriteProgram: lambda s, m: _with_image(s, s.image.with_programs({m.pn: m.program})),
    codec.LinkPrograms: lambda s, m: _link(s, m.first, m.last),
    codec.UnlinkPrograms: lambda s, m: _set_fields(s, "A", tuple((n, 0) for n in m.programs)),
    codec.WritePartProgram: lambda s, m: _set_positions_and_speeds(s, m.pn, ((m.position, m.speed),)),
    codec.WritePartPrograms: lambda s, m: _set_positions_and_speeds(s, m.first, m.items),
    codec.WriteAddresses: lambda s, m: _set_fields(s, "A", m.items),
    **{cls: (lambda s, m: _set_fields(s, m.FIELD, m.items)) for cls in codec.FIELD_MESSAGES.values()},
}


def _check_values(state: ModuleState, message: Message) -> None:
    """§4.5 step 9: the first bad value, in message order, gives the code."""
    system = state.image.system
    seen: dict[str, int] = {}
    for kind, value in message.checked_values():
        low, high, code_low, code_high = value_range(kind, system)
        if value < low:
            raise Rejected(code_low, f"{kind} = {value}")
        if value > high:
            raise Rejected(code_high, f"{kind} = {value}")
        seen[kind] = value
        if kind == "S5" and seen["S4"] < value:
            # 20h: the pair check comes right after S5's own range checks, before S6.
            raise Rejected(S4_BELOW_S5, f"S4 = {seen['S4']} < S5 = {value}")


def check_write(state: ModuleState, message: Message) -> None:
    """§4.5 steps 6–9 for a decoded write; raises `Rejected` with the first failing check's code."""
    # 6. operating state: the fault first, even in RUN; in E12, 10h and 20h are let through.
    if state.fault is not None and not (state.fault == "E12" and message.RELEASES_AXES):
        raise Rejected(FAULT_CODES[state.fault], f"fault {state.fault}")
    running = state.mode == "run"
    if running and message.RELEASES_AXES:
        raise Rejected(20, "module in RUN")
    # 7. item program numbers.
    for number in message.item_program_numbers():
        if not 1 <= number <= PROGRAM_COUNT:
            raise Rejected(15, f"program number {number}")
    # 8. the active program. (reading) A program is only "active" while the module runs:
    # in STOP an active_program left in the state does not block writes.
    if running and state.active_program is not None and state.active_program in message.touched_programs():
        raise Rejected(16, f"program {state.active_program} is active")
    # 9. values.
    _check_values(state, message)


def execute(state: ModuleState, message: Message) -> ModuleState:
    """The state after a decoded write is accepted; raises `Rejected` and changes nothing otherwise."""
    check_write(state, message)
    return _EFFECTS[type(message)](state, message)


def read(state: ModuleState, message: Message) -> bytes:
    """The data block a decoded read (50h..52h) is answered with."""
    if isinstance(message, codec.ReadSystem):
        return codec.SystemReply(state.image.system, state.address).encode()
    if not isinstance(message, codec.ReadProgram | codec.ReadPrograms):
        raise TypeError(f"{message.ID:02X}h is not a read")
    first = message.programs.start
    return codec.ProgramsReply(first, state.image.complete()[first - 1 : message.programs.stop - 1]).encode()


@dataclass(frozen=True, slots=True)
class Outcome:
    """What a module did with bytes addressed to it: its new state and its reply (None: silence)."""

    state: ModuleState
    reply: bytes | None


def process(state: ModuleState, data: bytes, *, broadcast: bool = False) -> Outcome:
    """A module receives the message `data`: every check of §4.5, in order, then the effect.

    (reading) A module in MANUAL neither answers nor processes anything, broadcasts
    included. A broadcast (address 0) is processed like any message and answered by none.
    """
    if state.mode == "manual":
        return Outcome(state, None)
    try:
        message = codec.decode_message(data)
        if (message.IS_READ and not state.read_messages) or (message.ID == codec.WriteF2.ID
                                                             and not state.f2_messages):
            raise Rejected(10, f"ID {message.ID:02X}h: firmware before PRC {FIRMWARE_ADDED[message.ID][0]}")
        if message.IS_READ:
            new_state, reply = state, read(state, message)
        else:
            new_state, reply = execute(state, message), codec.encode_code(ACCEPTED)
    except Rejected as rejected:
        new_state, reply = state, codec.encode_code(rejected.code)
    return Outcome(new_state, None if broadcast else reply)
