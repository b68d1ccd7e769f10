"""The three framings against fixed byte vectors (docs/line.md), and their decoders as tables of cases.

Line: 9600 baud 8E1, one character = 11/9600 s = 1.146 ms; crc16 inter-character time-out
5 characters = 5.729 ms; stx SPD message time-out 32 ms; open-driver ZVZ 20 ms.
"""

from __future__ import annotations

import ast
import binascii
import dataclasses
import subprocess
import sys
from collections import namedtuple
from pathlib import Path

import pytest

import prc3cfg.core.framing
from prc3cfg.core.framing import FRAMINGS, NEED_DATA, Direction, Discarded, Frame, FramingError, get_framing
from prc3cfg.core.framing.stx import message_timeout
from prc3cfg.core.line import LineSettings

REQUEST, REPLY = Direction.REQUEST, Direction.REPLY
LINE = LineSettings()
ZVZ = 0.020

MSG_21H = "210A041A012C0035001403F200320500"  # the manual's 21h example
READ_50H = "5000"
REPLY_50H = "0190003202F20258000A05DC03E800010247044C000A"  # the manual's 50h reply, module 1
MSG_64 = bytes(range(64)).hex().upper()

# (direction, address, message, frame) — frames computed once, pasted as literals
VECTORS = {
    "crc16": [
        (REQUEST, 5, MSG_21H, "A5050F" + MSG_21H + "02AB"),
        (REPLY, 5, MSG_21H, "05050F" + MSG_21H + "F0D8"),
        (REQUEST, 1, READ_50H, "A5010150005704"),
        (REPLY, 1, READ_50H, "05010150007D60"),
        (REPLY, 1, REPLY_50H, "050115" + REPLY_50H + "0F2A"),
        (REQUEST, 0, "1100", "A5000111001F4D"),
        (REPLY, 5, "0000", "0505010000B92E"),
        (REQUEST, 30, MSG_64, "A51E3F" + MSG_64 + "D15A"),
        (REQUEST, 1, "7E", "A501007E7A9A"),
        (REQUEST, 2, "55" * 256, "A502FF" + "55" * 256 + "F3B9"),
    ],
    "open-driver": [
        (REQUEST, 5, MSG_21H, "05" + MSG_21H),
        (REQUEST, 1, READ_50H, "015000"),
        (REPLY, 1, REPLY_50H, "01" + REPLY_50H),
        (REQUEST, 0, "1100", "001100"),
        (REPLY, 31, MSG_64, "1F" + MSG_64),
        (REQUEST, 7, "", "07"),
        (REQUEST, 1, "AA" * 1024, "01" + "AA" * 1024),
    ],
    "stx": [
        (REQUEST, 5, MSG_21H, "7E2510" + MSG_21H + "20"),
        (REPLY, 5, MSG_21H, "7E4510" + MSG_21H + "40"),
        (REQUEST, 1, READ_50H, "7E2102500073"),
        (REPLY, 1, READ_50H, "7E4102500093"),
        (REPLY, 1, REPLY_50H, "7E4116" + REPLY_50H + "E2"),
        (REQUEST, 0, "1100", "7E2002110033"),
        (REQUEST, 31, MSG_64, "7E3F40" + MSG_64 + "5F"),
        (REQUEST, 1, "7E", "7E21017E00A0"),  # a data byte 7E is stuffed
        (REQUEST, 1, "5C", "7E21015C7E00"),  # CHK = 7E is stuffed
        (REQUEST, 1, "00" * 126, "7E217E00" + "00" * 126 + "9F"),  # N = 7E is stuffed
        (REPLY, 31, "7E7E", "7E5F027E007E005D"),
        (REPLY, 3, "01" * 255, "7E43FF" + "01" * 255 + "41"),
    ],
}
ALL_VECTORS = [
    pytest.param(name, *vector, id=f"{name}-{vector[0].value}-{vector[1]}-{len(vector[2]) // 2}B")
    for name, vectors in VECTORS.items()
    for vector in vectors
]


def bitwise_crc_ccitt_false(data: bytes) -> int:
    """CRC-16/CCITT-FALSE the long way: polynomial 1021h, initial FFFFh, MSB first."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = (crc << 1 ^ 0x1021 if crc & 0x8000 else crc << 1) & 0xFFFF
    return crc


def decode(name: str, direction: Direction, chunks: list[bytes]) -> list[Frame | Discarded]:
    """Feed `chunks` at one instant, then report the line idle; every event."""
    decoder = get_framing(name).decoder(direction, LINE, zvz=ZVZ)
    for chunk in chunks:
        decoder.receive_data(chunk, 0.0)
    decoder.line_idle()
    events = []
    while (event := decoder.next_event()) is not NEED_DATA:
        events.append(event)
    return events


# --- encode and decode the vectors ----------------------------------------------------------


@pytest.mark.parametrize("name, direction, address, message, frame", ALL_VECTORS)
def test_encode(name, direction, address, message, frame):
    assert get_framing(name).encode(direction, address, bytes.fromhex(message)).hex().upper() == frame


@pytest.mark.parametrize("name, direction, address, message, frame", ALL_VECTORS)
def test_decode_whole_and_split_everywhere(name, direction, address, message, frame):
    raw = bytes.fromhex(frame)
    expected = [Frame(direction, address, bytes.fromhex(message))]
    assert decode(name, direction, [raw]) == expected
    for cut in range(1, len(raw)):
        assert decode(name, direction, [raw[:cut], raw[cut:]]) == expected, f"split at {cut}"
    assert decode(name, direction, [raw[i : i + 1] for i in range(len(raw))]) == expected


def test_crc_check_value():
    assert binascii.crc_hqx(b"123456789", 0xFFFF) == 0x29B1
    assert bitwise_crc_ccitt_false(b"123456789") == 0x29B1


@pytest.mark.parametrize("direction, address, message, frame", VECTORS["crc16"])
def test_crc16_vectors_by_a_bitwise_crc(direction, address, message, frame):
    raw = bytes.fromhex(frame)
    assert raw[0] == {REQUEST: 0xA5, REPLY: 0x05}[direction]
    assert raw[2] + 1 == len(raw) - 5 == len(message) // 2
    assert int.from_bytes(raw[-2:], "big") == bitwise_crc_ccitt_false(raw[:-2])


@pytest.mark.parametrize("direction, address, message, frame", VECTORS["stx"])
def test_stx_vectors_by_hand(direction, address, message, frame):
    raw = bytes.fromhex(frame)
    stuffed = raw[1:]
    assert raw[0] == 0x7E and all(stuffed[i + 1] == 0 for i, b in enumerate(stuffed) if b == 0x7E)
    body = stuffed.replace(b"\x7e\x00", b"\x7e")
    assert body[0] == {REQUEST: 0x20, REPLY: 0x40}[direction] + address
    assert body[1] == len(body) - 3 == len(message) // 2
    assert sum(body[:-1]) % 256 == body[-1]


# --- decoders, step by step --------------------------------------------------------------------

F = namedtuple("F", "address message")  # a Frame expected (the decoder's direction)
D = namedtuple("D", "data reason")  # a Discarded expected; `reason` is a part of its text
IDLE = "line_idle"


def run(name: str, direction: Direction, steps: list, **settings) -> None:
    """Steps: ((now, hex), events) feeds bytes, ((now, None), events) only lets time pass,
    (IDLE, events) reports the line idle; `events` are those next_event(now) returns then."""
    decoder = get_framing(name).decoder(direction, LINE, **{"zvz": ZVZ, **settings})
    for number, (action, expected) in enumerate(steps):
        now = None
        if action == IDLE:
            decoder.line_idle()
        else:
            now, data = action
            if data is not None:
                decoder.receive_data(bytes.fromhex(data), now)
        events = []
        while (event := decoder.next_event(now)) is not NEED_DATA:
            events.append(event)
        assert len(events) == len(expected), f"step {number}: {events}"
        for event, want in zip(events, expected):
            if isinstance(want, F):
                assert event == Frame(direction, want.address, bytes.fromhex(want.message)), f"step {number}"
            else:
                assert isinstance(event, Discarded), f"step {number}: {event}"
                assert event.data == bytes.fromhex(want.data), f"step {number}: {event}"
                assert want.reason in event.reason, f"step {number}: {event.reason!r}"


def case(id: str, *steps, direction: Direction = REQUEST, **settings):
    return pytest.param(direction, list(steps), settings, id=id)


REQ_50 = "A5010150005704"  # crc16 request, module 1, 50h
REP_50 = "05010150007D60"  # crc16 reply, module 1, 50h

CRC16_CASES = [
    case("garbage-and-wrong-start-code-before",
         ((0, "FF0005" + REQ_50), [D("FF0005", "no A5h start code"), F(1, "5000")])),
    case("garbage-in-pieces-is-one-discard",
         ((0, "FF"), []),
         ((0, "00"), []),
         ((0, REQ_50), [D("FF00", "no A5h"), F(1, "5000")])),
    case("two-frames-in-one-chunk",
         ((0, REQ_50 + "A5000111001F4D"), [F(1, "5000"), F(0, "1100")])),
    case("bad-crc",
         ((0, "A5010150005705" + REQ_50), [D("A5010150005705", "bad CRC 5705h, "
                                                               "expected 5704h"), F(1, "5000")])),
    # reading: hunting resumes after the whole bad frame, so the valid frame inside its data is not seen
    case("bad-crc-skips-whole-frame",
         ((0, "A50005" + "A5010050BF36" + "0000"), [D("A50005A5010050BF360000", "bad CRC 0000h")]),
         (IDLE, [])),
    case("reply-into-request-decoder",
         ((0, REP_50), []),
         (IDLE, [D(REP_50, "no A5h start code")])),
    case("request-into-reply-decoder",
         ((0, REQ_50), []),
         (IDLE, [D(REQ_50, "no 05h start code")]), direction=REPLY),
    # 4 bytes arrive 11 ms after the first 3: 11 - 4 × 1.146 = 6.4 ms of silence > 5.73 ms
    case("gap-too-long",
         ((0, "A50101"), []),
         ((0.011, "50005704"), [D("A50101", "incomplete frame")]),
         (IDLE, [D("50005704", "no A5h")])),
    case("gap-just-within",
         ((0, "A50101"), []),
         ((0.0095, "50005704"), [F(1, "5000")])),
    # reading: a 5-byte burst 9.7 ms after the last one is 4.0 ms of silence, not 9.7 ms
    case("burst-counts-its-own-bytes",
         ((0, "A501"), []),
         ((0.0097, "0150005704"), [F(1, "5000")])),
    case("gap-seen-by-next-event",
         ((0, "A50101"), []),
         ((0.0057, None), []),
         ((0.0058, None), [D("A50101", "5.8 ms of silence")])),
    case("frame-after-gap",
         ((0, "A50101"), []),
         ((0.1, REQ_50), [D("A50101", "incomplete"), F(1, "5000")])),
    case("line-idle-drops-partial",
         ((0, "A50101"), []),
         (IDLE, [D("A50101", "line went idle")])),
    case("own-inter-char-timeout",
         ((0, "A50101"), []),
         ((0.04, "50005704"), [F(1, "5000")]), inter_char_timeout=0.05),
    # over TCP a frame ends by its length: no pause inside it discards it
    case("tcp-a-pause-inside-a-frame",
         ((0, "A50101"), []),
         ((30.0, None), []),
         ((60.0, "50005704"), [F(1, "5000")]), uart=False),
    case("tcp-garbage-still-discarded",
         ((0, "FF00"), []),
         ((5.0, REQ_50), [D("FF00", "no A5h"), F(1, "5000")]), uart=False),
    case("tcp-own-inter-char-timeout-is-not-used",
         ((0, "A50101"), []),
         ((1.0, "50005704"), [F(1, "5000")]), inter_char_timeout=0.001, uart=False),
]

REQ_S = "7E2102500073"  # stx request, module 1, 50h
REP_S = "7E4102500093"  # stx reply, module 1, 50h
STX_64 = "7E3F40" + MSG_64 + "5F"  # 68 bytes: 32 ms + 68 × 1.146 ms = 109.9 ms

STX_CASES = [
    case("garbage-before",
         ((0, "0102" + REQ_S), [D("0102", "no 7Eh start code"), F(1, "5000")])),
    case("two-frames-in-one-chunk",
         ((0, REQ_S + "7E2002110033"), [F(1, "5000"), F(0, "1100")])),
    case("bad-checksum",
         ((0, "7E2102500074" + REQ_S), [D("7E2102500074", "bad checksum 74h, expected 73h"), F(1, "5000")])),
    case("reply-into-request-decoder",
         ((0, REP_S + REQ_S), [D(REP_S, "type 010, expected 001"), F(1, "5000")])),
    case("request-into-reply-decoder",
         ((0, REQ_S + REP_S), [D(REQ_S, "type 001, expected 010"), F(1, "5000")]), direction=REPLY),
    case("type-000",
         ((0, "7E0102500053"), [D("7E0102500053", "type 000")])),
    case("length-0",
         ((0, "7E2100" + REQ_S), [D("7E2100", "bad length N = 0"), F(1, "5000")])),
    case("new-start-inside-frame",
         ((0, "7E210250" + REQ_S), [D("7E210250", "cut short by a 7Eh"), F(1, "5000")])),
    case("lone-7e-before-frame",
         ((0, "7E"), []),
         ((0, REQ_S), [D("7E", "cut short"), F(1, "5000")])),
    case("line-idle-drops-partial-with-pending-7e",
         ((0, "7E21017E"), []),
         (IDLE, [D("7E21017E", "line went idle")])),
    # 6 bytes: 32 ms + 6 × 1.146 ms = 38.875 ms from the 7E
    case("time-out-just-met",
         ((0, "7E"), []),
         ((0.0388, "2102500073"), [F(1, "5000")])),
    case("time-out-exceeded",
         ((0, "7E"), []),
         ((0.0389, "2102500073"), [D("7E", "message time-out")]),
         (IDLE, [D("2102500073", "no 7Eh")])),
    case("time-out-counts-stuffing",
         ((0, "7E"), []),
         ((0.0388, "21017E00A0"), [F(1, "7E")])),
    case("time-out-seen-by-next-event",
         ((0, "7E"), []),
         ((0.001, "2102"), []),
         ((0.0388, None), []),
         ((0.0390, None), [D("7E2102", "message time-out")])),
    # reading: the first frame's last byte arrived 6 characters before the end of the chunk
    case("frame-ends-early-in-a-chunk",
         ((0, "7E"), []),
         ((0.0456, "2102500073" + "7E2002110033"), [F(1, "5000"), F(0, "1100")])),
    case("64-bytes-just-met",
         ((0, "7E"), []),
         ((0.1099, STX_64[2:]), [F(31, MSG_64)])),
    case("64-bytes-too-late",
         ((0, "7E"), []),
         ((0.1100, STX_64[2:]), [D("7E", "time-out")]),
         (IDLE, [D(STX_64[2:], "no 7Eh")])),
    case("64-bytes-in-pieces",
         ((0, "7E"), []),
         ((0.05, STX_64[2:-2]), []),
         ((0.1099, STX_64[-2:]), [F(31, MSG_64)])),
    # over TCP there is no message time-out: a frame ends by its N
    case("tcp-no-message-time-out",
         ((0, "7E"), []),
         ((10.0, None), []),
         ((20.0, "21017E"), []),
         ((30.0, "00A0"), [F(1, "7E")]), uart=False),
    case("tcp-a-bad-checksum-is-still-discarded",
         ((0, "7E2102500074"), [D("7E2102500074", "bad checksum")]), uart=False),
]

OPEN_DRIVER_CASES = [
    case("frames-separated-by-zvz",
         ((0, "015000"), []),
         ((0.1, "025000"), [F(1, "5000")]),
         (IDLE, [F(2, "5000")])),
    case("ended-by-line-idle",
         ((0, "015000"), []),
         (IDLE, [F(1, "5000")]),
         (IDLE, [])),
    case("ended-by-a-later-now",
         ((0, "015000"), []),
         ((0.0199, None), []),
         ((0.0200, None), [F(1, "5000")])),
    case("reply-ended-by-a-later-now",
         ((0, "01" + REPLY_50H), []),
         ((0.0200, None), [F(1, REPLY_50H)]), direction=REPLY),
    case("pieces-within-zvz",
         ((0, "01"), []),
         ((0.015, "5000"), []),
         ((0.1, None), [F(1, "5000")])),
    # reading: 2 bytes 21.5 ms after the last are 19.2 ms of silence, less than ZVZ
    case("burst-counts-its-own-bytes",
         ((0, "01"), []),
         ((0.0215, "5000"), []),
         (IDLE, [F(1, "5000")])),
    case("address-only-frame-then-another",
         ((0, "01"), []),
         ((0.0235, "5000"), [F(1, "")]),
         (IDLE, [F(0x50, "00")])),
    case("any-address-byte",
         ((0, "FF01"), []),
         (IDLE, [F(255, "01")])),
    # no length: over TCP too, ZVZ is the only end of a frame
    case("tcp-ended-by-zvz-all-the-same",
         ((0, "015000"), []),
         ((0.1, "025000"), [F(1, "5000")]),
         ((0.2, None), [F(2, "5000")]), uart=False),
]


@pytest.mark.parametrize("direction, steps, settings", CRC16_CASES)
def test_crc16_decoder(direction, steps, settings):
    run("crc16", direction, steps, **settings)


@pytest.mark.parametrize("direction, steps, settings", STX_CASES)
def test_stx_decoder(direction, steps, settings):
    run("stx", direction, steps, **settings)


@pytest.mark.parametrize("direction, steps, settings", OPEN_DRIVER_CASES)
def test_open_driver_decoder(direction, steps, settings):
    run("open-driver", direction, steps, **settings)


@pytest.mark.parametrize(
    "baud, seconds",
    [(600, 0.512), (1200, 0.256), (2400, 0.128), (4800, 0.064), (9600, 0.032), (19200, 0.016), (38400, 0.012),
     (57600, 0.008), (14400, 0.032), (115200, 0.008), (300, 1.024), (50, 6.144)],
)
def test_stx_message_timeout_table(baud, seconds):
    assert message_timeout(baud) == pytest.approx(seconds)


# --- the API -------------------------------------------------------------------------------------


def test_framings_by_name():
    assert list(FRAMINGS) == ["crc16", "open-driver", "stx"]
    assert all(get_framing(name).name == name for name in FRAMINGS)
    with pytest.raises(ValueError, match="crc16, open-driver, stx"):
        get_framing("modbus")


@pytest.mark.parametrize(
    "name, address, length",
    [("crc16", 31, 1), ("crc16", -1, 1), ("crc16", 1, 0), ("crc16", 1, 257),
     ("open-driver", 32, 0), ("open-driver", 1, 1025),
     ("stx", 32, 1), ("stx", 1, 0), ("stx", 1, 256)],
)
def test_encode_refuses_what_the_framing_cannot_carry(name, address, length):
    with pytest.raises(FramingError, match=name):
        get_framing(name).encode(REQUEST, address, bytes(length))


def test_open_driver_decoder_needs_zvz():
    with pytest.raises(ValueError, match="zvz"):
        get_framing("open-driver").decoder(REQUEST, LINE)


def test_over_tcp_the_length_framings_have_no_time_outs():
    assert get_framing("crc16").decoder(REQUEST, LINE, uart=False).inter_char_timeout == float("inf")
    assert get_framing("stx").decoder(REQUEST, LINE, uart=False).message_timeout == float("inf")


def test_crc16_default_inter_char_timeout_is_five_characters():
    assert get_framing("crc16").decoder(REQUEST, LINE).inter_char_timeout == pytest.approx(5 * 11 / 9600)
    slow = LineSettings(baud=1200, parity="none")
    assert get_framing("crc16").decoder(REQUEST, slow).inter_char_timeout == pytest.approx(5 * 10 / 1200)


def test_events_are_frozen_and_need_data_is_a_sentinel():
    with pytest.raises(dataclasses.FrozenInstanceError):
        Frame(REQUEST, 1, b"").address = 2
    assert repr(NEED_DATA) == "NEED_DATA"
    assert get_framing("stx").decoder(REQUEST, LINE).next_event() is NEED_DATA


ALLOWED_IMPORTS = {"__future__", "abc", "binascii", "collections", "dataclasses", "enum", "typing",
                   "prc3cfg.core.line"}


def test_framing_package_imports_no_io():
    for path in Path(prc3cfg.core.framing.__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module]
            else:
                continue
            assert all(n in ALLOWED_IMPORTS or n.startswith("prc3cfg.core.framing")
                       for n in names), f"{path.name}: {names}"
    blocked = ("import sys; sys.modules.update(serial=None, socket=None, time=None); import "
               "prc3cfg.core.framing")
    subprocess.run([sys.executable, "-c", blocked], check=True)


@pytest.mark.parametrize("name", ["crc16", "stx"])
def test_garbage_outside_frames_is_reported_in_bounded_pieces(name):
    """A line of endless garbage never grows a decoder: runs are discarded in pieces, every byte accounted."""
    decoder = get_framing(name).decoder(REPLY, LINE, zvz=ZVZ)
    garbage = bytes([0x55]) * 10_000  # no start code of either framing
    decoder.receive_data(garbage, 0.0)
    events = []
    while (event := decoder.next_event()) is not NEED_DATA:
        events.append(event)
    decoder.line_idle()
    while (event := decoder.next_event()) is not NEED_DATA:
        events.append(event)
    assert all(isinstance(e, Discarded) and len(e.data) <= prc3cfg.core.framing.base.MAX_SKIPPED
               for e in events)
    assert b"".join(e.data for e in events) == garbage


@pytest.mark.parametrize("name", ["crc16", "stx"])
def test_garbage_in_chunks_is_reported_in_whole_pieces_and_the_rest_at_the_next_start_code(name):
    framing = get_framing(name)
    decoder = framing.decoder(REQUEST, LINE)
    garbage = bytes([0x55]) * 1000
    for start in range(0, len(garbage), 100):
        decoder.receive_data(garbage[start : start + 100], 0.0)
    decoder.receive_data(framing.encode(REQUEST, 1, b"\x50\x00"), 0.0)
    events = []
    while (event := decoder.next_event()) is not NEED_DATA:
        events.append(event)
    assert [len(e.data) for e in events[:-1]] == [256, 256, 256, 232]
    assert b"".join(e.data for e in events[:-1]) == garbage
    assert events[-1] == Frame(REQUEST, 1, b"\x50\x00")


def test_an_open_driver_frame_that_never_ends_is_discarded_in_pieces():
    decoder = get_framing("open-driver").decoder(REPLY, LINE, zvz=ZVZ)
    endless = bytes(range(256)) * 20  # 5120 bytes without a gap: longer than any frame the driver takes
    decoder.receive_data(endless, 0.0)
    decoder.line_idle()
    events = []
    while (event := decoder.next_event()) is not NEED_DATA:
        events.append(event)
    assert all(isinstance(e, Discarded) and "longer than 1025 bytes" in e.reason for e in events)
    assert max(len(e.data) for e in events) == 1025
    assert b"".join(e.data for e in events) == endless


def test_only_open_driver_lacks_a_checksum():
    assert {name: f.checked for name, f in FRAMINGS.items()} == {"crc16": True, "open-driver": False,
                                                                 "stx": True}


def test_an_open_driver_zvz_not_longer_than_a_character_ends_a_frame_after_every_byte():
    """As a CP 524 does (seed 004 §5.2.8): the character delay time runs out before the next byte is in."""
    slow = LineSettings(baud=1200)  # 8E1: 9.17 ms a character
    events = []
    for zvz in (0.004, 0.030):
        decoder = get_framing("open-driver").decoder(REQUEST, slow, zvz=zvz)
        decoder.receive_data(b"\x01\x02\x03", 0.0)
        decoder.line_idle()
        events.append(list(iter(decoder.next_event, NEED_DATA)))
    assert events == [[Frame(REQUEST, 1, b""), Frame(REQUEST, 2, b""), Frame(REQUEST, 3, b"")],
                      [Frame(REQUEST, 1, b"\x02\x03")]]


def test_the_framing_names_a_plant_file_takes_are_the_framings() -> None:
    from typing import get_args

    from prc3cfg.core.framing import FramingName

    assert get_args(FramingName) == tuple(FRAMINGS)
