"""The table of messages made of a header and items (`codec.ITEMS_KINDS`), row by row against the
messages the codec builds: every price, bound and search of the planner derives from it, so a row that
said otherwise than the bytes would price every plan wrong."""

from __future__ import annotations

import pytest

from prc3cfg.core import codec, framing
from prc3cfg.core.framing import Direction

#: The rows as docs/protocol.md draws the messages (codec's docstring): ID, header bytes, item bytes,
#: items per message, fields, broadcast by the broadcast search.
ROWS = [
    (0x33, 4, 4, 15, ("P", "V"), False),
    (0x40, 2, 4, 15, ("P",), True),
    (0x41, 2, 4, 15, ("V",), True),
    (0x42, 2, 4, 15, ("Vr",), True),
    (0x43, 2, 4, 15, ("T",), True),
    (0x44, 2, 4, 15, ("F1",), True),
    (0x45, 2, 4, 15, ("F2",), True),
    (0x46, 2, 2, 31, ("A",), True),
]


def built(kind: codec.ItemsKind, n: int) -> codec.Message:
    """A message of `kind` with n items (33h: programs 1..n)."""
    if kind.message is codec.WritePartPrograms:
        return codec.WritePartPrograms(1, ((0, 1),) * n)
    return kind.message(tuple((pn, 1) for pn in range(1, n + 1)))  # type: ignore[call-arg]


def test_the_table_has_the_rows_the_protocol_draws() -> None:
    table = [(k.message.ID, k.header_bytes, k.item_bytes, k.capacity, k.fields, k.broadcast)
             for k in codec.ITEMS_KINDS.values()]
    assert table == ROWS


@pytest.mark.parametrize("kind", codec.ITEMS_KINDS.values(), ids=lambda kind: f"{kind.message.ID:02X}h")
def test_a_row_gives_the_bytes_of_every_message_of_its_kind(kind: codec.ItemsKind) -> None:
    """n items take header + n × item bytes, in one message up to `capacity` and in `messages(n)` of
    them beyond; one item more than `capacity` cannot be built; an item writes the row's fields."""
    framings = [framing.get_framing(name) for name in ("crc16", "open-driver", "stx")]
    for n in range(1, kind.capacity + 1):
        message = built(kind, n)
        assert message.size() == len(message.encode()) == kind.header_bytes + n * kind.item_bytes
        for way in framings:  # the frame bus time is priced by (`bustime`), stuffing aside
            frame = way.encode(Direction.REQUEST, 1, message.encode())
            assert (way.frame_length(message.size())
                    + way.stuffing(Direction.REQUEST, 1, message.encode()) == len(frame))
        assert {name for name, _ in message.checked_values()} == set(kind.fields)
        assert kind.messages(n) == 1 and kind.in_last(n) == n
    with pytest.raises(codec.MessageError):
        built(kind, kind.capacity + 1)
    assert kind.messages(0) == 0
    sizes = (kind.capacity + 1, 2 * kind.capacity, 2 * kind.capacity + 1)
    assert [kind.messages(n) for n in sizes] == [2, 2, 3]
    assert [kind.in_last(n) for n in sizes] == [1, kind.capacity, 1]


def test_every_field_of_a_program_has_one_kind_of_its_own() -> None:
    assert {field: kind.message.ID for field, kind in codec.FIELD_KINDS.items()} == {
        "P": 0x40, "V": 0x41, "Vr": 0x42, "T": 0x43, "F1": 0x44, "F2": 0x45, "A": 0x46,
    }
