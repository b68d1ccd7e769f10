"""Human units ↔ device units, exactly: the one table of every PRC 3 value a plant file sets.

A plant file says metres, m/s, seconds and m/s²; a module holds integers in mm, mm/s,
0.1 s and 0.001 m/s² (docs/protocol.md "Values"). The conversion is decimal arithmetic on the
number as written: `step` is the size of one device unit in human units, a human value
must be a whole number of steps (0.0005 m is an error, never rounded), and device → human
is `device × step` (1050 → Decimal("1.050")). F1/F2 are `{action, distance}` ↔
`action × 1000 + mm` (§1.1). S9 (the module address) is not here: a plant file sets it as
`address`. Device → human is `plant_value` (what a plant file writes) and `human_text` (what
people read): rendering, `show`, `import` and `adopt` all convert through them.

Owns the table and the arithmetic. Not the ranges: a value's device range is the device
model's (`prc3cfg.core.device.widest_range`), converted here. Does not own validation messages
or the plant file's structure (`prc3cfg.plant.models`). Pure.
"""

from __future__ import annotations

from dataclasses import dataclass
from decimal import Decimal
from typing import Any, Literal, get_args

from prc3cfg.core.device import widest_range

MM = Decimal("0.001")
#: F1/F2: action × `PER_ACTION` + distance in mm (docs/protocol.md "Values").
PER_ACTION = 1000


@dataclass(frozen=True, slots=True)
class Quantity:
    """One value: its plant-file key, its device symbol, its step; its device range (`lo`, `hi`) is
    the device model's (`device_range`).

    `step_name` and `what` word the "not a whole number" message: "0.0005 m is not a whole
    number of millimetres — positions are in steps of 0.001 m".
    """

    key: str
    symbol: str
    step: Decimal
    unit: str
    step_name: str = ""
    what: str = ""
    boolean: bool = False

    @property
    def integer(self) -> bool:
        """A plain count (S3, S7, …): step 1, no unit, written as a whole number."""
        return self.step == 1 and not self.unit

    @property
    def lo(self) -> int:
        return device_range(self.symbol)[0]

    @property
    def hi(self) -> int:
        return device_range(self.symbol)[1]

    @property
    def human_lo(self) -> Decimal:
        return self.lo * self.step

    @property
    def human_hi(self) -> Decimal:
        return self.hi * self.step

    def to_device(self, human: Decimal | int | bool) -> int:
        """The device value of an in-range human value; ValueError if not a whole number of steps."""
        # exact: a Decimal of at most 28 digits, an int or a bool, by a power of ten
        units = human / self.step
        whole = int(units)
        if units != whole:
            raise ValueError(f"{human} {self.unit} is not a whole number of {self.step_name}")
        return whole

    def to_human(self, device: int) -> Decimal | int | bool:
        if self.boolean:
            return bool(device)
        if self.integer:
            return device
        return self.in_unit(device)

    def in_unit(self, device: int) -> Decimal:
        """The device value in the quantity's unit (m, m/s, s): for a quantity that has one."""
        return device * self.step


#: Every value a plant file sets, keyed by the plant-file key; order: programs, then system.
QUANTITIES: dict[str, Quantity] = {
    q.key: q
    for q in (
        Quantity("position", "P", MM, "m", "millimetres", "positions are"),
        Quantity("speed", "V", MM, "m/s", "millimetres per second", "speeds are"),
        Quantity("relative_speed", "Vr", MM, "m/s", "millimetres per second", "relative speeds are"),
        Quantity("dwell", "T", Decimal("0.1"), "s", "tenths of a second", "dwell times are"),
        Quantity("distance", "F", MM, "m", "millimetres", "function output distances are"),
        Quantity("upper_reversing_point", "S1", MM, "m", "millimetres", "reversing points are"),
        Quantity("reference_point", "S2", MM, "m", "millimetres", "reference points are"),
        Quantity("increment_pulses", "S3", Decimal(1), ""),
        Quantity("max_speed", "S4", MM, "m/s", "millimetres per second", "speeds are"),
        Quantity("min_speed", "S5", MM, "m/s", "millimetres per second", "speeds are"),
        Quantity("acceleration", "S6", MM, "m/s²", "millimetres per second squared", "accelerations are"),
        Quantity("circuit_gain", "S7", Decimal(1), ""),
        Quantity("alarm", "S8", Decimal(1), "", boolean=True),
        Quantity("sync_increment", "S10", Decimal(1), ""),
        Quantity("sync_circuit_gain", "S11", Decimal(1), ""),
        Quantity("sync_conveyor_sequence", "S12", MM, "m", "millimetres", "sync conveyor sequences are"),
    )
}
BY_SYMBOL: dict[str, Quantity] = {q.symbol: q for q in QUANTITIES.values()}


def device_range(symbol: str) -> tuple[int, int]:
    """The device values a plant file may give the quantity `symbol`: those some module holds
    (`prc3cfg.core.device.widest_range`); for a distance (F), the millimetres of F1 and F2."""
    if symbol == "F":
        low, high = widest_range("F1")
        return low % PER_ACTION, high % PER_ACTION
    return widest_range(symbol)


#: Program fields set by a number; F1, F2 and A are set otherwise (function outputs, chains).
PROGRAM_QUANTITIES = tuple(QUANTITIES[k] for k in ("position", "speed", "relative_speed", "dwell"))
#: System parameters in message order (image.SYSTEM_KEYS).
SYSTEM_QUANTITIES = tuple(q for q in QUANTITIES.values() if q.symbol.startswith("S"))

#: F1/F2's action (`PER_ACTION`).
Action = Literal["reset", "set"]
ACTIONS: dict[str, int] = {name: code for code, name in enumerate(get_args(Action))}  # reset 0, set 1
_ACTION_NAMES: dict[int, str] = {code: name for name, code in ACTIONS.items()}
DISTANCE = QUANTITIES["distance"]
#: The program fields that hold an action and a distance.
FUNCTION_OUTPUTS = ("F1", "F2")


def function_output(action: str, distance: Decimal) -> int:
    """{action: set, distance: 0.010} → 1010."""
    return ACTIONS[action] * PER_ACTION + DISTANCE.to_device(distance)


def function_output_parts(device: int) -> tuple[str, int]:
    """1010 → ("set", 10): the action and the distance in device units (mm)."""
    return _ACTION_NAMES[device // PER_ACTION], device % PER_ACTION


def split_function_output(device: int) -> tuple[str, Decimal]:
    """1010 → ("set", Decimal("0.010")); 50 → ("reset", Decimal("0.050"))."""
    action, distance = function_output_parts(device)
    return action, DISTANCE.in_unit(distance)


def plant_value(symbol: str, device: int) -> Decimal | int | bool | dict[str, Any]:
    """A device value as a plant file writes it: P 1050 → Decimal("1.050"), S8 1 → True, S3 754 → 754,
    F1 1010 → {"action": "set", "distance": Decimal("0.010")}."""
    if symbol in FUNCTION_OUTPUTS:
        action, distance = split_function_output(device)
        return {"action": action, DISTANCE.key: distance}
    return BY_SYMBOL[symbol].to_human(device)


def human_text(symbol: str, device: int) -> str:
    """A device value as people read it, with its unit: "1.050 m", "true", "754", "set at 0.010 m"."""
    value = plant_value(symbol, device)
    if isinstance(value, dict):
        return f"{value['action']} at {value[DISTANCE.key]} {DISTANCE.unit}"
    if isinstance(value, bool):
        return str(value).lower()
    return f"{value} {BY_SYMBOL[symbol].unit}".rstrip()
