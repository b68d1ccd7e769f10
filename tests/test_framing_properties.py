"""The framings under hypothesis: round trips through random splits and garbage, frames back to
back, decoders that never raise and account for every byte they are fed, and frame lengths
said without encoding (what a plan is priced by) that are the encoded frames' lengths."""

from __future__ import annotations

import binascii

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_codec_properties import MESSAGE_STRATEGIES

from prc3cfg.core import codec
from prc3cfg.core.bustime import DEADLINE_MARGIN, LineCost
from prc3cfg.core.framing import FRAMINGS, NEED_DATA, Decoder, Direction, Discarded, Frame, Framing
from prc3cfg.core.line import LineSettings

COMBOS = [(name, direction) for name in FRAMINGS for direction in Direction]
HUNTING = [(name, direction) for name, direction in COMBOS if name != "open-driver"]
START_CODE = {
    ("crc16", Direction.REQUEST): 0xA5, ("crc16", Direction.REPLY): 0x05,
    ("stx", Direction.REQUEST): 0x7E, ("stx", Direction.REPLY): 0x7E,
}
STX_TYPE = {Direction.REQUEST: 0x20, Direction.REPLY: 0x40}
ZVZ = 0.050  # longer than one character on every line drawn (300 baud, 8E2: 40 ms), as it must be
EXAMPLES = settings(max_examples=250, deadline=None)

lines = st.builds(
    LineSettings,
    baud=st.sampled_from([300, 1200, 9600, 19200, 57600, 115200]),
    data_bits=st.sampled_from([7, 8]),
    parity=st.sampled_from(["none", "odd", "even"]),
    stop_bits=st.sampled_from([1, 2]),
)


@st.composite
def frame_contents(draw, framing: Framing) -> tuple[int, bytes]:
    address = draw(st.sampled_from(framing.addresses))
    length = draw(st.integers(framing.lengths.start, min(framing.lengths.stop - 1, 300)))
    return address, draw(st.binary(min_size=length, max_size=length))


def split(draw, raw: bytes) -> list[bytes]:
    cuts = sorted(draw(st.lists(st.integers(0, len(raw)), max_size=8)))
    return [raw[a:b] for a, b in zip([0, *cuts], [*cuts, len(raw)])]


def feed_back_to_back(decoder: Decoder, chunks: list[bytes], line: LineSettings, start: float = 0.0) -> float:
    """Feed chunks as a steady stream: each arrives when its last byte is through. The end time."""
    now = start
    for chunk in chunks:
        now += len(chunk) * line.char_time
        decoder.receive_data(chunk, now)
    return now


def drain(decoder: Decoder, now: float | None = None) -> list[Frame | Discarded]:
    events = []
    while (event := decoder.next_event(now)) is not NEED_DATA:
        events.append(event)
    return events


def wire(name: str, event: Frame | Discarded) -> bytes:
    """The bytes an event stands for, built here independently of the package's encoders."""
    if isinstance(event, Discarded):
        return event.data
    address, message = event.address, event.message
    if name == "open-driver":
        return bytes([address]) + message
    if name == "crc16":
        covered = bytes([START_CODE[name, event.direction], address, len(message) - 1]) + message
        return covered + binascii.crc_hqx(covered, 0xFFFF).to_bytes(2, "big")
    body = bytes([STX_TYPE[event.direction] | address, len(message)]) + message
    return b"\x7e" + (body + bytes([sum(body) % 256])).replace(b"\x7e", b"\x7e\x00")


@EXAMPLES
@given(combo=st.sampled_from(COMBOS), line=lines, data=st.data())
def test_round_trip_in_random_pieces_after_garbage(combo, line, data):
    name, direction = combo
    framing = FRAMINGS[name]
    address, message = data.draw(frame_contents(framing))
    garbage = b""
    if name != "open-driver":
        garbage = bytes(data.draw(st.lists(st.integers(0, 255).filter(lambda b: b != START_CODE[combo]),
                                           max_size=20)))
    decoder = framing.decoder(direction, line, zvz=ZVZ)
    feed_back_to_back(decoder, split(data.draw, garbage + framing.encode(direction, address, message)), line)
    decoder.line_idle()
    skipped = [Discarded(f"no {START_CODE[combo]:02X}h start code", garbage)] if garbage else []
    assert drain(decoder) == [*skipped, Frame(direction, address, message)]


def frames_in_a_row(draw, framing: Framing, direction: Direction) -> tuple[list[Frame], bytes]:
    """One to four frames, and their bytes back to back."""
    contents = draw(st.lists(frame_contents(framing), min_size=1, max_size=4))
    frames = [Frame(direction, address, message) for address, message in contents]
    return frames, b"".join(framing.encode(direction, address, message) for address, message in contents)


@EXAMPLES
@given(combo=st.sampled_from(HUNTING), line=lines, data=st.data())
def test_frames_back_to_back(combo, line, data):
    name, direction = combo
    frames, stream = frames_in_a_row(data.draw, FRAMINGS[name], direction)
    decoder = FRAMINGS[name].decoder(direction, line)
    end = feed_back_to_back(decoder, split(data.draw, stream), line)
    assert drain(decoder, end) == frames


@EXAMPLES
@given(combo=st.sampled_from(HUNTING), line=lines, data=st.data())
def test_over_tcp_frames_survive_any_split_and_any_pauses(combo, line, data):
    """Over TCP (uart=False) a frame with a length is taken whole however it is split and delayed."""
    name, direction = combo
    frames, stream = frames_in_a_row(data.draw, FRAMINGS[name], direction)
    decoder = FRAMINGS[name].decoder(direction, line, uart=False)
    events, now = [], 0.0
    for chunk in split(data.draw, stream):
        now += data.draw(st.floats(0, 100, allow_nan=False))
        decoder.receive_data(chunk, now)
        events += drain(decoder, now)
    events += drain(decoder, now + 100)
    assert events == frames


@EXAMPLES
@given(direction=st.sampled_from(Direction), line=lines, by_idle=st.booleans(), data=st.data())
def test_open_driver_frames_separated_by_zvz(direction, line, by_idle, data):
    framing = FRAMINGS["open-driver"]
    contents = data.draw(st.lists(frame_contents(framing), min_size=1, max_size=4))
    decoder = framing.decoder(direction, line, zvz=ZVZ)
    now = 0.0
    for address, message in contents:
        now += ZVZ + data.draw(st.floats(1e-6, 0.1))
        now = feed_back_to_back(decoder, split(data.draw, framing.encode(direction, address, message)), line,
                                now)
    frames = [Frame(direction, address, message) for address, message in contents]
    assert drain(decoder, now) == frames[:-1]  # the last frame waits for its silence
    if by_idle:
        decoder.line_idle()
    assert drain(decoder, None if by_idle else now + ZVZ + 1e-9) == frames[-1:]  # float margin


@st.composite
def line_activity(draw, name: str, direction: Direction) -> list[tuple]:
    """Arbitrary bytes, pieces of valid frames, pauses and idle reports, at non-decreasing times."""
    framing = FRAMINGS[name]
    frame_piece = (
        frame_contents(framing)
        .map(lambda c: framing.encode(direction, *c))
        .flatmap(
            lambda raw: st.tuples(st.integers(0, len(raw)), st.integers(0, len(raw))).map(
                lambda ab: raw[min(ab) : max(ab)]
            )
        )
    )
    special = st.lists(st.sampled_from([0x7E, 0x00, 0xA5, 0x05, 0x21, 0x41, 0x01, 0x02]),
                       max_size=12).map(bytes)
    pause = st.floats(0, 0.2, allow_nan=False)
    action = st.one_of(
        st.tuples(st.just("data"), st.one_of(st.binary(max_size=40), frame_piece, special), pause),
        st.tuples(st.just("tick"), pause),
        st.just(("idle",)),
    )
    return draw(st.lists(action, max_size=25))


@EXAMPLES
@given(combo=st.sampled_from(COMBOS), line=lines, data=st.data())
def test_decoders_never_raise_and_account_for_every_byte(combo, line, data):
    name, direction = combo
    decoder = FRAMINGS[name].decoder(direction, line, zvz=ZVZ)
    fed, events, now = b"", [], 0.0
    for kind, *args in data.draw(line_activity(name, direction)):
        if kind == "idle":
            decoder.line_idle()
            events += drain(decoder)
            continue
        now += args[-1]
        if kind == "data":
            decoder.receive_data(args[0], now)
            fed += args[0]
        events += drain(decoder, now)
    decoder.line_idle()
    events += drain(decoder)
    for event in events:
        assert event.reason and event.data if isinstance(event, Discarded) else event.direction is direction
    assert b"".join(wire(name, e) for e in events) == fed


def assert_frame_length(framing: Framing, direction: Direction, address: int, message: bytes) -> None:
    frame = framing.encode(direction, address, message)
    assert framing.frame_length(len(message)) + framing.stuffing(direction, address, message) == len(frame)
    assert framing.stuffs or framing.stuffing(direction, address, message) == 0


@EXAMPLES
@given(combo=st.sampled_from(COMBOS), data=st.data())
def test_frame_length_is_the_length_of_the_encoded_frame(combo, data):
    name, direction = combo
    address, message = data.draw(frame_contents(FRAMINGS[name]))
    assert_frame_length(FRAMINGS[name], direction, address, message)


@pytest.mark.parametrize(("address", "message"),
                         [(1, bytes([0x7E - 0x21 - 1])), (0, bytes(0x7E)), (2, bytes([0x7E] * 3))],
                         ids=["checksum 7Eh", "N = 7Eh", "data 7Eh"])  # 21h + 01h + 5Ch = 7Eh
def test_stx_frame_length_counts_every_stuffed_byte(address, message):
    assert_frame_length(FRAMINGS["stx"], Direction.REQUEST, address, message)


def encoded_time(cost: LineCost, address: int, message: codec.Message) -> float:
    """What an exchange costs by its encoded frames (docs/line.md "Bus time"), as bustime priced it before."""
    request = cost.framing.encode(Direction.REQUEST, address, message.encode())
    reply = cost.framing.encode(Direction.REPLY, address, bytes(codec.reply_length(message)))
    gaps = 2 * cost.zvz if cost.framing.name == "open-driver" else 0.0
    return (len(request) + len(reply)) * cost.line.char_time + cost.turnaround + gaps


def encoded_deadline(cost: LineCost, address: int, message: codec.Message) -> float:
    """How long a reply is waited for, by the encoded request frame and the longest reply frame: on stx a
    reply of 7Eh bytes, every byte after the start code stuffed (`bustime.DEADLINE_MARGIN` on the characters).
    """
    request = cost.framing.encode(Direction.REQUEST, address, message.encode())
    reply = len(cost.framing.encode(Direction.REPLY, address, bytes(codec.reply_length(message))))
    # 7Eh, CMD|ADDR, N, the data, CHK: each byte after the 7Eh may be a 7Eh, stuffed
    if cost.framing.name == "stx":
        reply = 2 * (1 + 2 + codec.reply_length(message) + 1) - 1
    gaps = 2 * cost.zvz if cost.framing.name == "open-driver" else 0.0
    return (len(request) + reply) * cost.line.char_time * (1 + DEADLINE_MARGIN) + cost.turnaround + gaps


@pytest.mark.parametrize("kind", list(MESSAGE_STRATEGIES), ids=lambda kind: kind.__name__)
@settings(max_examples=40, deadline=None)
@given(framing=st.sampled_from(list(FRAMINGS)), line=lines, address=st.integers(0, 30), data=st.data())
def test_a_message_is_priced_by_the_length_of_its_frames(kind, framing, line, address, data):
    message = data.draw(MESSAGE_STRATEGIES[kind])
    cost = LineCost.of(framing, line, 0.010, 0.020)
    assert message.size() == len(message.encode())
    assert cost.message_time(address, message) == encoded_time(cost, address, message)
    request = len(cost.framing.encode(Direction.REQUEST, 0, message.encode()))
    gap = cost.zvz if framing == "open-driver" else 0.0
    assert cost.broadcast_time(message) == request * line.char_time + cost.turnaround + gap
    assert cost.reply_deadline(1, message) == pytest.approx(encoded_deadline(cost, 1, message), rel=1e-12)
    # the whole wait, the bus's timeout on top
    assert cost.silence_time(message, 0.1) == cost.reply_deadline(1, message) + 0.1
