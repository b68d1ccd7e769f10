"""The decisions of one exchange as tables of cases (`prc3cfg.core.exchange`): what came back to
an attempt, to a read or a write, on a line with or without a checksum, with attempts left or
none → what the link does next, and what it says; the fault injection's draws → the fault.

The link client and the emulator act on these verdicts; their I/O is tested in tests/test_link.py
and tests/test_emulator.py. Each case here reaches a row (and column) of the tables, and a test
checks that every row is reached.
"""

from __future__ import annotations

import pytest

from prc3cfg.core import codec
from prc3cfg.core.exchange import FAULTS, VERDICTS, Arrival, Fault, LinkStep, answered_as_write, asked, judge
from prc3cfg.core.image import DEFAULT_SYSTEM

READ, WRITE = codec.ReadSystem(), codec.InitSystem()  # 50h, 10h
ADDED = codec.WriteF2(((1, 50),))  # 45h: PRC 3.02.1 added it
DATA = codec.SystemReply(DEFAULT_SYSTEM, 5).encode()  # 50h's reply: 22 bytes
SHORT = bytes(4)  # neither a code word nor 50h's data block

CHECKSUM, NO_CHECKSUM = True, False


def code(number: int) -> bytes:
    return codec.encode_code(number)


# what came, to what, on which line, the code the attempt before asked to confirm, attempts left
#   → what the link does next, and what it says (the log's note, the error's reason)
CASES = [
    # nothing came back: ask again, on every line, to every message
    pytest.param(None, READ, CHECKSUM, None, 3, LinkStep.RETRY, "no reply within 0.5 s",
                 id="nothing to a read"),
    pytest.param(None, WRITE, NO_CHECKSUM, None, 1, LinkStep.RETRY, "no reply within 0.5 s",
                 id="nothing to a write"),
    pytest.param(None, READ, NO_CHECKSUM, None, 0, LinkStep.GIVE_UP, "no reply within 0.5 s",
                 id="nothing on the last attempt"),
    # a reply that is none to what was asked
    pytest.param(SHORT, READ, CHECKSUM, None, 1, LinkStep.RETRY,
                 "bad reply (4 bytes in reply to 50h, expected 22)", id="garbled to a read"),
    pytest.param(DATA, WRITE, NO_CHECKSUM, None, 1, LinkStep.RETRY,
                 "bad reply (22 bytes in reply to 10h, expected 2)",
                 id="a data block to a write is garbled"),
    pytest.param(SHORT, WRITE, CHECKSUM, None, 0, LinkStep.GIVE_UP,
                 "bad reply (4 bytes in reply to 10h, expected 2)",
                 id="garbled on the last attempt"),
    # accepted: a write's answer; to a read, the module executed a damaged frame as a write
    pytest.param(code(0), WRITE, CHECKSUM, None, 3, LinkStep.ANSWER, "", id="a write accepted"),
    pytest.param(code(0), WRITE, NO_CHECKSUM, None, 0, LinkStep.ANSWER, "",
                 id="a write accepted without a checksum, at once"),
    pytest.param(code(0), READ, CHECKSUM, None, 3, LinkStep.POSSIBLE_WRITE, "", id="a read accepted"),
    pytest.param(code(0), READ, NO_CHECKSUM, None, 3, LinkStep.POSSIBLE_WRITE, "",
                 id="a read accepted without a checksum, at once"),
    pytest.param(code(0), READ, NO_CHECKSUM, 20, 0, LinkStep.POSSIBLE_WRITE, "",
                 id="a read accepted after another code"),
    # 10, an unknown message: to a read, firmware without reads — once believed
    pytest.param(code(10), READ, CHECKSUM, None, 3, LinkStep.OLD_FIRMWARE, "",
                 id="a read unknown, with a checksum"),
    pytest.param(code(10), READ, NO_CHECKSUM, None, 3, LinkStep.CONFIRM,
                 "code 10: invalid identification number (ID) on a line without a checksum, asking again to "
                 "confirm it",
                 id="a read unknown, once without a checksum"),
    pytest.param(code(10), READ, NO_CHECKSUM, 10, 2, LinkStep.OLD_FIRMWARE, "",
                 id="a read unknown, twice in a row"),
    pytest.param(code(10), READ, NO_CHECKSUM, 20, 2, LinkStep.CONFIRM,
                 "code 10: invalid identification number (ID) on a line without a checksum, asking again to "
                 "confirm it",
                 id="a read unknown after another code"),
    pytest.param(code(10), READ, NO_CHECKSUM, None, 0, LinkStep.GIVE_UP,
                 "code 10: invalid identification number (ID) on a line without a checksum, asking again to "
                 "confirm it",
                 id="a read unknown once, on the last attempt"),
    # 10 to a write, and 11..15: the module got our message damaged
    pytest.param(code(10), WRITE, CHECKSUM, None, 3, LinkStep.RETRY,
                 "the module reports a damaged message (code 10: invalid identification number (ID))",
                 id="a write unknown"),
    pytest.param(code(10), WRITE, NO_CHECKSUM, 10, 3, LinkStep.RETRY,
                 "the module reports a damaged message (code 10: invalid identification number (ID))",
                 id="a write unknown twice"),
    pytest.param(code(11), READ, CHECKSUM, None, 1, LinkStep.RETRY,
                 "the module reports a damaged message (code 11: invalid length (message shorter "
                 "than 1 byte))", id="damaged 11"),
    pytest.param(code(15), READ, NO_CHECKSUM, 15, 1, LinkStep.RETRY,
                 "the module reports a damaged message (code 15: invalid program number)",
                 id="damaged 15 twice"),
    pytest.param(code(13), WRITE, CHECKSUM, None, 1, LinkStep.RETRY,
                 "the module reports a damaged message (code 13: data block not complete (message shorter "
                 "than its data block))",
                 id="a write damaged 13"),
    pytest.param(code(14), WRITE, NO_CHECKSUM, None, 0, LinkStep.GIVE_UP,
                 "the module reports a damaged message (code 14: data block too long (message longer than "
                 "its data block))",
                 id="damaged on the last attempt"),
    # any other code: the module's answer — on a line without a checksum once it came twice in a row
    pytest.param(code(20), WRITE, CHECKSUM, None, 3, LinkStep.ANSWER, "",
                 id="a write refused, with a checksum"),
    pytest.param(code(20), WRITE, NO_CHECKSUM, None, 3, LinkStep.CONFIRM,
                 "code 20: operating condition is not STOP: system parameters can only be changed in STOP "
                 "on a line without a checksum, "
                 "asking again to confirm it", id="a write refused once, without a checksum"),
    pytest.param(code(20), WRITE, NO_CHECKSUM, 20, 2, LinkStep.ANSWER, "", id="a write refused "
                                                                              "twice in a row"),
    pytest.param(code(20), WRITE, NO_CHECKSUM, 21, 2, LinkStep.CONFIRM,
                 "code 20: operating condition is not STOP: system parameters can only be changed in STOP "
                 "on a line without a checksum, "
                 "asking again to confirm it", id="a write refused after another code"),
    pytest.param(code(200), WRITE, NO_CHECKSUM, None, 0, LinkStep.GIVE_UP,
                 "unknown code 200 on a line without a checksum, asking again to confirm it",
                 id="refused once, on the last attempt"),
    pytest.param(code(16), READ, CHECKSUM, None, 3, LinkStep.ANSWER, "", id="a read refused, with "
                                                                            "a checksum"),
    pytest.param(code(16), READ, NO_CHECKSUM, None, 3, LinkStep.CONFIRM,
                 "code 16: program is active: its data cannot be written while it runs on a line without a "
                 "checksum, "
                 "asking again to confirm it", id="a read refused once, without a checksum"),
    pytest.param(code(16), READ, NO_CHECKSUM, 16, 0, LinkStep.ANSWER, "",
                 id="a read refused twice, on the last attempt"),
    # a data block: a read's answer, at once
    pytest.param(DATA, READ, CHECKSUM, None, 3, LinkStep.ANSWER, "", id="data to a read"),
    pytest.param(DATA, READ, NO_CHECKSUM, 20, 0, LinkStep.ANSWER, "",
                 id="data to a read without a checksum, after a code"),
    # a write a later firmware added: as any write, but 10 is that older firmware, never damage
    pytest.param(None, ADDED, CHECKSUM, None, 1, LinkStep.RETRY, "no reply within 0.5 s",
                 id="nothing to 45h"),
    pytest.param(SHORT, ADDED, NO_CHECKSUM, None, 1, LinkStep.RETRY,
                 "bad reply (4 bytes in reply to 45h, expected 2)", id="garbled to 45h"),
    pytest.param(code(0), ADDED, NO_CHECKSUM, None, 1, LinkStep.ANSWER, "", id="45h accepted"),
    pytest.param(code(10), ADDED, CHECKSUM, None, 3, LinkStep.OLD_FIRMWARE, "",
                 id="45h unknown, with a checksum"),
    pytest.param(code(10), ADDED, NO_CHECKSUM, None, 3, LinkStep.CONFIRM,
                 "code 10: invalid identification number (ID) on a line without a checksum, asking again to "
                 "confirm it", id="45h unknown, once without a checksum"),
    pytest.param(code(10), ADDED, NO_CHECKSUM, 10, 2, LinkStep.OLD_FIRMWARE, "",
                 id="45h unknown, twice in a row"),
    pytest.param(code(12), ADDED, CHECKSUM, None, 1, LinkStep.RETRY,
                 "the module reports a damaged message (code 12: invalid length (message longer than 64 "
                 "bytes))", id="45h damaged 12"),
    pytest.param(code(25), ADDED, CHECKSUM, None, 1, LinkStep.ANSWER, "",
                 id="45h refused, with a checksum"),
    pytest.param(code(25), ADDED, NO_CHECKSUM, None, 1, LinkStep.CONFIRM,
                 "code 25: operating condition is error E21 (positioning error) on a line without a "
                 "checksum, asking again to confirm it", id="45h refused once, without a checksum"),
]


def verdict_of(raw, message, checked, heard, left):
    return judge(message, raw, checked=checked, heard=heard, attempts_left=left, timeout=0.5)


@pytest.mark.parametrize(("raw", "message", "checked", "heard", "left", "step", "problem"), CASES)
def test_the_verdict_on_an_attempt(raw, message, checked, heard, left, step, problem):
    verdict = verdict_of(raw, message, checked, heard, left)
    assert (verdict.step, verdict.problem) == (step, problem)
    if step is LinkStep.ANSWER:
        assert verdict.reply == codec.decode_reply(message, raw)  # the answer is the reply, decoded
    if step is LinkStep.CONFIRM:
        assert verdict.unconfirmed == raw[0]  # the next attempt confirms this code
    else:
        assert verdict.unconfirmed is None


def test_the_cases_reach_every_row_and_column_of_the_verdicts():
    """Every (what came back, to what) row of `VERDICTS`, and where its columns differ, both: believed
    (a checksum, or the code the attempt before asked to confirm) and heard once."""
    reached = set()
    for case in CASES:
        raw, message, checked, heard, left, _, _ = case.values
        verdict = verdict_of(raw, message, checked, heard, left)
        believed = checked or (heard is not None and verdict.reply == heard)
        reached.add((verdict.arrival, asked(message), believed))
    for (came, kind), steps in VERDICTS.items():
        columns = {believed for c, a, believed in reached if (c, a) == (came, kind)}
        assert columns, f"no case of {came} to a {kind.value}"
        if steps.believed is not steps.heard_once:
            assert columns == {True, False}, f"{came} to a {kind.value}: one column without a case"
    assert {came for came, _, _ in reached} == set(Arrival)  # every kind of arrival, made from bytes


def test_a_code_heard_once_is_confirmed_by_the_next_attempt_alone():
    """The link's loop on a line without a checksum: 20, then 21, then 21 — the third believed."""
    steps, heard = [], None
    for left, raw in zip((3, 2, 1), (code(20), code(21), code(21))):
        verdict = verdict_of(raw, WRITE, NO_CHECKSUM, heard, left)
        steps.append(verdict.step)
        heard = verdict.unconfirmed
    assert steps == [LinkStep.CONFIRM, LinkStep.CONFIRM, LinkStep.ANSWER]
    assert verdict.reply == 21


# the fault injection's draws: lost, damaged, on the request's side → the fault
FAULT_CASES = [
    pytest.param(False, False, False, Fault.NONE, id="clean"),
    pytest.param(True, False, True, Fault.REQUEST_LOST, id="request lost"),
    pytest.param(True, True, True, Fault.REQUEST_LOST, id="request lost and damaged: lost"),
    pytest.param(False, True, True, Fault.REQUEST_DAMAGED, id="request damaged"),
    pytest.param(True, False, False, Fault.REPLY_LOST, id="reply lost"),
    pytest.param(True, True, False, Fault.REPLY_LOST, id="reply lost and damaged: lost"),
    pytest.param(False, True, False, Fault.REPLY_DAMAGED, id="reply damaged"),
]


@pytest.mark.parametrize(("lost", "damaged", "request_side", "fault"), FAULT_CASES)
def test_the_fault_an_exchange_meets(lost, damaged, request_side, fault):
    assert FAULTS[lost, damaged, request_side] is fault


def test_the_fault_cases_are_every_row_and_every_fault():
    assert {case.values[:3] for case in FAULT_CASES} == set(FAULTS)
    assert {case.values[3] for case in FAULT_CASES} == set(Fault)
    assert (False, False, True) not in FAULTS  # no side is drawn when nothing is due


def test_a_read_answered_as_a_write_is_the_table_s_possible_write_for_every_message():
    """`answered_as_write`, which the lines' observers record as an axis release, decides by the verdicts: an
    acknowledgement to any read, nothing else — a data block, another code, no reply, bytes no message is."""
    reads = [codec.ReadSystem(), codec.ReadPrograms(1, 4)]
    writes = [codec.InitSystem(), codec.WriteSpeeds(((7, 100),))]
    for message in reads + writes:
        request = message.encode()
        assert answered_as_write(request, codec.encode_code(0)) is message.IS_READ, message
        assert not answered_as_write(request, None) and not answered_as_write(request, codec.encode_code(21))
    assert not answered_as_write(b"\x99\x00", codec.encode_code(0))
