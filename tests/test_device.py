"""The device model against docs/protocol.md "What a module does": every check of §4.5 and every error code,
their order, atomic rejection, operating states, defaults, clamping, link/unlink, reads and
the state-file entry. Each case is (state, message bytes) → (state, reply)."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from prc3cfg.core import codec, device, error_codes
from prc3cfg.core.codec import (
    InitAllPrograms,
    InitProgram,
    InitPrograms,
    InitProgramsFrom,
    InitSystem,
    LinkPrograms,
    ReadProgram,
    ReadPrograms,
    ReadSystem,
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
from prc3cfg.core.device import ModuleState
from prc3cfg.core.image import DEFAULT_SYSTEM, Program, SystemParameters

ACCEPTED = b"\x00\x00"


def h(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


def case(id_: str, *values):
    return pytest.param(*values, id=id_)


def as_bytes(message: codec.Message | bytes | str) -> bytes:
    if isinstance(message, codec.Message):
        return message.encode()
    return h(message) if isinstance(message, str) else message


def module(address: int = 1, *, system: dict | None = None, **state) -> ModuleState:
    """A factory module with some system parameters and operating state changed."""
    base = ModuleState.factory(address)
    image = replace(base.image, system=replace(DEFAULT_SYSTEM, **(system or {})))
    return replace(base, image=image, **state)


def with_programs(state: ModuleState, changes: dict[int, Program]) -> ModuleState:
    programs = list(state.image.programs)
    for number, program in changes.items():
        programs[number - 1] = program
    return replace(state, image=replace(state.image, programs=tuple(programs)))


def marked(state: ModuleState) -> ModuleState:
    """Every program holds a distinctive non-default value (valid for the module's system)."""
    s = state.image.system
    return with_programs(
        state, {n: Program(P=min(90 + n, s.S1), V=s.S4, Vr=-n, T=n, F1=1000 + n, F2=n, A=(n % 64) + 1)
                for n in range(1, 65)}
    )


def program(state: ModuleState, number: int) -> Program:
    return state.image.programs[number - 1]


def code_of(reply: bytes | None) -> int:
    assert reply is not None and len(reply) == 2 and reply[1] == 0, reply
    return reply[0]


def send(state: ModuleState, message, *, broadcast: bool = False) -> device.Outcome:
    return device.process(state, as_bytes(message), broadcast=broadcast)


STOP = module()
WIDE = module(system={"S1": 9999})  # room for the manual's 1.050 m positions
RUN_10 = replace(STOP, mode="run", active_program=10)
GOOD = Program(P=100, V=50)


def program_with(**fields) -> Program:
    return replace(GOOD, **fields)


# -- every error code, each from a real message -------------------------------------------

FAULTS = list(device.FAULT_CODES.items())  # E09 → 21 … fault → 30

ERROR_CASES = [
    # checks 1–5 (decoding)
    case("11-empty", STOP, b"", 11),
    case("12-65-bytes", STOP, b"\x10" + bytes(64), 12),
    case("10-unknown-id", STOP, "2200", 10),
    case("13-odd", STOP, "100000", 13),
    case("13-short", STOP, "3205 041A", 13),
    case("14-long", STOP, "5000 0000", 14),
    case("15-header-pn", STOP, "1241", 15),
    case("15-item-pn-65", STOP, WritePositions(((1, 100), (65, 100))), 15),
    case("15-item-pn-0", STOP, WriteAddresses(((0, 1),)), 15),
    # check 6 (operating state)
    case("20-run-10h", RUN_10, InitSystem(), 20),
    case("20-run-20h", RUN_10, WriteSystem(DEFAULT_SYSTEM), 20),
    *(case(f"{c}-{f}-12h", module(fault=f), InitProgram(5), c) for f, c in FAULTS),
    # check 8 (active program)
    case("16-active", RUN_10, InitProgram(10), 16),
    # check 9 (values), 21h-field messages, 32h and 46h
    case("31-p-below-0", STOP, WritePartProgram(5, -1, 50), 31),
    case("32-p-above-s1", STOP, WritePartProgram(5, 401, 50), 32),
    case("40-v-below-s5", STOP, WritePartProgram(5, 100, 9), 40),
    case("41-v-above-s4", STOP, WritePartProgram(5, 100, 601), 41),
    case("50-vr-below", STOP, WriteRelativeSpeeds(((5, -601),)), 50),
    case("51-vr-above", STOP, WriteRelativeSpeeds(((5, 601),)), 51),
    case("60-t-below", STOP, WriteDwellTimes(((5, -1),)), 60),
    case("61-t-above", STOP, WriteDwellTimes(((5, 601),)), 61),
    case("70-f1-below", STOP, WriteF1(((5, -1),)), 70),
    case("71-f1-above", STOP, WriteF1(((5, 2000),)), 71),
    case("72-f2-below", STOP, WriteF2(((5, -1),)), 72),
    case("73-f2-above", STOP, WriteF2(((5, 2000),)), 73),
    case("80-a-above", STOP, WriteAddresses(((5, 65),)), 80),
    # check 9, 20h
    *(
        case(f"{c}-{key}-{value}", STOP, WriteSystem(replace(DEFAULT_SYSTEM, **{key: value})), c)
        for key, value, c in [
            ("S1", 99, 100), ("S1", 10000, 101), ("S2", 49, 102), ("S2", 501, 103),
            ("S3", 0, 104), ("S3", 10000, 105), ("S4", 0, 106), ("S4", 601, 107),
            ("S5", 0, 108), ("S6", 999, 112), ("S6", 1501, 113),
            ("S7", 799, 114), ("S7", 1501, 115), ("S8", 2, 116), ("S8", 255, 116),
            ("S10", 0, 117), ("S10", 10000, 118), ("S11", 0, 119), ("S11", 1501, 120),
            ("S12", 4, 121), ("S12", 51, 122),
        ]
    ),
    case("109-S5-601", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S4=600, S5=601)), 109),
    case("110-S4-below-S5", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S4=10, S5=20)), 110),
]


def test_every_error_code_is_produced_by_a_real_message():
    produced = {param.values[-1] for param in ERROR_CASES}
    assert produced == set(error_codes.ERROR_CODES)


@pytest.mark.parametrize(("state", "message", "code"), ERROR_CASES)
def test_error_code(state, message, code):
    outcome = send(state, message)
    assert code_of(outcome.reply) == code
    assert outcome.state == state  # a rejected message changes nothing


#: The program fields one at a time: (field, bad value, code). P/V against the factory S1/S4/S5.
BAD_FIELDS = [
    ("P", -1, 31), ("P", 401, 32), ("V", 9, 40), ("V", 601, 41), ("V", -1, 40),
    ("Vr", -601, 50), ("Vr", 601, 51), ("T", -1, 60), ("T", 601, 61),
    ("F1", -1, 70), ("F1", 2000, 71), ("F2", -1, 72), ("F2", 2000, 73), ("A", 65, 80), ("A", 255, 80),
]


@pytest.mark.parametrize(("field", "value", "code"), [case(f"{f}={v}", f, v, c) for f, v, c in BAD_FIELDS])
def test_a_bad_field_in_21h(field, value, code):
    outcome = send(STOP, WriteProgram(7, program_with(**{field: value})))
    assert code_of(outcome.reply) == code
    assert outcome.state == STOP


@pytest.mark.parametrize(
    ("field", "value", "code"), [case(f"{f}={v}", f, v, c) for f, v, c in BAD_FIELDS if f != "A"]
)
def test_a_bad_field_in_its_own_4xh_message(field, value, code):
    outcome = send(STOP, codec.FIELD_MESSAGES[field](((3, 100 if field == "P" else 50), (7, value))))
    assert code_of(outcome.reply) == code
    assert outcome.state == STOP


@pytest.mark.parametrize(("field", "value", "code"),
                         [case(f"{f}={v}", f, v, c) for f, v, c in BAD_FIELDS if f in "PV"])
def test_a_bad_p_or_v_in_33h(field, value, code):
    pair = (value, 50) if field == "P" else (100, value)
    outcome = send(STOP, WritePartPrograms(6, ((100, 50), pair)))
    assert code_of(outcome.reply) == code
    assert outcome.state == STOP


# -- the order of the checks ---------------------------------------------------------------

ORDER_CASES = [
    # structure (1–5) before the operating state (6)
    case("13-before-fault", module(fault="E09"), "2000", 13),
    case("15-header-before-fault", module(fault="E09"), "1200", 15),
    case("15-header-before-run-20", RUN_10, "1400 0500", 15),
    case("14-before-run-20", RUN_10, "1000 0000", 14),
    # the operating state (6) before item program numbers (7)
    case("fault-before-item-pn-15", module(fault="E10"), WritePositions(((0, 100),)), 22),
    case("fault-before-46h-item-pn-15", module(fault="fault"), WriteAddresses(((65, 1),)), 30),
    # item program numbers (7) before the active program (8)
    case("15-before-16", RUN_10, WritePositions(((10, 100), (65, 100))), 15),
    case("15-before-16-46h", RUN_10, WriteAddresses(((10, 1), (0, 1))), 15),
    # the active program (8) before values (9)
    case("16-before-p-value", RUN_10, WriteProgram(10, program_with(P=-1)), 16),
    case("16-before-40h-value", RUN_10, WritePositions(((9, 5000), (10, 100))), 16),
    case("16-before-33h-value", RUN_10, WritePartPrograms(9, ((5000, 50), (100, 50))), 16),
    case("16-before-46h-value", RUN_10, WriteAddresses(((10, 99),)), 16),
    # the fault before RUN's 20, before 16, before values
    case("fault-before-run-20-10h", module(mode="run", fault="E10"), InitSystem(), 22),
    case("fault-before-run-20-20h", module(mode="run", fault="E25"), WriteSystem(DEFAULT_SYSTEM), 29),
    case("fault-before-16", module(mode="run", active_program=5, fault="E20"), InitProgram(5), 24),
    case("fault-before-value", module(fault="E21"), WritePartProgram(5, -1, 50), 25),
    case("e12-run-20h-gives-20", module(mode="run", fault="E12"), WriteSystem(DEFAULT_SYSTEM), 20),
    case("e12-run-10h-gives-20", module(mode="run", fault="E12"), InitSystem(), 20),
    case(
        "e12-bad-20h-gives-value-code", module(fault="E12"), WriteSystem(replace(DEFAULT_SYSTEM, S1=99)), 100
    ),
    # values in message order: 21h
    case("21h-p-before-v", STOP, WriteProgram(1, program_with(P=-1, V=9)), 31),
    case("21h-p-above-before-a", STOP, WriteProgram(1, program_with(P=401, A=65)), 32),
    case("21h-v-before-vr", STOP, WriteProgram(1, program_with(V=601, Vr=-601)), 41),
    case("21h-vr-before-t", STOP, WriteProgram(1, program_with(Vr=601, T=-1)), 51),
    case("21h-t-before-f1", STOP, WriteProgram(1, program_with(T=601, F1=-1)), 61),
    case("21h-f1-before-f2", STOP, WriteProgram(1, program_with(F1=2000, F2=-1)), 71),
    case("21h-f2-before-a", STOP, WriteProgram(1, program_with(F2=2000, A=65)), 73),
    # 33h: pairs in order, P before V within a pair
    case("33h-first-pair-v-before-second-pair-p", STOP, WritePartPrograms(1, ((100, 9), (-1, 50))), 40),
    case("33h-p-before-v-in-a-pair", STOP, WritePartPrograms(1, ((100, 50), (401, 601))), 32),
    case("33h-third-pair", STOP, WritePartPrograms(1, ((100, 50), (100, 50), (100, 601))), 41),
    # 40h: items in order
    case("40h-below-then-above", STOP, WritePositions(((1, -1), (2, 401))), 31),
    case("40h-above-then-below", STOP, WritePositions(((1, 401), (2, -1))), 32),
    case("41h-above-then-below", STOP, WriteSpeeds(((1, 601), (2, 1))), 41),
    case("46h-second-item", STOP, WriteAddresses(((1, 64), (2, 65), (3, 200))), 80),
    # 20h: S1..S12 in order, the pair check right after S5
    case("20h-s1-before-s12", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S1=99, S12=51)), 100),
    case("20h-s2-before-s3", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S2=501, S3=0)), 103),
    case("20h-s3-before-pair", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S3=0, S4=10, S5=20)), 104),
    case("20h-s4-range-before-pair", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S4=0, S5=20)), 106),
    case("20h-s4-above-before-s5", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S4=601, S5=0)), 107),
    case("20h-s5-range-before-pair", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S4=600, S5=601)), 109),
    case("20h-s4-below-before-s5-below", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S4=0, S5=0)), 106),
    case("20h-pair-before-s6", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S4=10, S5=20, S6=999)), 110),
    case("20h-pair-before-s8", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S4=10, S5=20, S8=2)), 110),
    case("20h-pair-before-s12", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S4=10, S5=20, S12=51)), 110),
    case("20h-s6-before-s7", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S6=1501, S7=799)), 113),
    case("20h-s8-before-s10", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S8=2, S10=0)), 116),
    case("20h-s10-before-s11", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S10=10000, S11=0)), 118),
    case("20h-s11-before-s12", STOP, WriteSystem(replace(DEFAULT_SYSTEM, S11=1501, S12=4)), 120),
    case(
        "20h-equal-s4-s5-is-fine-then-s6",
        STOP,
        WriteSystem(replace(DEFAULT_SYSTEM, S4=20, S5=20, S6=999)),
        112,
    ),
    # P and V against the S1, S4, S5 in force (not the factory ones, not those of the message)
    case("p-against-s1-in-force", module(system={"S1": 1000}), WritePartProgram(1, 1001, 50), 32),
    case("v-against-s4-in-force", module(system={"S4": 300}), WriteSpeeds(((1, 301),)), 41),
    case("v-against-s5-in-force", module(system={"S5": 100}), WritePartPrograms(1, ((150, 99),)), 40),
]


@pytest.mark.parametrize(("state", "message", "code"), ORDER_CASES)
def test_the_first_failing_check_gives_the_reply(state, message, code):
    outcome = send(state, message)
    assert code_of(outcome.reply) == code
    assert outcome.state == state


MANUAL_10 = Program(P=1050, V=300, Vr=53, T=20, F1=1010, F2=50, A=5)
UPPER = Program(P=9999, V=600, Vr=600, T=600, F1=1999, F2=1999, A=64)
LOWER = Program(P=0, V=10, Vr=-600, T=0, F1=0, F2=0, A=0)


@pytest.mark.parametrize(
    ("state", "message", "number", "expected"),
    [
        case("p-equal-to-s1-in-force", module(system={"S1": 1000}), WritePartProgram(1, 1000, 50), 1,
             Program(1000, 50)),
        case("v-equal-to-s4-in-force", module(system={"S4": 300}), WritePartProgram(1, 150, 300), 1,
             Program(150, 300)),
        case("v-equal-to-s5-in-force", module(system={"S5": 100}), WritePartProgram(1, 150, 100), 1,
             Program(150, 100)),
        case("p-0", STOP, WritePartProgram(64, 0, 50), 64, Program(0, 50)),
        case("manual-21h-with-s1-9999", WIDE, WriteProgram(10, MANUAL_10), 10, MANUAL_10),
        case("21h-upper-limits", WIDE, WriteProgram(1, UPPER), 1, UPPER),
        case("21h-lower-limits", WIDE, WriteProgram(1, LOWER), 1, LOWER),
    ],
)
def test_values_at_their_limits_are_accepted(state, message, number, expected):
    outcome = send(state, message)
    assert outcome.reply == ACCEPTED
    assert program(outcome.state, number) == expected


def test_the_manuals_21h_example_is_answered_0000():
    outcome = send(WIDE, h("210A 041A 012C 0035 0014 03F2 0032 0500"))
    assert outcome.reply == h("0000")


def test_the_manuals_error_reply_p_above_s1_is_2000():
    outcome = send(STOP, h("210A 041A 012C 0035 0014 03F2 0032 0500"))  # P 1050 > S1 400
    assert outcome.reply == h("2000")
    assert outcome.state == STOP


# -- atomic rejection ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("message", "code"),
    [
        case("33h-third-pair-bad", WritePartPrograms(1, ((100, 50), (200, 60), (401, 70))), 32),
        case("40h-third-item-bad", WritePositions(((1, 100), (2, 200), (3, -1))), 31),
        case("41h-third-item-bad", WriteSpeeds(((1, 100), (2, 200), (3, 601))), 41),
        case("44h-third-item-bad", WriteF1(((1, 100), (2, 200), (3, 2000))), 71),
        case("46h-third-item-bad", WriteAddresses(((1, 2), (2, 3), (3, 65))), 80),
        case("46h-third-item-pn-bad", WriteAddresses(((1, 2), (2, 3), (65, 1))), 15),
        case("21h-last-field-bad", WriteProgram(1, Program(100, 50, 1, 1, 1, 1, 65)), 80),
        case("20h-last-parameter-bad", WriteSystem(replace(DEFAULT_SYSTEM, S1=2000, S4=100, S12=51)), 122),
    ],
)
def test_a_rejected_message_changes_nothing(message, code):
    state = marked(STOP)
    outcome = send(state, message)
    assert code_of(outcome.reply) == code
    assert outcome.state == state


# -- RUN ---------------------------------------------------------------------------------------

TOUCHING_10 = [
    case("21h", WriteProgram(10, GOOD)),
    case("12h", InitProgram(10)),
    case("13h-from-5", InitProgramsFrom(5)),
    case("13h-from-10", InitProgramsFrom(10)),
    case("14h", InitPrograms(8, 12)),
    case("14h-ends-at-10", InitPrograms(1, 10)),
    case("11h", InitAllPrograms()),
    case("30h", LinkPrograms(9, 10)),
    case("30h-starts-at-10", LinkPrograms(10, 20)),
    case("31h", UnlinkPrograms(10, 11)),
    case("32h", WritePartProgram(10, 100, 50)),
    case("33h", WritePartPrograms(9, ((100, 50), (100, 50)))),
    *(case(f"{cls.ID:02X}h", cls(((9, 50), (10, 50)))) for cls in codec.FIELD_MESSAGES.values()),
    case("46h", WriteAddresses(((1, 2), (10, 0)))),
]


@pytest.mark.parametrize("message", TOUCHING_10)
def test_run_a_write_touching_the_active_program_gives_16(message):
    state = marked(RUN_10)
    outcome = send(state, message)
    assert code_of(outcome.reply) == 16
    assert outcome.state == state


NOT_TOUCHING_10 = [
    case("21h", WriteProgram(11, GOOD), lambda s: program(s, 11) == GOOD),
    case("12h", InitProgram(9), lambda s: program(s, 9) == Program(150, 50)),
    case("13h", InitProgramsFrom(11), lambda s: program(s, 11) == program(s, 64) == Program(150, 50)),
    case("14h", InitPrograms(1, 9), lambda s: program(s, 1) == program(s, 9) == Program(150, 50)),
    case("30h", LinkPrograms(1, 9), lambda s: program(s, 9).A == 0 and program(s, 8).A == 9),
    case("31h", UnlinkPrograms(11, 64), lambda s: program(s, 11).A == program(s, 64).A == 0),
    case("32h", WritePartProgram(9, 123, 45), lambda s: (program(s, 9).P, program(s, 9).V) == (123, 45)),
    case("33h", WritePartPrograms(11, ((123, 45),)),
         lambda s: (program(s, 11).P, program(s, 11).V) == (123, 45)),
    *(
        case(
            f"{cls.ID:02X}h",
            cls(((9, 77), (11, 77))),
            lambda s, f=field: getattr(program(s, 9), f) == getattr(program(s, 11), f) == 77,
        )
        for field, cls in codec.FIELD_MESSAGES.items()
    ),
    case("46h-pointing-at-10", WriteAddresses(((9, 10),)), lambda s: program(s, 9).A == 10),
]


@pytest.mark.parametrize(("message", "applied"), NOT_TOUCHING_10)
def test_run_a_write_to_another_program_is_accepted(message, applied):
    state = marked(RUN_10)
    outcome = send(state, message)
    assert outcome.reply == ACCEPTED
    assert applied(outcome.state)
    assert program(outcome.state, 10) == program(state, 10)
    assert (outcome.state.mode, outcome.state.active_program) == ("run", 10)


@pytest.mark.parametrize("message", [case("10h", InitSystem()), case("20h", WriteSystem(DEFAULT_SYSTEM))])
@pytest.mark.parametrize("active", [None, 10])
def test_run_rejects_10h_and_20h_with_20(message, active):
    state = replace(STOP, mode="run", active_program=active)
    outcome = send(state, message)
    assert code_of(outcome.reply) == 20
    assert outcome.state == state
    assert outcome.state.referenced is True


@pytest.mark.parametrize(
    ("message", "length"),
    [case("50h", ReadSystem(), 22), case("51h-active", ReadProgram(10), 16),
     case("52h-around-active", ReadPrograms(9, 12), 64)],
)
def test_run_reads_are_answered(message, length):
    state = marked(RUN_10)
    outcome = send(state, message)
    assert outcome.reply == device.read(state, message)
    assert len(outcome.reply) == length
    assert outcome.state == state


def test_stop_with_an_active_program_left_in_the_state_does_not_block_writes():
    """(reading in device.check_write) A program is only "active" while the module runs."""
    state = replace(STOP, active_program=10)
    outcome = send(state, InitProgram(10))
    assert outcome.reply == ACCEPTED


# -- faults ------------------------------------------------------------------------------------

WRITES = [
    case("10h", InitSystem()),
    case("11h", InitAllPrograms()),
    case("12h", InitProgram(1)),
    case("13h", InitProgramsFrom(1)),
    case("14h", InitPrograms(1, 2)),
    case("20h", WriteSystem(DEFAULT_SYSTEM)),
    case("21h", WriteProgram(1, GOOD)),
    case("30h", LinkPrograms(1, 2)),
    case("31h", UnlinkPrograms(1, 2)),
    case("32h", WritePartProgram(1, 100, 50)),
    case("33h", WritePartPrograms(1, ((100, 50),))),
    *(case(f"{cls.ID:02X}h", cls(((1, 50),))) for cls in codec.FIELD_MESSAGES.values()),
    case("46h", WriteAddresses(((1, 2),))),
]


#: Every fault × every write, but E12 × 10h/20h: those are accepted (test_e12_accepts_…).
FAULTED_WRITES = [
    case(f"{fault}->{code}-{write.id}", fault, code, write.values[0])
    for fault, code in FAULTS
    for write in WRITES
    if not (fault == "E12" and write.values[0].RELEASES_AXES)
]


@pytest.mark.parametrize(("fault", "code", "message"), FAULTED_WRITES)
def test_a_fault_rejects_every_write_with_its_code(fault, code, message):
    state = module(fault=fault)
    outcome = send(state, message)
    assert code_of(outcome.reply) == code
    assert outcome.state == state


@pytest.mark.parametrize("message",
                         [case("50h", ReadSystem()), case("51h", ReadProgram(1)),
                          case("52h", ReadPrograms(1, 4))])
@pytest.mark.parametrize("fault", list(device.FAULT_CODES))
@pytest.mark.parametrize("mode", ["stop", "run"])
def test_a_fault_still_answers_reads(fault, mode, message):
    state = module(fault=fault, mode=mode, active_program=1)
    outcome = send(state, message)
    assert len(outcome.reply) == codec.reply_length(message) > 2
    assert codec.decode_reply(message, outcome.reply) is not None
    assert outcome.state == state


@pytest.mark.parametrize("message",
                         [case("10h", InitSystem()),
                          case("20h", WriteSystem(replace(DEFAULT_SYSTEM, S1=1800)))])
def test_e12_accepts_10h_and_20h_and_clears_the_fault(message):
    state = module(fault="E12")
    outcome = send(state, message)
    assert outcome.reply == ACCEPTED
    assert outcome.state.fault is None
    assert outcome.state.referenced is False
    assert send(outcome.state, InitProgram(1)).reply == ACCEPTED  # writes are taken again


def test_e12_a_rejected_20h_leaves_the_fault():
    state = module(fault="E12")
    outcome = send(state, WriteSystem(replace(DEFAULT_SYSTEM, S4=5, S5=6)))
    assert code_of(outcome.reply) == 110
    assert outcome.state.fault == "E12"


@pytest.mark.parametrize("fault", [f for f in device.FAULT_CODES if f != "E12"])
def test_other_faults_are_not_cleared_by_10h(fault):
    state = module(fault=fault)
    outcome = send(state, InitSystem())
    assert code_of(outcome.reply) == device.FAULT_CODES[fault]
    assert outcome.state.fault == fault


# -- MANUAL and broadcast ----------------------------------------------------------------------

ANY_MESSAGES = [
    *WRITES,
    case("50h", ReadSystem()),
    case("51h", ReadProgram(1)),
    case("52h", ReadPrograms(1, 4)),
    case("bad-id", h("2200")),
    case("empty", b""),
]


@pytest.mark.parametrize("message", ANY_MESSAGES)
@pytest.mark.parametrize("broadcast", [False, True], ids=["addressed", "broadcast"])
def test_manual_neither_answers_nor_changes_anything(message, broadcast):
    state = module(mode="manual")
    outcome = send(state, message, broadcast=broadcast)
    assert outcome.reply is None
    assert outcome.state == state


@pytest.mark.parametrize("message", ANY_MESSAGES)
def test_broadcast_is_processed_and_answered_by_none(message):
    state = marked(STOP)
    addressed = send(state, message)
    broadcast = send(state, message, broadcast=True)
    assert broadcast.reply is None
    assert broadcast.state == addressed.state


def test_a_broadcast_write_changes_the_module():
    outcome = send(marked(STOP), InitProgram(3), broadcast=True)
    assert outcome.reply is None
    assert program(outcome.state, 3) == Program(150, 50)


# -- defaults ------------------------------------------------------------------------------------


def test_10h_sets_the_exact_default_words_and_keeps_s9():
    others = {"S1": 2000, "S2": 300, "S3": 1, "S4": 500, "S5": 100, "S6": 1000, "S7": 800, "S8": 1, "S10": 1,
              "S11": 1, "S12": 50}
    state = module(7, system=others)
    outcome = send(state, InitSystem())
    assert outcome.reply == ACCEPTED
    assert outcome.state.image.system == SystemParameters(
        S1=400, S2=50, S3=754, S4=600, S5=10, S6=1500, S7=1000, S8=0, S10=583, S11=1100, S12=10
    )
    assert send(outcome.state,
                ReadSystem()).reply == h("0190 0032 02F2 0258 000A 05DC 03E8 0007 0247 044C 000A")
    assert outcome.state.address == 7


DEFAULT_PROGRAM_CASES = [
    case("factory-s2-50", {}, Program(150, 50)),
    case("s2-500-s1-9999", {"S1": 9999, "S2": 500}, Program(600, 50)),
    case("s2-300-s1-350-def-pos-is-s1", {"S1": 350, "S2": 300}, Program(350, 50)),
    case("s1-100-def-pos-is-s1", {"S1": 100}, Program(100, 50)),
    case("s1-equals-s2-plus-100", {"S1": 250, "S2": 150}, Program(250, 50)),
    case("s5-60-v-60", {"S5": 60}, Program(150, 60)),
    case("s4-40-v-40", {"S4": 40}, Program(150, 40)),
    case("s4-s5-50", {"S4": 50, "S5": 50}, Program(150, 50)),
]

INITS = [
    case("11h", InitAllPrograms(), range(1, 65)),
    case("12h", InitProgram(10), (10,)),
    case("12h-64", InitProgram(64), (64,)),
    case("13h", InitProgramsFrom(60), range(60, 65)),
    case("13h-1", InitProgramsFrom(1), range(1, 65)),
    case("14h", InitPrograms(3, 5), range(3, 6)),
    case("14h-one", InitPrograms(7, 7), (7,)),
]


@pytest.mark.parametrize(("message", "numbers"), INITS)
@pytest.mark.parametrize(("system", "default"), DEFAULT_PROGRAM_CASES)
def test_init_sets_the_default_program(system, default, message, numbers):
    state = marked(module(system=system))
    outcome = send(state, message)
    assert outcome.reply == ACCEPTED
    for n in range(1, 65):
        assert program(outcome.state, n) == (default if n in numbers else program(state, n)), n
    assert outcome.state.image.system == state.image.system
    assert outcome.state.referenced is True


# -- clamping after 10h and 20h ------------------------------------------------------------------

CLAMP_CASES = [
    case("p-above-new-s1", {"S1": 2000}, Program(1500, 300, 5, 6, 7, 8, 9), {"S1": 1000},
         Program(1000, 300, 5, 6, 7, 8, 9)),
    case("p-equal-new-s1", {"S1": 2000}, Program(1000, 300), {"S1": 1000}, Program(1000, 300)),
    case("v-above-new-s4", {}, Program(100, 590, -5), {"S4": 400}, Program(100, 400, -5)),
    case("v-below-new-s5", {}, Program(100, 15, 0, 9), {"S5": 200}, Program(100, 200, 0, 9)),
    case("both", {"S1": 2000}, Program(1900, 20), {"S1": 500, "S4": 300, "S5": 100}, Program(500, 100)),
    case("inside-untouched", {}, Program(300, 300), {"S1": 300, "S4": 300, "S5": 300}, Program(300, 300)),
]


@pytest.mark.parametrize(("old", "before", "new", "after"), CLAMP_CASES)
def test_20h_clamps_every_program_silently(old, before, new, after):
    state = with_programs(module(system=old), {n: before for n in range(1, 65)})
    outcome = send(state, WriteSystem(replace(state.image.system, **new)))
    assert outcome.reply == ACCEPTED  # not reported
    assert outcome.state.image.programs == (after,) * 64
    assert outcome.state.image.system == replace(state.image.system, **new)


def test_20h_clamps_only_the_programs_outside():
    state = with_programs(module(system={"S1": 2000}), {1: Program(1500, 300), 64: Program(1500, 5)})
    outcome = send(state, WriteSystem(replace(DEFAULT_SYSTEM, S1=1000, S5=20)))
    assert program(outcome.state, 1) == Program(1000, 300)
    assert program(outcome.state, 64) == Program(1000, 20)
    assert outcome.state.image.programs[1:63] == state.image.programs[1:63]


def test_10h_clamps_to_the_defaults():
    state = with_programs(module(system={"S1": 2000, "S5": 1}),
                          {1: Program(1500, 5, 1, 2, 3, 4, 5), 2: Program(300, 600)})
    outcome = send(state, InitSystem())
    assert outcome.reply == ACCEPTED
    assert program(outcome.state, 1) == Program(400, 10, 1, 2, 3, 4, 5)
    assert program(outcome.state, 2) == Program(300, 600)


def test_init_after_20h_uses_the_new_def_pos():
    state = send(STOP, WriteSystem(replace(DEFAULT_SYSTEM, S1=120, S2=60))).state
    assert send(state, InitProgram(1)).state.image.programs[0] == Program(120, 50)


# -- axis release: referenced --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("message", "referenced"),
    [
        case("10h", InitSystem(), False),
        case("20h", WriteSystem(DEFAULT_SYSTEM), False),
        case("20h-rejected", WriteSystem(replace(DEFAULT_SYSTEM, S1=99)), True),
        case("10h-malformed", h("1000 0000"), True),
        case("11h", InitAllPrograms(), True),
        case("21h", WriteProgram(1, GOOD), True),
        case("50h", ReadSystem(), True),
    ],
)
def test_referenced_turns_false_on_an_accepted_10h_or_20h_only(message, referenced):
    assert send(STOP, message).state.referenced is referenced


def test_a_module_keeps_accepting_messages_after_the_release():
    state = send(STOP, InitSystem()).state
    outcome = send(state, WriteProgram(1, GOOD))
    assert outcome.reply == ACCEPTED
    assert outcome.state.referenced is False


# -- link, unlink, addresses ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("message", "expected_a"),
    [
        case("30h-5-8", LinkPrograms(5, 8), {5: 6, 6: 7, 7: 8, 8: 0}),
        case("30h-single", LinkPrograms(7, 7), {7: 0}),
        case("30h-manual-5-48", h("3000 0530"), {**{n: n + 1 for n in range(5, 48)}, 48: 0}),
        case("30h-all", LinkPrograms(1, 64), {**{n: n + 1 for n in range(1, 64)}, 64: 0}),
        case("31h-manual-5-64", h("3100 0540"), {n: 0 for n in range(5, 65)}),
        case("31h-single", UnlinkPrograms(3, 3), {3: 0}),
        case("46h-manual", h("4604 0110 0501 0805 1401"), {1: 16, 5: 1, 8: 5, 20: 1}),
        case("46h-later-wins", WriteAddresses(((5, 9), (6, 1), (5, 12))), {5: 12, 6: 1}),
        case("46h-a-0-and-64", WriteAddresses(((1, 0), (2, 64))), {1: 0, 2: 64}),
    ],
)
def test_jump_addresses(message, expected_a):
    state = marked(STOP)
    outcome = send(state, message)
    assert outcome.reply == ACCEPTED
    for n in range(1, 65):
        before = program(state, n)
        after = program(outcome.state, n)
        assert after == replace(before, A=expected_a.get(n, before.A)), n


# -- 21h, 32h, 33h, 40h..45h ----------------------------------------------------------------------


@pytest.mark.parametrize(("field", "cls"), list(codec.FIELD_MESSAGES.items()), ids=list(codec.FIELD_MESSAGES))
def test_4xh_sets_its_field_only(field, cls):
    state = marked(STOP)
    value = {"P": 222, "V": 333, "Vr": -444, "T": 555, "F1": 1666, "F2": 1777}[field]
    outcome = send(state, cls(((2, value), (40, value))))
    assert outcome.reply == ACCEPTED
    for n in range(1, 65):
        before = program(state, n)
        assert program(outcome.state, n) == (before.with_field(field, value) if n in (2, 40) else before)


@pytest.mark.parametrize(("field", "cls"), list(codec.FIELD_MESSAGES.items()), ids=list(codec.FIELD_MESSAGES))
def test_4xh_duplicate_program_later_item_wins(field, cls):
    outcome = send(marked(STOP), cls(((5, 100), (6, 100), (5, 200))))
    assert outcome.reply == ACCEPTED
    assert getattr(program(outcome.state, 5), field) == 200


def test_21h_writes_the_whole_program_only():
    state = marked(WIDE)
    outcome = send(state, WriteProgram(10, MANUAL_10))
    assert program(outcome.state, 10) == MANUAL_10
    assert outcome.state.image.programs[:9] == state.image.programs[:9]
    assert outcome.state.image.programs[10:] == state.image.programs[10:]


def test_32h_writes_p_and_v_only():
    state = marked(WIDE)
    outcome = send(state, h("3205 041A 012C"))
    assert outcome.reply == ACCEPTED
    assert program(outcome.state, 5) == replace(program(state, 5), P=1050, V=300)


def test_33h_writes_consecutive_programs():
    state = marked(STOP)
    outcome = send(state, WritePartPrograms(62, ((100, 10), (200, 20), (300, 30))))
    assert outcome.reply == ACCEPTED
    assert [(program(outcome.state, n).P, program(outcome.state, n).V) for n in (62, 63, 64)] == [(100, 10),
                                                                                                  (200, 20),
                                                                                                  (300, 30)]
    assert program(outcome.state, 62) == replace(program(state, 62), P=100, V=10)
    assert outcome.state.image.programs[:61] == state.image.programs[:61]


# -- reads ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("address", [1, 17, 30])
def test_50h_reports_s9_as_the_address(address):
    outcome = send(module(address, system={"S8": 1}), ReadSystem())
    assert outcome.reply[14:16] == bytes([1, address])
    assert codec.decode_reply(ReadSystem(), outcome.reply) == codec.SystemReply(replace(DEFAULT_SYSTEM, S8=1),
                                                                                address)


def test_51h_and_52h_the_manuals_reads():
    state = with_programs(
        WIDE,
        {
            4: Program(1050, 300, 53, 20, 1020, 20, 7),
            5: Program(100, 500, 0, 20, 1000, 0, 6),
            6: Program(600, 200, 0, 0, 1000, 0, 7),
        },
    )
    assert send(state, "5106").reply == h("0600 0258 00C8 0000 0000 03E8 0000 0700")
    assert send(state, "5200 0406").reply == h(
        "0400 041A 012C 0035 0014 03FC 0014 0700"
        "0500 0064 01F4 0000 0014 03E8 0000 0600"
        "0600 0258 00C8 0000 0000 03E8 0000 0700"
    )


@pytest.mark.parametrize("count", [1, 2, 3, 4])
def test_52h_reads_one_to_four_programs(count):
    state = marked(STOP)
    message = ReadPrograms(61, 60 + count)
    outcome = send(state, message)
    assert len(outcome.reply) == 16 * count
    reply = codec.decode_reply(message, outcome.reply)
    assert reply.first == 61
    assert reply.programs == state.image.programs[60 : 60 + count]


def test_52h_five_programs_is_15():
    assert send(STOP, "5200 0105").reply == h("0F00")


# -- the state-file entry (docs/files.md "Emulator state")
# -------------------------------------------------------

STATE_FILE_CASES = [
    case("factory", ModuleState.factory(1)),
    case("run-active", marked(replace(module(5), mode="run", active_program=12))),
    case("fault-e12-unreferenced", module(30, fault="E12", referenced=False)),
    case("manual-fault", module(2, mode="manual", fault="fault")),
]


@pytest.mark.parametrize("state", STATE_FILE_CASES)
def test_state_file_entry_round_trips(state):
    entry = json.loads(json.dumps(state.to_json()))
    assert ModuleState.from_json(entry) == state


@pytest.mark.parametrize("state", STATE_FILE_CASES)
def test_state_file_entry_shape(state):
    entry = state.to_json()
    assert set(entry) == {"address", "system", "programs", "mode", "active_program", "fault", "referenced"}
    assert entry["address"] == state.address
    assert set(entry["system"]) == {"S1", "S2", "S3", "S4", "S5", "S6", "S7", "S8", "S10", "S11", "S12"}
    assert len(entry["programs"]) == 64
    assert all(set(p) == {"P", "V", "Vr", "T", "F1", "F2", "A"} for p in entry["programs"])
    assert entry["mode"] in ("stop", "run", "manual")
    assert (entry["mode"], entry["active_program"], entry["fault"], entry["referenced"]) == (
        state.mode, state.active_program, state.fault, state.referenced
    )


def test_state_file_entry_of_the_factory_module():
    entry = ModuleState.factory(3).to_json()
    assert entry["system"] == {
        "S1": 400, "S2": 50, "S3": 754, "S4": 600, "S5": 10, "S6": 1500, "S7": 1000, "S8": 0, "S10": 583,
                               "S11": 1100, "S12": 10
    }
    assert entry["programs"][0] == {"P": 150, "V": 50, "Vr": 0, "T": 0, "F1": 0, "F2": 0, "A": 0}
    assert (entry["mode"], entry["active_program"], entry["fault"], entry["referenced"]) == ("stop", None,
                                                                                             None, True)


def test_a_bare_module_image_reads_as_a_stopped_referenced_module():
    image = ModuleState.factory(4).image.to_json()
    assert ModuleState.from_json(image) == ModuleState.factory(4)


@pytest.mark.parametrize(
    ("changes", "what"),
    [
        case("mode", {"mode": "auto"}, "mode"),
        case("fault", {"fault": "E11"}, "fault"),
        case("active-0", {"active_program": 0}, "active program"),
        case("active-65", {"active_program": 65}, "active program"),
    ],
)
def test_a_bad_state_entry_is_refused(changes, what):
    with pytest.raises(ValueError, match=what):
        ModuleState.from_json({**ModuleState.factory(1).to_json(), **changes})
