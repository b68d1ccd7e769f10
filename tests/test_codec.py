"""The codec against docs/protocol.md: the manual's worked examples (§5) byte for byte, one
hand-written vector per message ID, the build-time limits, the structural checks 1–5 of §4.5
with their codes and order, reply decoding, and the error-code texts."""

from __future__ import annotations

from dataclasses import replace

import pytest

from prc3cfg.core import codec, error_codes
from prc3cfg.core.codec import (
    InitAllPrograms,
    InitProgram,
    InitPrograms,
    InitProgramsFrom,
    InitSystem,
    LinkPrograms,
    ProgramsReply,
    ReadProgram,
    ReadPrograms,
    ReadSystem,
    SystemReply,
    UnlinkPrograms,
    WriteAddresses,
    WriteDwellTimes,
    WriteF1,
    WriteF2,
    WritePartProgram,
    WritePartPrograms,
    WritePositions,
    WriteProgram,
    WriteRelativeSpeeds,
    WriteSpeeds,
    WriteSystem,
)
from prc3cfg.core.image import DEFAULT_SYSTEM, Program, SystemParameters


def h(text: str) -> bytes:
    """Hex words as the manual prints them ("210A 041A") → bytes."""
    return bytes.fromhex(text.replace(" ", ""))


def case(id_: str, *values):
    return pytest.param(*values, id=id_)


# -- §5: the manual's worked examples -----------------------------------------------------

MANUAL_PROGRAM_10 = Program(P=1050, V=300, Vr=53, T=20, F1=1010, F2=50, A=5)
MANUAL_PROGRAM_6 = Program(P=1050, V=300, Vr=53, T=20, F1=1020, F2=50, A=7)
#: manual §2.4.3: the three blocks answering 52h 4..6, with the A words as printed (07, 06, 07).
MANUAL_PROGRAMS_4_TO_6 = (
    Program(P=1050, V=300, Vr=53, T=20, F1=1020, F2=20, A=7),
    Program(P=100, V=500, Vr=0, T=20, F1=1000, F2=0, A=6),
    Program(P=600, V=200, Vr=0, T=0, F1=1000, F2=0, A=7),
)
MANUAL_52H_REPLY = h(
    "0400 041A 012C 0035 0014 03FC 0014 0700"
    "0500 0064 01F4 0000 0014 03E8 0000 0600"
    "0600 0258 00C8 0000 0000 03E8 0000 0700"
)
MANUAL_50H_REPLY = h("0190 0032 02F2 0258 000A 05DC 03E8 0001 0247 044C 000A")
MANUAL_51H_REPLY = h("0600 041A 012C 0035 0014 03FC 0032 0700")

MANUAL_REQUESTS = [
    case("21h-2.3.7", "210A 041A 012C 0035 0014 03F2 0032 0500", WriteProgram(10, MANUAL_PROGRAM_10)),
    case("30h-2.3.8", "3000 0530", LinkPrograms(5, 48)),
    case("31h-2.3.9", "3100 0540", UnlinkPrograms(5, 64)),
    case("32h-2.3.10", "3205 041A 012C", WritePartProgram(5, 1050, 300)),
    case("46h-2.3.17-first-four", "4604 0110 0501 0805 1401",
         WriteAddresses(((1, 16), (5, 1), (8, 5), (20, 1)))),
    case("50h-2.4.1", "5000", ReadSystem()),
    case("51h-2.4.2", "5106", ReadProgram(6)),
    case("52h-2.4.3", "5200 0406", ReadPrograms(4, 6)),
]


@pytest.mark.parametrize(("words", "message"), MANUAL_REQUESTS)
def test_manual_request_encodes_to_the_manuals_words(words, message):
    assert message.encode() == h(words)
    assert message.hex() == h(words).hex()


@pytest.mark.parametrize(("words", "message"), MANUAL_REQUESTS)
def test_manual_request_decodes_from_the_manuals_words(words, message):
    assert codec.decode_message(h(words)) == message


MANUAL_REPLIES = [
    case("50h-2.4.1-address-1", ReadSystem(), MANUAL_50H_REPLY, SystemReply(DEFAULT_SYSTEM, 1)),
    case("51h-2.4.2", ReadProgram(6), MANUAL_51H_REPLY, ProgramsReply(6, (MANUAL_PROGRAM_6,))),
    case("52h-2.4.3-three-blocks", ReadPrograms(4, 6), MANUAL_52H_REPLY,
         ProgramsReply(4, MANUAL_PROGRAMS_4_TO_6)),
    case("error-reply-32", WritePartProgram(5, 1050, 300), h("2000"), 32),
    case("accepted", WriteProgram(10, MANUAL_PROGRAM_10), h("0000"), 0),
]


@pytest.mark.parametrize(("request_", "data", "reply"), MANUAL_REPLIES)
def test_manual_reply_decodes(request_, data, reply):
    assert codec.decode_reply(request_, data) == reply


@pytest.mark.parametrize(("request_", "data", "reply"), MANUAL_REPLIES)
def test_manual_reply_encodes(request_, data, reply):
    encoded = codec.encode_code(reply) if isinstance(reply, int) else reply.encode()
    assert encoded == data


def test_manual_50h_reply_carries_s8_and_s9_in_one_word():
    reply = SystemReply(replace(DEFAULT_SYSTEM, S8=1), 30)
    assert reply.encode()[14:16] == h("011E")
    assert SystemReply.decode(reply.encode()) == reply


# -- one hand-written vector per message ID -----------------------------------------------

SYSTEM_1800 = SystemParameters(S1=1800, S2=60, S3=754, S4=500, S5=20, S6=1200, S7=900, S8=1, S10=583,
                               S11=1100, S12=50)

EVERY_ID = [
    case("10h", "1000", InitSystem()),
    case("11h", "1100", InitAllPrograms()),
    case("12h-manual-2.3.3", "120A", InitProgram(10)),
    case("13h-manual-2.3.4", "130A", InitProgramsFrom(10)),
    case("14h-manual-2.3.5", "1400 0A14", InitPrograms(10, 20)),
    case("20h-manual-2.3.6-defaults", "2000 0190 0032 02F2 0258 000A 05DC 03E8 0000 0247 044C 000A",
         WriteSystem(DEFAULT_SYSTEM)),
    case("20h", "2000 0708 003C 02F2 01F4 0014 04B0 0384 0100 0247 044C 0032", WriteSystem(SYSTEM_1800)),
    case("21h-limits", "2140 0000 0258 FDA8 0258 07CF 0000 4000",
         WriteProgram(64, Program(0, 600, -600, 600, 1999, 0, 64))),
    case("30h", "3000 0102", LinkPrograms(1, 2)),
    case("31h", "3100 4040", UnlinkPrograms(64, 64)),
    case("32h", "3240 0000 0001", WritePartProgram(64, 0, 1)),
    case("33h", "3300 3E40 0064 000A 00C8 0014 012C 001E",
         WritePartPrograms(62, ((100, 10), (200, 20), (300, 30)))),
    case("40h-negative-kf", "4002 0100 0320 4000 FFFF", WritePositions(((1, 800), (64, -1)))),
    case("41h", "4101 0500 012C", WriteSpeeds(((5, 300),))),
    case("42h", "4202 0100 0320 0500 FE0C", WriteRelativeSpeeds(((1, 800), (5, -500)))),
    case("43h", "4301 1800 01F4", WriteDwellTimes(((24, 500),))),
    case("44h", "4402 0100 0438 1800 0032", WriteF1(((1, 1080), (24, 50)))),
    case("45h", "4501 1800 041A", WriteF2(((24, 1050),))),
    case("46h", "4601 2001", WriteAddresses(((32, 1),))),
    case("50h", "5000", ReadSystem()),
    case("51h", "5140", ReadProgram(64)),
    case("52h", "5200 3D40", ReadPrograms(61, 64)),
]


def test_the_id_table_covers_every_message_type():
    ids = {param.values[0][:2] for param in EVERY_ID}
    assert ids == {f"{message_id:02X}" for message_id in codec.MESSAGE_TYPES}


@pytest.mark.parametrize(("words", "message"), EVERY_ID)
def test_message_encodes(words, message):
    assert message.encode() == h(words)
    assert h(words)[0] == type(message).ID


@pytest.mark.parametrize(("words", "message"), EVERY_ID)
def test_message_decodes(words, message):
    decoded = codec.decode_message(h(words))
    assert decoded == message
    assert type(decoded) is codec.MESSAGE_TYPES[h(words)[0]]


@pytest.mark.parametrize(
    ("words", "message"),
    [
        case("10h-low-byte", "10FF", InitSystem()),
        case("11h-low-byte", "11A5", InitAllPrograms()),
        case("14h-low-byte", "14FF 0A14", InitPrograms(10, 20)),
        case("20h-id-and-s8-low-bytes", "20FF 0190 0032 02F2 0258 000A 05DC 03E8 01FF 0247 044C 000A",
             WriteSystem(replace(DEFAULT_SYSTEM, S8=1))),
        case("21h-a-low-byte", "210A 041A 012C 0035 0014 03F2 "
                               "0032 05FF", WriteProgram(10, MANUAL_PROGRAM_10)),
        case("30h-low-byte", "3001 0530", LinkPrograms(5, 48)),
        case("31h-low-byte", "3180 0540", UnlinkPrograms(5, 64)),
        case("33h-low-byte", "33FF 0101 0064 000A", WritePartPrograms(1, ((100, 10),))),
        case("40h-item-low-bytes", "4002 01FF 0320 05AA 012C", WritePositions(((1, 800), (5, 300)))),
        case("45h-item-low-byte", "4501 1801 041A", WriteF2(((24, 1050),))),
        case("50h-low-byte", "5001", ReadSystem()),
        case("52h-low-byte", "52FF 0406", ReadPrograms(4, 6)),
    ],
)
def test_dont_care_bytes_are_ignored_on_decode_and_sent_as_zero(words, message):
    decoded = codec.decode_message(h(words))
    assert decoded == message
    assert decoded.encode() != h(words)  # the xx bytes come back as 00
    assert len(decoded.encode()) == len(h(words))


@pytest.mark.parametrize(
    "message",
    [
        pytest.param(WriteAddresses(tuple((n, n + 1) for n in range(1, 32))), id="46h-31-items-64-bytes"),
        pytest.param(WritePositions(tuple((n, 100) for n in range(1, 16))), id="40h-15-items-62-bytes"),
        pytest.param(WritePartPrograms(50, tuple((100, 50) for _ in range(15))), id="33h-15-pairs-64-bytes"),
        pytest.param(ReadPrograms(61, 64), id="52h-4-programs"),
    ],
)
def test_largest_messages_fit_64_bytes_and_round_trip(message):
    assert len(message.encode()) <= 64
    assert codec.decode_message(message.encode()) == message


# -- build-time limits: MessageError -------------------------------------------------------

P = Program(P=100, V=50)
FIELD_CLASSES = list(codec.FIELD_MESSAGES.values())

BUILD_ERRORS = [
    *(case(f"{c.ID:02X}h-16-items", lambda c=c: c(tuple((n, 100) for n in range(1, 17))))
      for c in FIELD_CLASSES),
    *(case(f"{c.ID:02X}h-no-items", lambda c=c: c(())) for c in FIELD_CLASSES),
    case("46h-32-items", lambda: WriteAddresses(tuple((n, 0) for n in range(1, 33)))),
    case("46h-no-items", lambda: WriteAddresses(())),
    case("33h-16-pairs", lambda: WritePartPrograms(1, ((100, 50),) * 16)),
    case("33h-no-pairs", lambda: WritePartPrograms(1, ())),
    case("33h-past-64", lambda: WritePartPrograms(63, ((100, 50),) * 3)),
    case("33h-first-0", lambda: WritePartPrograms(0, ((100, 50),))),
    case("52h-5-programs", lambda: ReadPrograms(1, 5)),
    case("52h-64-programs", lambda: ReadPrograms(1, 64)),
    case("12h-pn-0", lambda: InitProgram(0)),
    case("12h-pn-65", lambda: InitProgram(65)),
    case("13h-pn-0", lambda: InitProgramsFrom(0)),
    case("13h-pn-65", lambda: InitProgramsFrom(65)),
    case("21h-pn-0", lambda: WriteProgram(0, P)),
    case("21h-pn-65", lambda: WriteProgram(65, P)),
    case("32h-pn-65", lambda: WritePartProgram(65, 100, 50)),
    case("51h-pn-0", lambda: ReadProgram(0)),
    case("51h-pn-65", lambda: ReadProgram(65)),
    case("14h-pn1-0", lambda: InitPrograms(0, 5)),
    case("14h-pn2-65", lambda: InitPrograms(5, 65)),
    case("30h-pn1-0", lambda: LinkPrograms(0, 1)),
    case("31h-pn2-65", lambda: UnlinkPrograms(1, 65)),
    case("52h-pn1-0", lambda: ReadPrograms(0, 1)),
    case("14h-pn1-gt-pn2", lambda: InitPrograms(6, 5)),
    case("30h-pn1-gt-pn2", lambda: LinkPrograms(6, 5)),
    case("31h-pn1-gt-pn2", lambda: UnlinkPrograms(64, 1)),
    case("52h-pn1-gt-pn2", lambda: ReadPrograms(6, 5)),
    case("21h-p-32768", lambda: WriteProgram(1, replace(P, P=32768))),
    case("21h-vr-minus-32769", lambda: WriteProgram(1, replace(P, Vr=-32769))),
    case("21h-f2-65536", lambda: WriteProgram(1, replace(P, F2=65536))),
    case("32h-v-65536", lambda: WritePartProgram(1, 100, 65536)),
    case("33h-p-minus-40000", lambda: WritePartPrograms(1, ((-40000, 50),))),
    case("40h-p-40000", lambda: WritePositions(((1, 40000),))),
    case("43h-t-minus-32769", lambda: WriteDwellTimes(((1, -32769),))),
    case("20h-s1-70000", lambda: WriteSystem(replace(DEFAULT_SYSTEM, S1=70000))),
    case("20h-s12-minus-32769", lambda: WriteSystem(replace(DEFAULT_SYSTEM, S12=-32769))),
    case("21h-a-256", lambda: WriteProgram(1, replace(P, A=256))),
    case("21h-a-minus-1", lambda: WriteProgram(1, replace(P, A=-1))),
    case("46h-a-256", lambda: WriteAddresses(((1, 256),))),
    case("46h-a-minus-1", lambda: WriteAddresses(((1, -1),))),
    case("46h-pn-256", lambda: WriteAddresses(((256, 1),))),
    case("40h-pn-256", lambda: WritePositions(((256, 100),))),
    case("20h-s8-256", lambda: WriteSystem(replace(DEFAULT_SYSTEM, S8=256))),
    case("20h-s8-minus-1", lambda: WriteSystem(replace(DEFAULT_SYSTEM, S8=-1))),
]


@pytest.mark.parametrize("build", BUILD_ERRORS)
def test_building_a_message_the_protocol_cannot_carry_raises(build):
    with pytest.raises(codec.MessageError):
        build()


@pytest.mark.parametrize(
    "build",
    [
        case("21h-kf-extremes",
             lambda: WriteProgram(1, Program(P=32767, V=-32768, Vr=-32768, T=32767, F1=-1, F2=0, A=255))),
        case("20h-s8-255", lambda: WriteSystem(replace(DEFAULT_SYSTEM, S8=255))),
        case("40h-item-pn-0-is-the-modules-to-check", lambda: WritePositions(((0, 100),))),
        case("46h-item-pn-65-is-the-modules-to-check", lambda: WriteAddresses(((65, 1),))),
    ],
)
def test_values_the_module_rejects_can_still_be_built(build):
    message = build()
    assert codec.decode_message(message.encode()) == message


# -- decode_message: structural checks 1–5 of §4.5 ----------------------------------------

TOO_LONG = b"\x10" + bytes(64)  # 65 bytes

REJECTED = [
    # 1. length
    case("empty", b"", 11),
    case("65-bytes", TOO_LONG, 12),
    case("66-bytes", b"\x50" + bytes(65), 12),
    case("65-bytes-unknown-id-12-wins", b"\xff" * 65, 12),
    # 2. unknown ID
    *(case(f"unknown-id-{i:02X}", bytes([i, 0]), 10) for i in (0x00, 0x15, 0x22, 0x47, 0x53, 0xFF)),
    case("unknown-id-0F", h("0F00"), 10),
    case("unknown-id-1-byte-10-wins-over-odd", b"\x22", 10),
    case("unknown-id-3-bytes-10-wins-over-odd", h("470000"), 10),
    # 3. odd length / shorter than the header
    case("odd-1-byte", b"\x10", 13),
    case("odd-3-bytes", h("100000"), 13),
    case("odd-21h-15-bytes", h("210A 041A 012C 0035 0014 03F2 0032 05"), 13),
    *(case(f"{i:02X}h-header-cut", bytes([i, 0]), 13) for i in (0x14, 0x30, 0x31, 0x33, 0x52)),
    # 4. header program numbers
    case("12h-pn-0", h("1200"), 15),
    case("12h-pn-65", h("1241"), 15),
    case("13h-pn-0", h("1300"), 15),
    case("13h-pn-FF", h("13FF"), 15),
    case("21h-pn-0", h("2100 041A 012C 0035 0014 03F2 0032 0500"), 15),
    case("32h-pn-65", h("3241 041A 012C"), 15),
    case("51h-pn-0", h("5100"), 15),
    case("51h-pn-65", h("5141"), 15),
    case("14h-pn1-0", h("1400 0005"), 15),
    case("14h-pn2-65", h("1400 0541"), 15),
    case("14h-pn1-gt-pn2", h("1400 0605"), 15),
    case("30h-pn-0-0", h("3000 0000"), 15),
    case("30h-pn1-gt-pn2", h("3000 3005"), 15),
    case("31h-pn-65-65", h("3100 4141"), 15),
    case("33h-pn1-gt-pn2", h("3300 0201 0064 000A"), 15),
    case("33h-pn2-65", h("3300 4041 0064 000A 0064 000A"), 15),
    case("52h-pn1-0", h("5200 0001"), 15),
    case("52h-five-programs", h("5200 0105"), 15),
    case("52h-sixty-four-programs", h("5200 0140"), 15),
    *(case(f"{i:02X}h-num-0", bytes([i, 0]), 15) for i in range(0x40, 0x47)),
    case("12h-pn-0-extra-bytes-15-before-length", h("1200 0000"), 15),
    case("40h-num-0-extra-bytes-15-before-length", h("4000 0100 0064"), 15),
    case("52h-five-programs-extra-bytes-15-before-length", h("5200 0105 0000"), 15),
    # 5. length against the header
    case("20h-short", h("2000"), 13),
    case("20h-one-word-short", h("2000 0190 0032 02F2 0258 000A 05DC 03E8 0000 0247 044C"), 13),
    case("21h-short", h("210A 041A 012C 0035 0014 03F2 0032"), 13),
    case("32h-short", h("3205 041A"), 13),
    case("33h-short", h("3300 0102 0064 000A"), 13),
    case("40h-short", h("4002 0100 0320"), 13),
    case("46h-short", h("4602 0110"), 13),
    case("46h-num-32-in-64-bytes", h("4620") + h("0101") * 31, 13),
    case("40h-num-16-in-64-bytes", h("4010") + h("0100 0064") * 15 + h("0100"), 13),
    case("33h-16-programs-in-64-bytes", h("3300 0110") + h("0064 000A") * 15, 13),
    case("10h-long", h("1000 0000"), 14),
    case("11h-long", h("1100 0000"), 14),
    case("12h-long", h("120A 0000"), 14),
    case("13h-long", h("130A 0000"), 14),
    case("14h-long", h("1400 0A14 0000"), 14),
    case("20h-long", h("2000 0190 0032 02F2 0258 000A 05DC 03E8 0000 0247 044C 000A 0000"), 14),
    case("21h-long", h("210A 041A 012C 0035 0014 03F2 0032 0500 0000"), 14),
    case("30h-long", h("3000 0530 0000"), 14),
    case("31h-long", h("3100 0540 0000"), 14),
    case("32h-long", h("3205 041A 012C 0000"), 14),
    case("33h-long", h("3300 0101 0064 000A 0000"), 14),
    case("41h-long", h("4101 0500 012C 0000"), 14),
    case("46h-long", h("4601 0110 0000"), 14),
    case("50h-long", h("5000 0000"), 14),
    case("51h-long", h("5106 0000"), 14),
    case("52h-long", h("5200 0406 0000"), 14),
]


@pytest.mark.parametrize(("data", "code"), REJECTED)
def test_decode_message_rejects_with_the_modules_code(data, code):
    with pytest.raises(codec.Rejected) as rejected:
        codec.decode_message(data)
    assert rejected.value.code == code


# -- decode_reply --------------------------------------------------------------------------

REPLIES = [
    case("write-accepted", InitSystem(), h("0000"), 0),
    case("write-code-32", WritePartProgram(5, 1050, 300), h("2000"), 32),
    case("write-code-122", WriteSystem(DEFAULT_SYSTEM), h("7A00"), 122),
    case("read-rejected-15", ReadPrograms(4, 6), h("0F00"), 15),
    case("50h-block", ReadSystem(), MANUAL_50H_REPLY, SystemReply(DEFAULT_SYSTEM, 1)),
    case("51h-block", ReadProgram(6), MANUAL_51H_REPLY, ProgramsReply(6, (MANUAL_PROGRAM_6,))),
    case("52h-one-block", ReadPrograms(5, 5), MANUAL_52H_REPLY[16:32],
         ProgramsReply(5, MANUAL_PROGRAMS_4_TO_6[1:2])),
    case("52h-three-blocks", ReadPrograms(4, 6), MANUAL_52H_REPLY, ProgramsReply(4, MANUAL_PROGRAMS_4_TO_6)),
    case(
        "51h-block-dont-care-bytes",
        ReadProgram(6),
        h("06FF 041A 012C 0035 0014 03FC 0032 07A5"),
        ProgramsReply(6, (MANUAL_PROGRAM_6,)),
    ),
    case("code-dont-care-byte", InitSystem(), h("0FFF"), 15),
]


@pytest.mark.parametrize(("request_", "data", "reply"), REPLIES)
def test_decode_reply(request_, data, reply):
    assert codec.decode_reply(request_, data) == reply


BAD_REPLIES = [
    case("write-empty", InitSystem(), b""),
    case("write-one-byte", InitSystem(), b"\x00"),
    case("write-4-bytes", WritePartProgram(5, 1050, 300), h("0000 0000")),
    case("write-answered-with-a-block", InitAllPrograms(), MANUAL_51H_REPLY),
    case("50h-one-word-short", ReadSystem(), MANUAL_50H_REPLY[:-2]),
    case("50h-one-word-long", ReadSystem(), MANUAL_50H_REPLY + h("0000")),
    case("51h-two-blocks", ReadProgram(4), MANUAL_52H_REPLY[:32]),
    case("51h-odd", ReadProgram(6), MANUAL_51H_REPLY[:-1]),
    case("52h-two-of-three-blocks", ReadPrograms(4, 6), MANUAL_52H_REPLY[:32]),
    case("52h-four-blocks-for-three", ReadPrograms(4, 6), MANUAL_52H_REPLY + MANUAL_51H_REPLY),
    case("51h-block-numbered-7", ReadProgram(6), h("0700") + MANUAL_51H_REPLY[2:]),
    case("52h-blocks-numbered-4-5-7", ReadPrograms(4, 6), MANUAL_52H_REPLY[:32] + h("0700")
         + MANUAL_52H_REPLY[34:]),
    case("52h-blocks-numbered-5-6-7", ReadPrograms(4, 6), b"".join(
        h(f"0{n}00") + MANUAL_52H_REPLY[16 * b + 2 : 16 * b + 16] for b, n in enumerate((5, 6, 7))
    )),
]


@pytest.mark.parametrize(("request_", "data"), BAD_REPLIES)
def test_decode_reply_rejects_a_reply_that_fits_neither(request_, data):
    with pytest.raises(codec.BadReply):
        codec.decode_reply(request_, data)


@pytest.mark.parametrize(
    ("message", "length"),
    [
        case("write", WriteProgram(10, MANUAL_PROGRAM_10), 2),
        case("50h", ReadSystem(), 22),
        case("51h", ReadProgram(6), 16),
        case("52h-1", ReadPrograms(1, 1), 16),
        case("52h-4", ReadPrograms(1, 4), 64),
    ],
)
def test_reply_length(message, length):
    assert codec.reply_length(message) == length


@pytest.mark.parametrize("code", [0, 10, 32, 122, 255])
def test_encode_code_is_one_word_high_byte_first(code):
    assert codec.encode_code(code) == bytes([code, 0])


# -- error_codes.describe ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("code", "text"),
    [
        case("accepted", 0, "accepted"),
        case("32", 32, "code 32: P > S1: position must not be greater than the upper reversing point"),
        case("10", 10, "code 10: invalid identification number (ID)"),
        case("110", 110, "code 110: S4 < S5: maximum speed must not be smaller than the minimum speed"),
        case("unknown-111", 111, "unknown code 111"),
        case("unknown-17", 17, "unknown code 17"),
        case("unknown-255", 255, "unknown code 255"),
    ],
)
def test_describe(code, text):
    assert error_codes.describe(code) == text


@pytest.mark.parametrize("code", sorted(error_codes.ERROR_CODES))
def test_every_code_has_a_meaning_and_a_remedy(code):
    assert error_codes.describe(code).startswith(f"code {code}: ")
    assert error_codes.remedy(code)
    assert error_codes.remedy(code) != error_codes.remedy(999)


def test_the_error_table_is_the_manuals():
    expected = {
        *range(10, 17), *range(20, 33), 40, 41, 50, 51, 60, 61, 70, 71, 72, 73, 80,
        *range(100, 111), *range(112, 123),
    }
    assert set(error_codes.ERROR_CODES) == expected
