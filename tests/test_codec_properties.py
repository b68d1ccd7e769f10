"""Properties of the codec: every message and reply round-trips, and `decode_message` on any
bytes either gives back a message that re-encodes to those bytes (don't-care bytes zeroed) or
rejects them with the code an independent reading of §4.5 checks 1–5 predicts."""

from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from prc3cfg.core import codec
from prc3cfg.core.image import Program, SystemParameters

PROPERTY = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])

kf = st.integers(-0x8000, 0x7FFF)
byte = st.integers(0, 0xFF)
pn = st.integers(1, 64)


@st.composite
def program_range(draw, most: int = 64):
    first = draw(pn)
    last = draw(st.integers(first, min(64, first + most - 1)))
    return first, last


systems = st.builds(
    SystemParameters, S1=kf, S2=kf, S3=kf, S4=kf, S5=kf, S6=kf, S7=kf, S8=byte, S10=kf, S11=kf, S12=kf
)
programs = st.builds(Program, P=kf, V=kf, Vr=kf, T=kf, F1=kf, F2=kf, A=byte)


@st.composite
def part_programs(draw):
    first = draw(pn)
    items = draw(st.lists(st.tuples(kf, kf), min_size=1, max_size=min(15, 65 - first)))
    return codec.WritePartPrograms(first, tuple(items))


def ranged(cls, most: int = 64):
    return program_range(most).map(lambda r: cls(*r))


def items(cls, value, most):
    return st.lists(st.tuples(byte, value), min_size=1, max_size=most).map(lambda xs: cls(tuple(xs)))


MESSAGE_STRATEGIES: dict[type[codec.Message], st.SearchStrategy[codec.Message]] = {
    codec.InitSystem: st.just(codec.InitSystem()),
    codec.InitAllPrograms: st.just(codec.InitAllPrograms()),
    codec.InitProgram: st.builds(codec.InitProgram, pn),
    codec.InitProgramsFrom: st.builds(codec.InitProgramsFrom, pn),
    codec.InitPrograms: ranged(codec.InitPrograms),
    codec.WriteSystem: st.builds(codec.WriteSystem, systems),
    codec.WriteProgram: st.builds(codec.WriteProgram, pn, programs),
    codec.LinkPrograms: ranged(codec.LinkPrograms),
    codec.UnlinkPrograms: ranged(codec.UnlinkPrograms),
    codec.WritePartProgram: st.builds(codec.WritePartProgram, pn, kf, kf),
    codec.WritePartPrograms: part_programs(),
    **{cls: items(cls, kf, 15) for cls in codec.FIELD_MESSAGES.values()},
    codec.WriteAddresses: items(codec.WriteAddresses, byte, 31),
    codec.ReadSystem: st.just(codec.ReadSystem()),
    codec.ReadProgram: st.builds(codec.ReadProgram, pn),
    codec.ReadPrograms: ranged(codec.ReadPrograms, most=4),
}
messages = st.one_of(*MESSAGE_STRATEGIES.values())


def test_there_is_a_strategy_for_every_message_type():
    assert set(MESSAGE_STRATEGIES) == set(codec.MESSAGE_TYPES.values())


@PROPERTY
@given(messages)
def test_every_message_round_trips(message):
    data = message.encode()
    assert len(data) % 2 == 0 and 2 <= len(data) <= 64
    assert data[0] == message.ID
    assert codec.decode_message(data) == message


# -- decode_message on arbitrary bytes -------------------------------------------------------
# An independent reading of docs/protocol.md "Messages" and §4.5 checks 1–5: per ID, the header words
# and the length the header gives, and which bytes are don't-care ("xx").

BARE = {0x10: 1, 0x11: 1, 0x50: 1}  # [ID xx]
ONE_PN = {0x12: 1, 0x13: 1, 0x21: 8, 0x32: 3, 0x51: 1}  # [ID PN] …
RANGE = {0x14, 0x30, 0x31, 0x33, 0x52}  # [ID xx] [PN1 PN2] …
ITEMS = {0x40: 2, 0x41: 2, 0x42: 2, 0x43: 2, 0x44: 2, 0x45: 2, 0x46: 1}  # [ID NUM] items of n words


def expected_code(data: bytes) -> int | None:
    """The code checks 1–5 give, or None when the bytes are a well-formed message."""
    if not data:
        return 11
    if len(data) > 64:
        return 12
    ident = data[0]
    if ident not in {*BARE, *ONE_PN, *RANGE, *ITEMS, 0x20}:
        return 10
    header = 2 if ident in RANGE else 1
    if len(data) % 2 or len(data) < 2 * header:
        return 13
    if ident in ONE_PN:
        if not 1 <= data[1] <= 64:
            return 15
        words = ONE_PN[ident]
    elif ident in RANGE:
        first, last = data[2], data[3]
        if not (1 <= first <= 64 and 1 <= last <= 64) or first > last:
            return 15
        if ident == 0x52 and last - first + 1 > 4:
            return 15
        words = 2 + 2 * (last - first + 1) if ident == 0x33 else 2
    elif ident in ITEMS:
        if data[1] == 0:
            return 15
        words = 1 + ITEMS[ident] * data[1]
    else:
        words = BARE.get(ident, 12)  # 20h: 12 words
    if len(data) < 2 * words:
        return 13
    if len(data) > 2 * words:
        return 14
    return None


def dont_care_zeroed(data: bytes) -> bytes:
    out = bytearray(data)
    ident = data[0]
    if ident in BARE or ident in RANGE or ident == 0x20:
        out[1] = 0  # [ID xx]
    if ident == 0x20:
        out[17] = 0  # [S8 xx]
    if ident == 0x21:
        out[15] = 0  # [A xx]
    if ident in ITEMS and ITEMS[ident] == 2:
        for i in range(data[1]):
            out[4 * i + 3] = 0  # [PN xx]
    return bytes(out)


ids = st.sampled_from(sorted(codec.MESSAGE_TYPES))


@st.composite
def mutated(draw):
    """A valid message with one byte changed, or cut, or extended."""
    data = bytearray(draw(messages).encode())
    how = draw(st.sampled_from(["byte", "cut", "extend"]))
    if how == "byte":
        data[draw(st.integers(0, len(data) - 1))] = draw(byte)
    elif how == "cut":
        del data[draw(st.integers(0, len(data) - 1)) :]
    else:
        data += draw(st.binary(min_size=1, max_size=8))
    return bytes(data)


ARBITRARY_BYTES = (
    st.binary(max_size=70),
    st.tuples(ids, st.binary(max_size=69)).map(lambda t: bytes([t[0]]) + t[1]),
    st.tuples(ids, st.binary(min_size=1, max_size=7), st.integers(0, 70)).map(
        lambda t: (bytes([t[0]]) + t[1] + bytes(70))[: t[2]]
    ),
    messages.map(lambda m: m.encode()),
    mutated(),
)
#: Each kind of input equally often (a plain one_of leans hard towards the valid messages).
arbitrary_bytes = st.sampled_from(range(len(ARBITRARY_BYTES))).flatmap(ARBITRARY_BYTES.__getitem__)


@PROPERTY
@given(arbitrary_bytes)
def test_decode_message_accepts_exactly_the_well_formed_bytes(data):
    expected = expected_code(data)
    try:
        message = codec.decode_message(data)
    except codec.Rejected as rejected:
        assert rejected.code in {10, 11, 12, 13, 14, 15}
        assert rejected.code == expected
    else:
        assert expected is None
        assert isinstance(message, codec.MESSAGE_TYPES[data[0]])
        assert message.encode() == dont_care_zeroed(data)


# -- replies ---------------------------------------------------------------------------------


@PROPERTY
@given(systems, byte)
def test_system_reply_round_trips(system, address):
    reply = codec.SystemReply(system, address)
    data = reply.encode()
    assert len(data) == 22
    assert codec.decode_reply(codec.ReadSystem(), data) == reply


@st.composite
def program_replies(draw):
    first, last = draw(program_range(most=4))
    block = draw(st.lists(programs, min_size=last - first + 1, max_size=last - first + 1))
    return codec.ProgramsReply(first, tuple(block))


@PROPERTY
@given(program_replies())
def test_programs_reply_round_trips(reply):
    data = reply.encode()
    assert len(data) == 16 * len(reply.programs)
    last = reply.first + len(reply.programs) - 1
    assert codec.decode_reply(codec.ReadPrograms(reply.first, last), data) == reply
    if len(reply.programs) == 1:
        assert codec.decode_reply(codec.ReadProgram(reply.first), data) == reply


@PROPERTY
@given(messages, byte)
def test_a_code_reply_round_trips_for_any_request(message, code):
    assert codec.decode_reply(message, codec.encode_code(code)) == code
