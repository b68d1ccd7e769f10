"""The INIT data block of a CP 524/525 running the Open Driver S5D004 (seed 004 §5.2, §9.4).

Owns the eight data words the S5 program hands to the driver with the special job
INIT (SEND-DIREKT A-NR 189), the code tables for them, and the checks the driver makes
when it evaluates them (SYSTAT 8Bh..95h). Does not own the line itself (`prc3cfg.core.line`),
the `open-driver` framing, or talking to a PLC. Pure: no serial port, no sockets, no files.

    DW 1  EMPFDB  | EMPFDW     KY   receive DB (>= 3) | first data word
    DW 2  ECPUNR  | EKENN      KY   CPU number 0..4   | receive identifier 1..223
    DW 3  PROPAM               KM   ...... DD SS PP BBBB   data bits, stop bits, parity, baud
    DW 4  PROPAR               KM   A V S Z EE X X ...... R F   (bit 15 .. bit 0)
    DW 5  ENDEZ1  | ENDEZ2     KH   end identifiers (hex codes, §5.2.6)
    DW 6  TELLEN               KF   message / part block length, 0 = none
    DW 7  ZVZTIM               KF   character delay time, ms
    DW 8  XOFFTIM              KF   XOFF monitoring time, ms

Two layers of "no":
- a value that cannot be written into its byte or word at all (EMPFDW 300, ZVZ 70000 ms,
  a negative number) is a `ValueError` when `GatewaySettings` is built — the driver never
  sees it, so the manual gives it no SYSTAT number;
- a value that can be written but that the driver refuses is a `Refusal` with the driver's
  SYSTAT number, and `init_data_block` raises `GatewayRefused` for it.

The seed's §9.4.4 ("when evaluating an INIT-DB") has a heading and no table; every INIT-DB
check with a number is the 8Bh..95h table printed under §9.4.3, all implemented here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

from prc3cfg.core.line import LineSettings
from prc3cfg.errors import UserError

# PROPAM bits 0-3 (§5.2.4). (reading) The manual prints 1011 for both 200 and 150 baud;
# the project reads 200 baud as 1010, the one code left free between 300 (1001) and 150 (1011).
BAUD_CODES = {
    19200: 0b0011, 9600: 0b0100, 4800: 0b0101, 2400: 0b0110, 1200: 0b0111, 600: 0b1000,
    300: 0b1001, 200: 0b1010, 150: 0b1011, 110: 0b1100, 75: 0b1101, 50: 0b1111,
}
PARITY_CODES = {"none": 0b00, "odd": 0b10, "even": 0b11}           # PROPAM bits 4-5
STOP_BIT_CODES = {1: 0b00, 1.5: 0b01, 2: 0b10, 0.75: 0b11}         # PROPAM bits 6-7
DATA_BIT_CODES = {8: 0b00, 7: 0b01, 6: 0b10, 5: 0b11}              # PROPAM bits 8-9

PROPAR_BITS = {                                                    # §5.2.5, bit numbers
    "break_evaluation_off": 1, "rs485": 2, "xon_xoff_receive": 8, "xon_xoff_output": 9,
    "echo": 12, "keep_free_after_stx": 13, "full_duplex": 14, "trailing_ff": 15,
}
END_CRITERIA = {"zvz": 0b00, "one-end-char": 0b01, "two-end-chars": 0b10, "fixed-length": 0b11}
END_CRITERION_SHIFT = 10                                           # PROPAR bits 11,10

# Interface modules the driver runs on (§1, §5.2.5.2, §5.4): V.24 (RS232) and TTY on
# CP 524 and CP 525, RS422 (and RS485 through PROPAR bit 2) on CP 524 only.
INTERFACE_MAX_BAUD = {"rs422": 19200, "v24": 19200, "tty": 9600}
INTERFACE_NAMES = {"rs422": "RS422", "v24": "V.24", "tty": "TTY (20 mA)"}
CP_TOTAL_BAUD = 19200      # §5.4: total baud rate of a CP 525, maximum speed of a CP 524

MIN_ZVZ_MS = 4
#: The manual's guide to ZVZ by baud rate, ms, for a partner that sends its characters back to
#: back (seed 004 §5.2.8).
ZVZ_GUIDE_MS = {9600: (5, 100), 4800: (10, 200), 1200: (30, 800), 110: (200, 3000)}
MIN_XOFF_MS = 4
MIN_RECEIVE_DB = 3
MAX_CPU = 4
IDENTIFIERS = range(1, 224)
MAX_TELLEN = 1024

# The manual's reason for each INIT-DB error, as printed (§9.4.3, ANZW 7 for all).
SYSTAT_TEXT = {
    0x8B: "Illegal Baudrate in PROPAM",
    0x8C: "Illegal Parity in PROPAM",
    0x8D: "PROPAR: full duplex only possible, without echo, w/o XON/XOFF-Protocol and w/o "
          "STX-keep free time",
    0x8E: 'Character delay time "ZVZTIM" smaller 4ms',
    0x8F: 'Number of Receive Data Block "EMPFDB" smaller 3',
    0x90: 'CPU-Nummer greater 4 "ECPUNR"',
    0x91: 'Illegal value for "EKENN" (1 to 223 permitted)',
    0x92: 'Illegal value in "TELLEN" (1 to 1024 permitted)',
    0x93: "PROPAR: RS485-operation only possible, without echo, w/o XON/XOFF-Protocol, half "
          "duplex, w/o keep free time after STX and w/o BREAK-recognition",
    0x94: "RS485-operatiron, but no CP524 with RS485/RS422-sub-module",
    0x95: '"XOFFTIM" smaller 4 ms',
}

# What fits the block: byte fields 0..255, word fields 0..65535.
_FIELD_MAX = {
    "receive_db": 0xFF, "receive_dw": 0xFF, "cpu": 0xFF, "identifier": 0xFF,
    "telegram_length": 0xFFFF, "zvz_ms": 0xFFFF, "xoff_ms": 0xFFFF,
}


@dataclass(frozen=True, slots=True)
class GatewaySettings:
    """One interface of the Open Driver. The PROPAR options default off, as a PRC 3 line needs."""

    receive_db: int             # EMPFDB
    receive_dw: int             # EMPFDW
    cpu: int                    # ECPUNR, 0 = every CPU
    identifier: int             # EKENN
    line: LineSettings
    zvz_ms: int                 # ZVZTIM
    break_evaluation_off: bool = False
    rs485: bool = False
    xon_xoff_receive: bool = False
    xon_xoff_output: bool = False
    echo: bool = False
    keep_free_after_stx: bool = False
    full_duplex: bool = False
    trailing_ff: bool = False
    end_criterion: str = "zvz"
    end_chars: tuple[int, int] = (0, 0)   # ENDEZ1, ENDEZ2: read for one (ENDEZ1) or two end ids
    telegram_length: int = 0              # TELLEN: part block length, or the fixed length
    xoff_ms: int = 0                      # XOFFTIM: read only with XON/XOFF for output
    interface: str = "rs422"              # rs422 | v24 | tty

    def __post_init__(self) -> None:
        for name, top in _FIELD_MAX.items():
            value = getattr(self, name)
            if not 0 <= value <= top:
                raise ValueError(f"{name} {value} does not fit its INIT-DB field (0..{top})")
        if len(self.end_chars) != 2 or not all(0 <= c <= 0xFF for c in self.end_chars):
            raise ValueError(f"end_chars must be two bytes 0..255, not {self.end_chars!r}")
        if self.end_criterion not in END_CRITERIA:
            raise ValueError(f"end_criterion must be one of {', '.join(END_CRITERIA)}, "
                             f"not {self.end_criterion!r}")
        if self.interface not in INTERFACE_MAX_BAUD:
            raise ValueError(f"interface must be one of {', '.join(INTERFACE_MAX_BAUD)}, "
                             f"not {self.interface!r}")


@dataclass(frozen=True, slots=True)
class Refusal:
    """One reason the driver would refuse the INIT: its SYSTAT number and the field it is about."""

    systat: int
    field: str
    reason: str

    def __str__(self) -> str:
        return f"SYSTAT {self.systat:02X}h: {self.reason}"


class GatewayRefused(UserError):
    """The Open Driver would refuse this INIT data block (LED blinks four times)."""

    def __init__(self, found: Sequence[Refusal]) -> None:
        self.refusals = tuple(found)
        super().__init__("the Open Driver would refuse this INIT data block — "
                         + "; ".join(map(str, self.refusals))
                         + " — correct the gateway settings")


class _Check(NamedTuple):
    systat: int
    field: str
    fails: Callable[[GatewaySettings], bool]
    reason: Callable[[GatewaySettings], str]


def _baud_over_interface(s: GatewaySettings) -> bool:
    return s.line.baud in BAUD_CODES and s.line.baud > INTERFACE_MAX_BAUD[s.interface]


def _baud_over_total(s: GatewaySettings) -> bool:
    return s.full_duplex and s.line.baud in BAUD_CODES and 2 * s.line.baud > CP_TOTAL_BAUD


def _full_duplex_with(flag: str, what: str) -> _Check:
    return _Check(0x8D, flag, lambda s: s.full_duplex and getattr(s, flag),
                  lambda s: f"full duplex is only possible without {what}")


def _rs485_needs(flag: str, bad: bool, what: str) -> _Check:
    return _Check(0x93, flag, lambda s: s.rs485 and getattr(s, flag) == bad,
                  lambda s: f"RS485 operation is only possible {what}")


# Every INIT-DB check of the driver, in SYSTAT order.
CHECKS: tuple[_Check, ...] = (
    _Check(0x8B, "line.baud", lambda s: s.line.baud not in BAUD_CODES,
           lambda s: f"{s.line.baud} baud is not a baud rate of the driver "
                     f"({', '.join(map(str, sorted(BAUD_CODES)))})"),
    # (reading) §5.4 says a TTY interface must not run above 9600 baud but names no SYSTAT;
    # the tool refuses it as an illegal baud rate, 8Bh.
    _Check(0x8B, "line.baud", _baud_over_interface,
           lambda s: f"{s.line.baud} baud is above the {INTERFACE_MAX_BAUD[s.interface]} baud "
                     f"a {INTERFACE_NAMES[s.interface]} interface allows"),
    # (reading) §5.4: in full duplex the baud rate counts twice against the CP's total of
    # 19200 baud, so full duplex at 19200 baud exceeds it; no SYSTAT named, refused as 8Bh.
    _Check(0x8B, "line.baud", _baud_over_total,
           lambda s: f"full duplex at {s.line.baud} baud counts {2 * s.line.baud} baud against "
                     f"the CP's total of {CP_TOTAL_BAUD} baud"),
    _Check(0x8C, "line.parity", lambda s: s.line.parity not in PARITY_CODES,
           lambda s: f"parity {s.line.parity!r} is not a parity of the driver "
                     f"(none, odd, even)"),
    _full_duplex_with("echo", "echo"),
    _full_duplex_with("xon_xoff_receive", "the XON/XOFF protocol for reception"),
    _full_duplex_with("xon_xoff_output", "the XON/XOFF protocol for output"),
    _full_duplex_with("keep_free_after_stx", "the keep free time after STX"),
    _Check(0x8E, "zvz_ms", lambda s: s.zvz_ms < MIN_ZVZ_MS,
           lambda s: f"character delay time ZVZ {s.zvz_ms} ms is below the driver's minimum "
                     f"of {MIN_ZVZ_MS} ms"),
    _Check(0x8F, "receive_db", lambda s: s.receive_db < MIN_RECEIVE_DB,
           lambda s: f"receive data block DB {s.receive_db} is below DB {MIN_RECEIVE_DB}"),
    _Check(0x90, "cpu", lambda s: s.cpu > MAX_CPU,
           lambda s: f"CPU number {s.cpu} is greater than {MAX_CPU}"),
    _Check(0x91, "identifier", lambda s: s.identifier not in IDENTIFIERS,
           lambda s: f"receive identifier EKENN {s.identifier} is outside "
                     f"{IDENTIFIERS.start}..{IDENTIFIERS.stop - 1}"),
    # (reading) the SYSTAT table says "1 to 1024 permitted", §5.2.7 says 0 means "without
    # part blocks": 0..1024 is accepted, except that a fixed message length needs 1..1024.
    _Check(0x92, "telegram_length", lambda s: s.telegram_length > MAX_TELLEN,
           lambda s: f"message length TELLEN {s.telegram_length} is outside 0..{MAX_TELLEN}"),
    _Check(0x92, "telegram_length",
           lambda s: s.end_criterion == "fixed-length" and s.telegram_length == 0,
           lambda s: f"a fixed message length needs TELLEN 1..{MAX_TELLEN}, not 0"),
    _rs485_needs("full_duplex", True, "in half duplex"),
    _rs485_needs("echo", True, "without echo"),
    _rs485_needs("xon_xoff_receive", True, "without the XON/XOFF protocol for reception"),
    _rs485_needs("xon_xoff_output", True, "without the XON/XOFF protocol for output"),
    _rs485_needs("keep_free_after_stx", True, "without the keep free time after STX"),
    _rs485_needs("break_evaluation_off", False,
                 "with BREAK evaluation off (PROPAR bit 1 = 1)"),
    _Check(0x94, "interface", lambda s: s.rs485 and s.interface != "rs422",
           lambda s: f"RS485 operation needs a CP 524 with the RS422/RS485 module, "
                     f"not a {INTERFACE_NAMES[s.interface]} interface"),
    _Check(0x95, "xoff_ms", lambda s: s.xon_xoff_output and s.xoff_ms < MIN_XOFF_MS,
           lambda s: f"XOFF monitoring time XOFFTIM {s.xoff_ms} ms is below the driver's "
                     f"minimum of {MIN_XOFF_MS} ms"),
)


def refusals(settings: GatewaySettings) -> list[Refusal]:
    """Every reason the driver would refuse `settings`, in SYSTAT order; [] when it accepts."""
    found = [Refusal(c.systat, c.field, c.reason(settings)) for c in CHECKS if c.fails(settings)]
    return sorted(found, key=lambda r: r.systat)


def init_data_block(settings: GatewaySettings) -> tuple[int, ...]:
    """DW 1..8 of the INIT-DB as unsigned 16-bit words; `GatewayRefused` if the driver refuses."""
    if found := refusals(settings):
        raise GatewayRefused(found)
    s, line = settings, settings.line
    propam = (BAUD_CODES[line.baud] | PARITY_CODES[line.parity] << 4
              | STOP_BIT_CODES[line.stop_bits] << 6 | DATA_BIT_CODES[line.data_bits] << 8)
    propar = sum(1 << bit for name, bit in PROPAR_BITS.items() if getattr(s, name))
    propar |= END_CRITERIA[s.end_criterion] << END_CRITERION_SHIFT
    return (
        s.receive_db << 8 | s.receive_dw,
        s.cpu << 8 | s.identifier,
        propam,
        propar,
        s.end_chars[0] << 8 | s.end_chars[1],
        s.telegram_length,
        s.zvz_ms,
        s.xoff_ms,
    )


# S5 constant formats, as the DB189 listing of §10.3.2 writes them.
# (reading) The manual prints KF with five digits ("KF = +00220"); docs/line.md, the project's
# source of truth, writes "KF = +220" — the tool follows docs/line.md.
# (reading) KF is a signed word (-32768..+32767); ZVZTIM and XOFFTIM run to 65535 ms, so a
# word above 32767 is written as KH rather than as a negative KF.
_NOTATIONS: dict[str, Callable[[int], str]] = {
    "KY": lambda w: f"KY = {w >> 8:03d},{w & 0xFF:03d}",
    "KM": lambda w: f"KM = {w >> 8:08b} {w & 0xFF:08b}",
    "KH": lambda w: f"KH = {w:04X}",
    "KF": lambda w: f"KF = {w:+d}" if w <= 0x7FFF else f"KH = {w:04X}",
}
WORD_NOTATION = ("KY", "KY", "KM", "KM", "KH", "KF", "KF", "KF")
# (reading) The manual writes the unused TELLEN and XOFFTIM as "KH = 0000"; a zero DW 6 or
# DW 8 is written that way, a used one as KF. ENDEZ (DW 5) is always KH: "the HEX codes".
UNUSED_AS_KH = frozenset({6, 8})


def format_data_block(words: Sequence[int]) -> list[tuple[str, str, str]]:
    """Per data word: ("DW n", S5 notation, hex as "0034h")."""
    if len(words) != len(WORD_NOTATION) or not all(0 <= w <= 0xFFFF for w in words):
        raise ValueError(f"an INIT-DB is eight words 0..FFFFh, not {tuple(words)!r}")
    rows = []
    for dw, (word, notation) in enumerate(zip(words, WORD_NOTATION), start=1):
        if dw in UNUSED_AS_KH and word == 0:
            notation = "KH"
        rows.append((f"DW {dw}", _NOTATIONS[notation](word), f"{word:04X}h"))
    return rows


def zvz_too_short(zvz: float, line: LineSettings) -> str | None:
    """Why a character delay time of `zvz` seconds cannot end frames on `line`: it is not longer
    than one character, so the driver's time runs out between any two characters, back to back
    as they are, and it ends a frame after every byte (seed 004 §5.2.8: "ZVZ must be greater than
    the time between two characters"; docs/line.md, framing open-driver). None when it is longer."""
    if zvz > line.char_time:
        return None
    guide = ZVZ_GUIDE_MS.get(line.baud)
    said = (f"its guide at {line.baud} baud: {guide[0]}..{guide[1]} ms" if guide else
            "its guide: "
            + ", ".join(f"{baud} baud {low}..{high} ms" for baud, (low, high) in ZVZ_GUIDE_MS.items()))
    form = f"{line.data_bits}{line.parity[0].upper()}{line.stop_bits:g}"
    return (f"zvz {zvz:g} s is not longer than one character at {line.baud} baud, {form} "
            f"({line.bits_per_char:g} bits: "
            f"{line.char_time * 1000:.2f} ms), so the gateway would end a frame after every byte — the "
            "character delay "
            f"time must be greater than the time between two characters (seed 004 §5.2.8; {said}): raise zvz")
