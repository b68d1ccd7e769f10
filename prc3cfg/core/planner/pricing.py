"""The planner's price list: what each kind of message costs on one module's line, as a formula.

The search compares thousands of partial plans, so it prices a message as
`exchange + byte × message bytes`: a fixed cost per exchange (turnaround, frame overhead,
reply frame, open-driver gaps) and a cost per message byte. Both are measured from the
line's own `LineCost` by pricing two probe messages, so every framing and line setting is
priced by `prc3cfg.core.bustime`, never by a copy of its rules. The formula is exact up to stx
stuffing; the final plans are priced exactly with `LineCost.message_time`.

Message sizes are measured on `prc3cfg.core.codec` messages or read from its table of messages of a
header and items (`codec.ITEMS_KINDS`), not written down again here.
Owns: the formula and the sizes. Does not own the cost of an exchange (`prc3cfg.core.bustime`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.image import PROGRAM_COUNT, Program


def _size(message: codec.Message) -> int:
    return message.size()


#: Bytes of the messages the planner sends whole, measured on the codec.
INIT_SIZE = _size(codec.InitProgram(1))  # 11h, 12h and 13h alike
INIT_RANGE_SIZE = _size(codec.InitPrograms(1, 2))  # 14h
LINK_SIZE = _size(codec.LinkPrograms(1, 2))  # 30h and 31h alike
PROGRAM_SIZE = _size(codec.WriteProgram(1, Program(0, 1)))  # 21h
PART_SIZE = _size(codec.WritePartProgram(1, 0, 1))  # 32h
#: The messages of a header and items, as the codec's table gives them (`codec.ITEMS_KINDS`).
PARTS = codec.ITEMS_KINDS[codec.WritePartPrograms.ID]  # 33h
FIELDS = codec.FIELD_KINDS["P"]  # 40h..45h: the DPs price every one of them as this row
ADDRESSES = codec.FIELD_KINDS["A"]  # 46h
if len({(k.header_bytes, k.item_bytes, k.capacity) for name, k in codec.FIELD_KINDS.items()
         if name != "A"}) != 1:
    raise RuntimeError("codec.FIELD_KINDS: the planner prices 40h..45h alike (`FIELDS`); give each field "
                       "its own price first")


@dataclass(frozen=True, slots=True)
class Prices:
    """Seconds per exchange and per message byte on one module's line, and the planner's unit prices.

    The unit prices are worked out once, when the prices are made: the search asks for them
    hundreds of thousands of times.
    """

    exchange: float
    byte: float
    init: float = field(init=False)  # 11h, 12h, 13h
    init_range: float = field(init=False)  # 14h
    link: float = field(init=False)  # 30h, 31h
    program: float = field(init=False)  # 21h
    field_item: float = field(init=False)  # one more item in a 40h..45h
    address_item: float = field(init=False)  # one more item in a 46h
    field_header: float = field(init=False)  # a 40h..45h without its items
    address_header: float = field(init=False)  # a 46h without its items
    parts_header: float = field(init=False)  # a 33h of n programs costs parts_header + n × parts_item
    parts_item: float = field(init=False)
    _parts: tuple[float, ...] = field(init=False, repr=False)
    _fields: tuple[float, ...] = field(init=False, repr=False)
    _addresses: tuple[float, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        def put(name: str, value: object) -> None:
            object.__setattr__(self, name, value)

        put("init", self.message(INIT_SIZE))
        put("init_range", self.message(INIT_RANGE_SIZE))
        put("link", self.message(LINK_SIZE))
        put("program", self.message(PROGRAM_SIZE))
        put("field_item", self.byte * FIELDS.item_bytes)
        put("address_item", self.byte * ADDRESSES.item_bytes)
        put("field_header", self.message(FIELDS.header_bytes))
        put("parts_header", self.message(PARTS.header_bytes))
        put("parts_item", self.byte * PARTS.item_bytes)
        runs = (self.parts_header + n * self.parts_item for n in range(2, PARTS.capacity + 1))
        put("_parts", (0.0, self.message(PART_SIZE), *runs))
        counts = range(PROGRAM_COUNT + 1)
        put("_fields", tuple(FIELDS.messages(n) * self.field_header + n * self.field_item for n in counts))
        put("address_header", self.message(ADDRESSES.header_bytes))
        put("_addresses",
            tuple(ADDRESSES.messages(n) * self.address_header + n * self.address_item for n in counts))

    @classmethod
    def measure(cls, cost: LineCost, address: int) -> Prices:
        """Fit `exchange + byte × n` to two probes priced by the line itself."""
        small = codec.InitProgram(1)
        large = codec.WriteProgram(1, Program(1, 1))
        t_small = cost.message_time(address, small)
        t_large = cost.message_time(address, large)
        byte = (t_large - t_small) / (_size(large) - _size(small))
        return cls(exchange=t_small - byte * _size(small), byte=byte)

    def message(self, size: int) -> float:
        return self.exchange + self.byte * size

    def header(self, kind: codec.ItemsKind) -> float:
        """A message of `kind` (33h, 40h..46h) without its items."""
        return (self.parts_header if kind is PARTS else self.address_header if kind is ADDRESSES
                else self.field_header)

    def item(self, kind: codec.ItemsKind) -> float:
        """One more item in a message of `kind`."""
        return (self.parts_item if kind is PARTS else self.address_item if kind is ADDRESSES
                else self.field_item)

    def parts(self, n: int) -> float:
        """P and V of n consecutive programs: a 32h for one, a 33h for more."""
        return self._parts[n]

    def fields(self, n: int) -> float:
        """n items of one field (40h..45h), in as few messages as their limit allows."""
        return self._fields[n]

    def addresses(self, n: int) -> float:
        """n jump addresses (46h), in as few messages as their limit allows."""
        return self._addresses[n]
