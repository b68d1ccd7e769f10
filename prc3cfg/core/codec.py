"""PRC 3 messages (10h..52h) and replies as immutable values that encode to and decode from bytes.

A message is a sequence of 16-bit data words sent high byte first (docs/protocol.md "Values", "Messages"):

    10h  [10 00]                                    init system parameters (releases the axes)
    11h  [11 00]          12h [12 PN]   13h [13 PN]  init programs: all / one / PN..64
    14h  [14 00] [PN1 PN2]                          init programs PN1..PN2
    20h  [20 00] S1 S2 S3 S4 S5 S6 S7 [S8 00] S10 S11 S12   write system parameters (releases the axes)
    21h  [21 PN] P V Vr T F1 F2 [A 00]               write one program
    30h  [30 00] [PN1 PN2]   31h [31 00] [PN1 PN2]   link / unlink
    32h  [32 PN] P V                                 part program
    33h  [33 00] [PN1 PN2] (P V) × n                  consecutive part programs, n ≤ 15
    40h..45h [4x NUM] ([PN 00] value) × NUM           one field of arbitrary programs, NUM ≤ 15
    46h  [46 NUM] [PN A] × NUM                       jump addresses, NUM ≤ 31
    50h  [50 00]   51h [51 PN]   52h [52 00] [PN1 PN2] (≤ 4 programs)   reads

Owns: the layouts, the limits a message must keep when it is *built* (64 bytes, 15/15/31/4
items, header program numbers, 16-bit values: building a bad one raises `MessageError`,
a bug in our code), and the structural checks 1–5 of §4.5 when a message is *decoded*
(`decode_message` raises `Rejected` with the module's error code). Does not own what a
module does with a message (`prc3cfg.core.device`) nor the frame around it (`prc3cfg.core.framing`).
Item program numbers (40h..46h) and values are not range-checked here: the module checks
them (§4.5 steps 7 and 9), after the operating state. Pure: no I/O.

It is long because it holds every layout drawn above, once: two dozen message classes built on a
few shared shapes (`_Bare`, `_OneProgram`, `_ProgramRange`, `_WriteItems`) and word checks, the
table that decodes each by its ID (`MESSAGE_TYPES`), the table of those made of a header and items
(`ITEMS_KINDS`), and the replies that answer them. Split by
family, the shapes and the table would be imported across the parts, and a message's bytes would no
longer be read beside their drawing. The `# --` rulers mark words, messages and replies.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from typing import ClassVar

from prc3cfg.core.image import PROGRAM_COUNT, PROGRAM_FIELDS, SYSTEM_KEYS, Program, SystemParameters

MAX_MESSAGE_BYTES = 64
MAX_FIELD_ITEMS = 15  # 33h pairs and 40h..45h items
MAX_ADDRESS_ITEMS = 31  # 46h
MAX_READ_PROGRAMS = 4  # 52h


class MessageError(ValueError):
    """Our code tried to build a message the protocol cannot carry."""


class Rejected(Exception):
    """A module's answer to bytes it rejects: the error code of the first failing check."""

    def __init__(self, code: int, reason: str = "") -> None:
        super().__init__(f"{code}: {reason}" if reason else str(code))
        self.code = code


# -- words -------------------------------------------------------------------------------


def _check_kf(name: str, value: int) -> None:
    if not -0x8000 <= value <= 0x7FFF:
        raise MessageError(f"{name} = {value} does not fit a 16-bit data word")


def _check_byte(name: str, value: int) -> None:
    if not 0 <= value <= 0xFF:
        raise MessageError(f"{name} = {value} does not fit a byte")


def _check_pn(name: str, value: int) -> None:
    if not 1 <= value <= PROGRAM_COUNT:
        raise MessageError(f"{name} = {value} is not a program number 1..{PROGRAM_COUNT}")


def _check_range(first: int, last: int) -> None:
    _check_pn("PN1", first)
    _check_pn("PN2", last)
    if first > last:
        raise MessageError(f"PN1 = {first} is greater than PN2 = {last}")


def _pack(words: list[int]) -> bytes:
    """Words as big-endian 16-bit, negative values in two's complement."""
    return struct.pack(f">{len(words)}H", *[w & 0xFFFF for w in words])


def _kf(data: bytes, word: int) -> int:
    """The signed value of data word `word` (0-based)."""
    return int.from_bytes(data[2 * word : 2 * word + 2], "big", signed=True)


def _hi(data: bytes, word: int) -> int:
    return data[2 * word]


def _lo(data: bytes, word: int) -> int:
    return data[2 * word + 1]


# -- messages ----------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Message:
    """Base of every master → module message."""

    ID: ClassVar[int]
    RELEASES_AXES: ClassVar[bool] = False
    IS_READ: ClassVar[bool] = False
    HEADER_WORDS: ClassVar[int] = 1

    def words(self) -> list[int]:
        raise NotImplementedError

    def encode(self) -> bytes:
        return _pack(self.words())

    def size(self) -> int:
        """Bytes of the message, without encoding it (what its bus time is priced by)."""
        return 2 * len(self.words())

    def hex(self) -> str:
        return self.encode().hex()

    def checked_values(self) -> Iterator[tuple[str, int]]:
        """(kind, value) pairs in message order, for the module's value checks (§4.5 step 9)."""
        return iter(())

    def item_program_numbers(self) -> tuple[int, ...]:
        """Program numbers carried in items (40h..46h), checked after the operating state."""
        return ()

    def touched_programs(self) -> range | tuple[int, ...]:
        """The programs a write changes (for the active-program check, §4.5 step 8)."""
        return ()

    @classmethod
    def expected_words(cls, data: bytes) -> int:
        """The message's length in words as its header gives it."""
        raise NotImplementedError

    @classmethod
    def check_header(cls, data: bytes) -> None:
        """§4.5 step 4 on the header words; raise Rejected(15)."""

    @classmethod
    def from_bytes(cls, data: bytes) -> Message:
        raise NotImplementedError

    def __post_init__(self) -> None:
        size = 2 * len(self.words())
        if size > MAX_MESSAGE_BYTES:
            raise MessageError(f"{type(self).__name__} of {size} bytes exceeds {MAX_MESSAGE_BYTES}")


@dataclass(frozen=True, slots=True)
class _Bare(Message):
    """A message that is its ID word alone: [ID 00]."""

    @classmethod
    def expected_words(cls, data: bytes) -> int:
        return 1

    def words(self) -> list[int]:
        return [self.ID << 8]

    @classmethod
    def from_bytes(cls, data: bytes) -> Message:
        return cls()


@dataclass(frozen=True, slots=True)
class _OneProgram(Message):
    """A message whose header is [ID PN]."""

    pn: int

    def __post_init__(self) -> None:
        _check_pn("PN", self.pn)
        Message.__post_init__(self)

    @classmethod
    def check_header(cls, data: bytes) -> None:
        if not 1 <= _lo(data, 0) <= PROGRAM_COUNT:
            raise Rejected(15, f"program number {_lo(data, 0)}")

    @classmethod
    def expected_words(cls, data: bytes) -> int:
        return 1

    def words(self) -> list[int]:
        return [self.ID << 8 | self.pn]

    @classmethod
    def from_bytes(cls, data: bytes) -> Message:
        return cls(_lo(data, 0))


@dataclass(frozen=True, slots=True)
class _ProgramRange(Message):
    """A message whose header is [ID 00] [PN1 PN2]."""

    first: int
    last: int
    HEADER_WORDS: ClassVar[int] = 2

    def __post_init__(self) -> None:
        _check_range(self.first, self.last)
        Message.__post_init__(self)

    @classmethod
    def check_header(cls, data: bytes) -> None:
        first, last = _hi(data, 1), _lo(data, 1)
        if not (1 <= first <= PROGRAM_COUNT and 1 <= last <= PROGRAM_COUNT) or first > last:
            raise Rejected(15, f"program range {first}..{last}")

    @classmethod
    def expected_words(cls, data: bytes) -> int:
        return 2

    def range_words(self) -> list[int]:
        return [self.ID << 8, self.first << 8 | self.last]

    def words(self) -> list[int]:
        return self.range_words()

    @property
    def programs(self) -> range:
        return range(self.first, self.last + 1)

    def touched_programs(self) -> range | tuple[int, ...]:
        return self.programs

    @classmethod
    def from_bytes(cls, data: bytes) -> Message:
        return cls(_hi(data, 1), _lo(data, 1))


@dataclass(frozen=True, slots=True)
class InitSystem(_Bare):
    """10h: all system parameters but S9 to their defaults. Releases the axes."""

    ID: ClassVar[int] = 0x10
    RELEASES_AXES: ClassVar[bool] = True


@dataclass(frozen=True, slots=True)
class InitAllPrograms(_Bare):
    """11h: all 64 programs to their defaults."""

    ID: ClassVar[int] = 0x11

    def touched_programs(self) -> range:
        return range(1, PROGRAM_COUNT + 1)


@dataclass(frozen=True, slots=True)
class InitProgram(_OneProgram):
    """12h: program PN to its defaults."""

    ID: ClassVar[int] = 0x12

    def touched_programs(self) -> tuple[int, ...]:
        return (self.pn,)


@dataclass(frozen=True, slots=True)
class InitProgramsFrom(_OneProgram):
    """13h: programs PN..64 to their defaults."""

    ID: ClassVar[int] = 0x13

    def touched_programs(self) -> range:
        return range(self.pn, PROGRAM_COUNT + 1)


@dataclass(frozen=True, slots=True)
class InitPrograms(_ProgramRange):
    """14h: programs PN1..PN2 to their defaults."""

    ID: ClassVar[int] = 0x14


@dataclass(frozen=True, slots=True)
class WriteSystem(Message):
    """20h: all system parameters but S9. Releases the axes."""

    system: SystemParameters
    ID: ClassVar[int] = 0x20
    RELEASES_AXES: ClassVar[bool] = True

    def __post_init__(self) -> None:
        for key in SYSTEM_KEYS:
            (_check_byte if key == "S8" else _check_kf)(key, getattr(self.system, key))
        Message.__post_init__(self)

    @classmethod
    def expected_words(cls, data: bytes) -> int:
        return 12

    def words(self) -> list[int]:
        s = self.system
        return [0x2000, s.S1, s.S2, s.S3, s.S4, s.S5, s.S6, s.S7, s.S8 << 8, s.S10, s.S11, s.S12]

    def checked_values(self) -> Iterator[tuple[str, int]]:
        return zip(SYSTEM_KEYS, self.system.values())

    @classmethod
    def from_bytes(cls, data: bytes) -> Message:
        values = [_kf(data, w) for w in range(1, 12)]
        values[7] = _hi(data, 8)  # [S8 xx]
        return cls(SystemParameters(*values))


def _check_program(program: Program) -> None:
    for name, value in zip(PROGRAM_FIELDS, program.values()):
        (_check_byte if name == "A" else _check_kf)(name, value)


def _program_words(program: Program) -> list[int]:
    return [program.P, program.V, program.Vr, program.T, program.F1, program.F2, program.A << 8]


def _program_from_words(data: bytes, start: int) -> Program:
    """The seven fields P V Vr T F1 F2 [A xx] from data word `start` on."""
    P, V, Vr, T, F1, F2 = (_kf(data, start + i) for i in range(6))
    return Program(P, V, Vr, T, F1, F2, A=_hi(data, start + 6))


@dataclass(frozen=True, slots=True)
class WriteProgram(_OneProgram):
    """21h: one whole program. (reading) 8 words, as the manual's example has, not the table's 6."""

    program: Program
    ID: ClassVar[int] = 0x21

    def __post_init__(self) -> None:
        _check_program(self.program)
        _OneProgram.__post_init__(self)

    @classmethod
    def expected_words(cls, data: bytes) -> int:
        return 8

    def words(self) -> list[int]:
        return [0x2100 | self.pn, *_program_words(self.program)]

    def checked_values(self) -> Iterator[tuple[str, int]]:
        return zip(PROGRAM_FIELDS, self.program.values())

    def touched_programs(self) -> tuple[int, ...]:
        return (self.pn,)

    @classmethod
    def from_bytes(cls, data: bytes) -> Message:
        return cls(_lo(data, 0), _program_from_words(data, 1))


@dataclass(frozen=True, slots=True)
class LinkPrograms(_ProgramRange):
    """30h: A(i) = i + 1 for PN1 ≤ i < PN2, A(PN2) = 0."""

    ID: ClassVar[int] = 0x30


@dataclass(frozen=True, slots=True)
class UnlinkPrograms(_ProgramRange):
    """31h: A(i) = 0 for PN1 ≤ i ≤ PN2."""

    ID: ClassVar[int] = 0x31


@dataclass(frozen=True, slots=True)
class WritePartProgram(_OneProgram):
    """32h: P and V of one program."""

    position: int
    speed: int
    ID: ClassVar[int] = 0x32

    def __post_init__(self) -> None:
        _check_kf("P", self.position)
        _check_kf("V", self.speed)
        _OneProgram.__post_init__(self)

    @classmethod
    def expected_words(cls, data: bytes) -> int:
        return 3

    def words(self) -> list[int]:
        return [0x3200 | self.pn, self.position, self.speed]

    def checked_values(self) -> Iterator[tuple[str, int]]:
        return iter((("P", self.position), ("V", self.speed)))

    def touched_programs(self) -> tuple[int, ...]:
        return (self.pn,)

    @classmethod
    def from_bytes(cls, data: bytes) -> Message:
        return cls(_lo(data, 0), _kf(data, 1), _kf(data, 2))


@dataclass(frozen=True, slots=True)
class WritePartPrograms(Message):
    """33h: P and V of the consecutive programs first..first + n − 1, n ≤ 15."""

    first: int
    items: tuple[tuple[int, int], ...]  # (P, V) per program
    ID: ClassVar[int] = 0x33
    HEADER_WORDS: ClassVar[int] = 2
    ITEM_WORDS: ClassVar[int] = 2  # P V
    MAX_ITEMS: ClassVar[int] = MAX_FIELD_ITEMS

    def __post_init__(self) -> None:
        if not 1 <= len(self.items) <= self.MAX_ITEMS:
            raise MessageError(f"33h carries 1..{self.MAX_ITEMS} programs, not {len(self.items)}")
        _check_range(self.first, self.last)
        for position, speed in self.items:
            _check_kf("P", position)
            _check_kf("V", speed)
        Message.__post_init__(self)

    @property
    def last(self) -> int:
        return self.first + len(self.items) - 1

    check_header = _ProgramRange.check_header

    @classmethod
    def expected_words(cls, data: bytes) -> int:
        return 2 + 2 * (_lo(data, 1) - _hi(data, 1) + 1)

    def words(self) -> list[int]:
        return [0x3300, self.first << 8 | self.last, *(w for pair in self.items for w in pair)]

    def checked_values(self) -> Iterator[tuple[str, int]]:
        for position, speed in self.items:
            yield "P", position
            yield "V", speed

    def touched_programs(self) -> range:
        return range(self.first, self.last + 1)

    @classmethod
    def from_bytes(cls, data: bytes) -> Message:
        n = _lo(data, 1) - _hi(data, 1) + 1
        return cls(_hi(data, 1), tuple((_kf(data, 2 + 2 * i), _kf(data, 3 + 2 * i)) for i in range(n)))


@dataclass(frozen=True, slots=True)
class _WriteItems(Message):
    """[ID NUM] followed by NUM items."""

    items: tuple[tuple[int, int], ...]  # (program number, value)
    MAX_ITEMS: ClassVar[int] = MAX_FIELD_ITEMS
    ITEM_WORDS: ClassVar[int] = 2

    def __post_init__(self) -> None:
        if not 1 <= len(self.items) <= self.MAX_ITEMS:
            raise MessageError(f"{self.ID:02X}h carries 1..{self.MAX_ITEMS} items, not {len(self.items)}")
        for pn, value in self.items:
            _check_byte("PN", pn)
            self.check_value(value)
        Message.__post_init__(self)

    def check_value(self, value: int) -> None:
        """MessageError for a value an item cannot carry."""
        raise NotImplementedError

    @classmethod
    def check_header(cls, data: bytes) -> None:
        if _lo(data, 0) == 0:
            raise Rejected(15, "NUM = 0")

    @classmethod
    def expected_words(cls, data: bytes) -> int:
        return 1 + cls.ITEM_WORDS * _lo(data, 0)

    def item_program_numbers(self) -> tuple[int, ...]:
        return tuple(pn for pn, _ in self.items)

    def touched_programs(self) -> tuple[int, ...]:
        return self.item_program_numbers()


@dataclass(frozen=True, slots=True)
class WriteField(_WriteItems):
    """40h..45h: one field of NUM arbitrary programs, items [PN 00] value."""

    FIELD: ClassVar[str]

    def check_value(self, value: int) -> None:
        _check_kf(self.FIELD, value)

    def words(self) -> list[int]:
        return [self.ID << 8 | len(self.items), *(w for pn, value in self.items for w in (pn << 8, value))]

    def checked_values(self) -> Iterator[tuple[str, int]]:
        return ((self.FIELD, value) for _, value in self.items)

    @classmethod
    def from_bytes(cls, data: bytes) -> Message:
        return cls(tuple((_hi(data, 1 + 2 * i), _kf(data, 2 + 2 * i)) for i in range(_lo(data, 0))))


@dataclass(frozen=True, slots=True)
class WritePositions(WriteField):
    ID: ClassVar[int] = 0x40
    FIELD: ClassVar[str] = "P"


@dataclass(frozen=True, slots=True)
class WriteSpeeds(WriteField):
    ID: ClassVar[int] = 0x41
    FIELD: ClassVar[str] = "V"


@dataclass(frozen=True, slots=True)
class WriteRelativeSpeeds(WriteField):
    ID: ClassVar[int] = 0x42
    FIELD: ClassVar[str] = "Vr"


@dataclass(frozen=True, slots=True)
class WriteDwellTimes(WriteField):
    ID: ClassVar[int] = 0x43
    FIELD: ClassVar[str] = "T"


@dataclass(frozen=True, slots=True)
class WriteF1(WriteField):
    ID: ClassVar[int] = 0x44
    FIELD: ClassVar[str] = "F1"


@dataclass(frozen=True, slots=True)
class WriteF2(WriteField):
    ID: ClassVar[int] = 0x45
    FIELD: ClassVar[str] = "F2"


@dataclass(frozen=True, slots=True)
class WriteAddresses(_WriteItems):
    """46h: jump addresses of NUM arbitrary programs, items [PN A], NUM ≤ 31."""

    ID: ClassVar[int] = 0x46
    MAX_ITEMS: ClassVar[int] = MAX_ADDRESS_ITEMS
    ITEM_WORDS: ClassVar[int] = 1

    def check_value(self, value: int) -> None:
        _check_byte("A", value)

    def words(self) -> list[int]:
        return [0x4600 | len(self.items), *(pn << 8 | a for pn, a in self.items)]

    def checked_values(self) -> Iterator[tuple[str, int]]:
        return (("A", a) for _, a in self.items)

    @classmethod
    def from_bytes(cls, data: bytes) -> Message:
        return cls(tuple((_hi(data, 1 + i), _lo(data, 1 + i)) for i in range(_lo(data, 0))))


@dataclass(frozen=True, slots=True)
class ReadSystem(_Bare):
    """50h: read the system parameters (S9 included)."""

    ID: ClassVar[int] = 0x50
    IS_READ: ClassVar[bool] = True


@dataclass(frozen=True, slots=True)
class ReadProgram(_OneProgram):
    """51h: read one program."""

    ID: ClassVar[int] = 0x51
    IS_READ: ClassVar[bool] = True

    @property
    def programs(self) -> range:
        return range(self.pn, self.pn + 1)


@dataclass(frozen=True, slots=True)
class ReadPrograms(_ProgramRange):
    """52h: read programs PN1..PN2, at most four."""

    ID: ClassVar[int] = 0x52
    IS_READ: ClassVar[bool] = True

    def __post_init__(self) -> None:
        _ProgramRange.__post_init__(self)
        if self.last - self.first + 1 > MAX_READ_PROGRAMS:
            raise MessageError(f"52h reads at most {MAX_READ_PROGRAMS} programs, not "
                               f"{self.first}..{self.last}")

    @classmethod
    def check_header(cls, data: bytes) -> None:
        _ProgramRange.check_header(data)
        if _lo(data, 1) - _hi(data, 1) + 1 > MAX_READ_PROGRAMS:
            raise Rejected(15, f"52h asks for {_lo(data, 1) - _hi(data, 1) + 1} programs")

    def touched_programs(self) -> tuple[int, ...]:
        return ()


MESSAGE_TYPES: dict[int, type[Message]] = {
    cls.ID: cls
    for cls in (
        InitSystem, InitAllPrograms, InitProgram, InitProgramsFrom, InitPrograms,
        WriteSystem, WriteProgram, LinkPrograms, UnlinkPrograms, WritePartProgram, WritePartPrograms,
        WritePositions, WriteSpeeds, WriteRelativeSpeeds, WriteDwellTimes, WriteF1, WriteF2,
        WriteAddresses, ReadSystem, ReadProgram, ReadPrograms,
    )
}

#: The per-field messages 40h..45h by program field name.
FIELD_MESSAGES: dict[str, type[WriteField]] = {
    cls.FIELD: cls for cls in MESSAGE_TYPES.values() if issubclass(cls, WriteField)
}


@dataclass(frozen=True, slots=True)
class ItemsKind:
    """A kind of message made of a header and items, up to `capacity` items a message (33h, 40h..46h):
    n items take header_bytes + n × item_bytes, in `messages(n)` messages. Every price, bound and
    search of the planner that counts items and headers derives from these rows (`ITEMS_KINDS`)."""

    message: type[WritePartPrograms] | type[_WriteItems]
    header_bytes: int
    item_bytes: int
    capacity: int
    fields: tuple[str, ...]  # the program fields an item writes
    # the broadcast search (`prc3cfg.core.broadcast_search`) sends items every module shares in it
    broadcast: bool

    @classmethod
    def of(cls, message: type[WritePartPrograms] | type[_WriteItems], fields: tuple[str, ...],
           broadcast: bool) -> ItemsKind:
        return cls(message, 2 * message.HEADER_WORDS, 2 * message.ITEM_WORDS, message.MAX_ITEMS, fields,
                   broadcast)

    def messages(self, n: int) -> int:
        """How many messages n items need (none for none)."""
        return -(-n // self.capacity) if n > 0 else 0

    def in_last(self, n: int) -> int:
        """The items in the last of the messages n > 0 items need."""
        return n - self.capacity * ((n - 1) // self.capacity)


#: The messages of a header and items, by ID.
ITEMS_KINDS: dict[int, ItemsKind] = {
    kind.message.ID: kind
    for kind in (
        ItemsKind.of(WritePartPrograms, ("P", "V"), broadcast=False),
        *(ItemsKind.of(cls, (cls.FIELD,), broadcast=True) for cls in FIELD_MESSAGES.values()),
        ItemsKind.of(WriteAddresses, ("A",), broadcast=True),
    )
}
#: The message of one field of arbitrary programs (40h..46h), by program field name.
FIELD_KINDS: dict[str, ItemsKind] = {kind.fields[0]: kind for kind in ITEMS_KINDS.values()
                                     if len(kind.fields) == 1}


def decode_message(data: bytes) -> Message:
    """Bytes → message, applying the module's structural checks 1–5 (§4.5) in their order.

    Raises `Rejected` with the module's error code: 11 empty, 12 over 64 bytes, 10 unknown
    ID, 13 odd length or shorter than the header, 15 bad header program numbers / NUM = 0 /
    52h over four programs, 13 / 14 shorter / longer than the header says.
    """
    if not data:
        raise Rejected(11, "empty message")
    if len(data) > MAX_MESSAGE_BYTES:
        raise Rejected(12, f"{len(data)} bytes")
    cls = MESSAGE_TYPES.get(data[0])
    if cls is None:
        raise Rejected(10, f"ID {data[0]:02X}h")
    if len(data) % 2 or len(data) < 2 * cls.HEADER_WORDS:
        raise Rejected(13, f"{len(data)} bytes")
    cls.check_header(data)
    expected = 2 * cls.expected_words(data)
    if len(data) != expected:
        raise Rejected(13 if len(data) < expected else 14, f"{len(data)} bytes, the header says {expected}")
    return cls.from_bytes(data)


# -- replies -----------------------------------------------------------------------------


def encode_code(code: int) -> bytes:
    """The one-word reply [ECN 00]."""
    return bytes((code, 0))


@dataclass(frozen=True, slots=True)
class SystemReply:
    """50h's reply: S1 S2 S3 S4 S5 S6 S7 [S8 S9] S10 S11 S12."""

    system: SystemParameters
    address: int  # S9
    WORDS: ClassVar[int] = 11

    def encode(self) -> bytes:
        s = self.system
        s8_s9 = s.S8 << 8 | self.address
        return _pack([s.S1, s.S2, s.S3, s.S4, s.S5, s.S6, s.S7, s8_s9, s.S10, s.S11, s.S12])

    @classmethod
    def decode(cls, data: bytes) -> SystemReply:
        values = [_kf(data, w) for w in range(11)]
        values[7] = _hi(data, 7)
        return cls(SystemParameters(*values), _lo(data, 7))


@dataclass(frozen=True, slots=True)
class ProgramsReply:
    """51h/52h's reply: per program [PN 00] P V Vr T F1 F2 [A 00]."""

    first: int
    programs: tuple[Program, ...]
    BLOCK_WORDS: ClassVar[int] = 8

    def encode(self) -> bytes:
        return _pack(
            [w for i, p in enumerate(self.programs) for w in ((self.first + i) << 8, *_program_words(p))]
        )

    @classmethod
    def decode(cls, data: bytes) -> ProgramsReply:
        blocks = len(data) // (2 * cls.BLOCK_WORDS)
        return cls(_hi(data, 0), tuple(_program_from_words(data, 8 * b + 1) for b in range(blocks)))

    def block_numbers(self, data: bytes) -> tuple[int, ...]:
        return tuple(_hi(data, 8 * b) for b in range(len(self.programs)))


class BadReply(Exception):
    """A reply whose length fits neither the request's data block nor an error code."""


def reply_length(message: Message) -> int:
    """Bytes of the data block a read is answered with; 2 (the code word) for a write."""
    if isinstance(message, ReadSystem):
        return 2 * SystemReply.WORDS
    if isinstance(message, (ReadProgram, ReadPrograms)):
        return 2 * ProgramsReply.BLOCK_WORDS * len(message.programs)
    return 2


def decode_reply(message: Message, data: bytes) -> int | SystemReply | ProgramsReply:
    """A module's reply to `message`: its error code (0 = accepted) or the data block read.

    Raises `BadReply` when the length is neither; a program block numbered differently from
    what was asked is a bad reply too.
    """
    if len(data) == 2:
        return data[0]
    # the reads (IS_READ)
    if not isinstance(message, ReadSystem | ReadProgram | ReadPrograms) or len(data) != reply_length(message):
        raise BadReply(f"{len(data)} bytes in reply to {message.ID:02X}h, expected {reply_length(message)}")
    if isinstance(message, ReadSystem):
        return SystemReply.decode(data)
    reply = ProgramsReply.decode(data)
    if reply.block_numbers(data) != tuple(message.programs):
        raise BadReply(f"programs {reply.block_numbers(data)} in reply to a read of "
                       f"{tuple(message.programs)}")
    return reply
