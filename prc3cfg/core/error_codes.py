"""The PRC 3 error codes (manual §3, docs/protocol.md "What a module does"): number → meaning → what to do.

One table, used by the device model's tests, the link client and every message shown to a
person. Pure.
"""

from __future__ import annotations

from typing import NamedTuple

ACCEPTED = 0


class ErrorCode(NamedTuple):
    meaning: str
    remedy: str


_STOP = "put the module in STOP (and AUTOMATIC), then run again"
_FAULT = "clear the fault on the module, then run again"
_BUG = "prc3cfg built a message the module did not understand: report this as a bug"
_VALUE = "fix the value in the plant file (or the module's system parameters), then run again"

ERROR_CODES: dict[int, ErrorCode] = {
    10: ErrorCode("invalid identification number (ID)", _BUG),
    11: ErrorCode("invalid length (message shorter than 1 byte)", _BUG),
    12: ErrorCode("invalid length (message longer than 64 bytes)", _BUG),
    13: ErrorCode("data block not complete (message shorter than its data block)", _BUG),
    14: ErrorCode("data block too long (message longer than its data block)", _BUG),
    15: ErrorCode("invalid program number", _BUG),
    16: ErrorCode("program is active: its data cannot be written while it runs", _STOP),
    20: ErrorCode("operating condition is not STOP: system parameters can only be changed in STOP", _STOP),
    21: ErrorCode("operating condition is error E09 (emergency stop)", _FAULT),
    22: ErrorCode("operating condition is error E10 (reference point not reached)", _FAULT),
    23: ErrorCode("operating condition is error E12 (system parameters not set)",
                  "write the system parameters (10h or 20h) first, then run again"),
    24: ErrorCode("operating condition is error E20 (upper reversing point over-run)", _FAULT),
    25: ErrorCode("operating condition is error E21 (positioning error)", _FAULT),
    26: ErrorCode("operating condition is error E22 (fault in the axis movement monitoring)", _FAULT),
    27: ErrorCode("operating condition is error E23 (fault in the dwell time monitoring)", _FAULT),
    28: ErrorCode("operating condition is error E24 (fault in the incremental pulse generator monitoring)",
                  _FAULT),
    29: ErrorCode("operating condition is error E25 (fault in the incremental pulse generator monitoring)",
                  _FAULT),
    30: ErrorCode("operating condition is an undefinable fault", _FAULT),
    31: ErrorCode("P < 0: position must not be smaller than 0", _VALUE),
    32: ErrorCode("P > S1: position must not be greater than the upper reversing point", _VALUE),
    40: ErrorCode("V < S5: speed must not be smaller than the minimum speed", _VALUE),
    41: ErrorCode("V > S4: speed must not be greater than the maximum speed", _VALUE),
    50: ErrorCode("Vr < -600: relative speed must not be smaller than -0.600 m/s", _VALUE),
    51: ErrorCode("Vr > 600: relative speed must not be greater than 0.600 m/s", _VALUE),
    60: ErrorCode("T < 0: dwell time must not be smaller than 0.0 s", _VALUE),
    61: ErrorCode("T > 600: dwell time must not be greater than 60.0 s", _VALUE),
    70: ErrorCode("F1 < 0: function value must not be smaller than 0.000", _VALUE),
    71: ErrorCode("F1 > 1999: function value must not be greater than 1.999", _VALUE),
    72: ErrorCode("F2 < 0: function value must not be smaller than 0.000", _VALUE),
    73: ErrorCode("F2 > 1999: function value must not be greater than 1.999", _VALUE),
    80: ErrorCode("A > 64: the jump address must not be greater than 64", _VALUE),
    100: ErrorCode("S1 < 100: upper reversing point must not be smaller than 0.100 m", _VALUE),
    101: ErrorCode("S1 > 9999: upper reversing point must not be greater than 9.999 m", _VALUE),
    102: ErrorCode("S2 < 50: reference point must not be smaller than 0.050 m", _VALUE),
    103: ErrorCode("S2 > 500: reference point must not be greater than 0.500 m", _VALUE),
    104: ErrorCode("S3 < 1: increment pulses must not be smaller than 1", _VALUE),
    105: ErrorCode("S3 > 9999: increment pulses must not be greater than 9999", _VALUE),
    106: ErrorCode("S4 < 1: maximum speed must not be smaller than 0.001 m/s", _VALUE),
    107: ErrorCode("S4 > 600: maximum speed must not be greater than 0.600 m/s", _VALUE),
    108: ErrorCode("S5 < 1: minimum speed must not be smaller than 0.001 m/s", _VALUE),
    109: ErrorCode("S5 > 600: minimum speed must not be greater than 0.600 m/s", _VALUE),
    110: ErrorCode("S4 < S5: maximum speed must not be smaller than the minimum speed", _VALUE),
    112: ErrorCode("S6 < 1000: acceleration must not be smaller than 1.000 m/s²", _VALUE),
    113: ErrorCode("S6 > 1500: acceleration must not be greater than 1.500 m/s²", _VALUE),
    114: ErrorCode("S7 < 800: circuit amplification must not be smaller than 800", _VALUE),
    115: ErrorCode("S7 > 1500: circuit amplification must not be greater than 1500", _VALUE),
    116: ErrorCode("S8 > 1: the alarm parameter must not be greater than 1", _VALUE),
    117: ErrorCode("S10 < 1: sync increment must not be smaller than 1", _VALUE),
    118: ErrorCode("S10 > 9999: sync increment must not be greater than 9999", _VALUE),
    119: ErrorCode("S11 < 1: sync circuit amplification must not be smaller than 1", _VALUE),
    120: ErrorCode("S11 > 1500: sync circuit amplification must not be greater than 1500", _VALUE),
    121: ErrorCode("S12 < 5: conveyor sequence must not be smaller than 5 mm", _VALUE),
    122: ErrorCode("S12 > 50: conveyor sequence must not be greater than 50 mm", _VALUE),
}


#: The codes a module in a fault state refuses every write with (§4.4), by code: the fault's name on
#: the module's display. The device model's `FAULT_CODES` is this, turned round.
FAULT_STATES: dict[int, str] = {
    21: "E09", 22: "E10", 23: "E12", 24: "E20", 25: "E21", 26: "E22", 27: "E23", 28: "E24", 29: "E25",
                                30: "fault",
}


def fault_said(code: int) -> str:
    """A fault state as told to a person: its name and what it is ("E21 (positioning error)")."""
    meaning = ERROR_CODES[code].meaning
    what = (meaning.split("(", 1)[1].rstrip(")") if "(" in meaning
            else meaning.removeprefix("operating condition is "))
    return f"{FAULT_STATES[code]} ({what})" if FAULT_STATES[code] != "fault" else "an undefinable fault"


def describe(code: int) -> str:
    """The meaning of a reply code, as shown to people; "unknown code N" outside the table."""
    if code == ACCEPTED:
        return "accepted"
    entry = ERROR_CODES.get(code)
    return f"code {code}: {entry.meaning}" if entry else f"unknown code {code}"


def remedy(code: int) -> str:
    entry = ERROR_CODES.get(code)
    return entry.remedy if entry else "check the module's firmware and the line, then run again"
