"""One exchange on the line, as data: what the link makes of what came back to a message, and
what the emulator's fault injection does to an exchange on its way.

Every decision is in the tables at the top of this file, as h11's `_state.py` keeps its
transitions: `VERDICTS` — what came back to one attempt, to a read or to a write, believed or
heard once, and what the link does next (take the answer, ask again, or stop); `FAULTS` — which
frame of an exchange the emulator loses or damages. The link client (`Link.request`, `Link.probe`)
and the emulator server (`Emulator.exchange`) only send, read, wait and act on what these say.

The rules the verdicts keep:
- every PRC 3 message is idempotent (an absolute write or a read): a lost reply, one that does
  not decode, and a structural error code (11..15, and 10 to a write: we only send messages the
  codec built, so the module saw ours damaged on the line) are asked for again;
- a read answered with an acknowledgement: nothing more may be sent on the line, and it is never
  asked again; its likeliest cause (`ACK_TO_READ`) is by the line's protection (`Protection`) and by
  what was seen: the late acknowledgement of a write to that module that went unanswered at first,
  a duplicated one (a checksum rules damage out), or a damaged frame the module executed as a write;
- a message some firmware lacks (`FIRMWARE_ADDED`: 45h came with PRC 3.02.1, the reads with 3.03.1)
  answered as an unknown message (10) is that older firmware, never damage to ask again about;
- on a framing without a checksum (open-driver) a damaged reply can look like any code: an
  error code there is believed only when the module gives the same one twice in a row (asking
  again is harmless: the message is idempotent);
- a step that asks again gives up on the last attempt (`GIVE_UP`), naming what went wrong last.

Does not own what the messages and the codes mean (`codec`, `error_codes`), how frames look or
what is left of a damaged one (`framing`), nor the port, the clock or the random draws: the
shell's.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Final, NamedTuple

from prc3cfg.core import codec
from prc3cfg.core.error_codes import ACCEPTED, describe
from prc3cfg.core.framing import Framing

#: Codes of the structural checks (docs/protocol.md "What a module does" steps 1–5): to us, damage on the
#: line.
DAMAGED_CODES: Final = frozenset(range(10, 16))
# damage — or, to a message of `FIRMWARE_ADDED`, firmware older than the one that added it
UNKNOWN_ID: Final = 10

#: The messages a firmware after the first added (the manual's version table: PRC 3.01.1 had neither),
#: by ID: the version that added it, and what it is, as said to a person.
FIRMWARE_ADDED: Final[dict[int, tuple[str, str]]] = {
    0x45: ("3.02.1", "function outputs F2"),  # "PRC 3.02.1 February 1994 Function Output 2 (End)"
    0x50: ("3.03.1", "read messages"),  # "PRC 3.03.1 June 1994 Read Data Blocks interface"
    0x51: ("3.03.1", "read messages"),
    0x52: ("3.03.1", "read messages"),
}


class Arrival(enum.Enum):
    """What came back to one attempt, as the link sorts it."""

    # no reply from the module asked within the time-out (others' replies, damaged frames: ignored)
    NOTHING = "nothing"
    GARBLED = "garbled"  # a reply that is not one to what was asked (`codec.BadReply`)
    ACCEPTED = "accepted"  # code 0
    UNKNOWN_ID = "unknown ID"  # code 10
    DAMAGED = "damaged"  # codes 11..15: the module reports our message damaged
    REFUSED = "refused"  # any other code: the module will not do it (not in STOP, a fault, …)
    DATA = "data"  # a data block: what a read asks for


class Asked(enum.Enum):
    READ = "read"  # 50h..52h
    WRITE = "write"  # every write every firmware has
    ADDED = "added write"  # a write a later firmware added (`FIRMWARE_ADDED`: 45h)


def asked(message: codec.Message) -> Asked:
    """What `message` is, to the verdicts."""
    if message.IS_READ:
        return Asked.READ
    return Asked.ADDED if message.ID in FIRMWARE_ADDED else Asked.WRITE


class LinkStep(enum.Enum):
    """What the link does next."""

    ANSWER = "answer"  # the reply is the module's answer
    RETRY = "retry"  # lost or damaged: ask again
    CONFIRM = "confirm"  # a code heard once on a line without a checksum: ask again, believe it heard twice
    POSSIBLE_WRITE = "possible write"  # stop the line (`PossibleWrite`)
    OLD_FIRMWARE = "old firmware"  # stop: the firmware predates the message (`OldFirmware`, `NoReadMessages`)
    GIVE_UP = "give up"  # a retry or a confirmation with no attempt left (`LinkError`)


class Steps(NamedTuple):
    believed: LinkStep  # on a framing with a checksum, or the code the attempt before asked to confirm
    heard_once: LinkStep  # on a framing without one, not (yet) given twice in a row


#: What the link does with what came back to one attempt, by what it was, whether the message
#: was a read, and whether what came is believed (`Steps`).
VERDICTS: Final[dict[tuple[Arrival, Asked], Steps]] = {
    # what came back     to a                believed                   heard once, no checksum
    (Arrival.NOTHING,    Asked.READ):  Steps(LinkStep.RETRY,            LinkStep.RETRY),
    (Arrival.NOTHING,    Asked.WRITE): Steps(LinkStep.RETRY,            LinkStep.RETRY),
    (Arrival.GARBLED,    Asked.READ):  Steps(LinkStep.RETRY,            LinkStep.RETRY),
    (Arrival.GARBLED,    Asked.WRITE): Steps(LinkStep.RETRY,            LinkStep.RETRY),
    (Arrival.ACCEPTED,   Asked.READ):  Steps(LinkStep.POSSIBLE_WRITE,   LinkStep.POSSIBLE_WRITE),
    (Arrival.ACCEPTED,   Asked.WRITE): Steps(LinkStep.ANSWER,           LinkStep.ANSWER),
    (Arrival.UNKNOWN_ID, Asked.READ):  Steps(LinkStep.OLD_FIRMWARE,     LinkStep.CONFIRM),
    (Arrival.UNKNOWN_ID, Asked.WRITE): Steps(LinkStep.RETRY,            LinkStep.RETRY),
    (Arrival.DAMAGED,    Asked.READ):  Steps(LinkStep.RETRY,            LinkStep.RETRY),
    (Arrival.DAMAGED,    Asked.WRITE): Steps(LinkStep.RETRY,            LinkStep.RETRY),
    (Arrival.REFUSED,    Asked.READ):  Steps(LinkStep.ANSWER,           LinkStep.CONFIRM),
    (Arrival.REFUSED,    Asked.WRITE): Steps(LinkStep.ANSWER,           LinkStep.CONFIRM),
    (Arrival.DATA,       Asked.READ):  Steps(LinkStep.ANSWER,           LinkStep.ANSWER),
    # a write a later firmware added: as any write, but for the code that says the firmware predates it
    (Arrival.NOTHING,    Asked.ADDED): Steps(LinkStep.RETRY,            LinkStep.RETRY),
    (Arrival.GARBLED,    Asked.ADDED): Steps(LinkStep.RETRY,            LinkStep.RETRY),
    (Arrival.ACCEPTED,   Asked.ADDED): Steps(LinkStep.ANSWER,           LinkStep.ANSWER),
    (Arrival.UNKNOWN_ID, Asked.ADDED): Steps(LinkStep.OLD_FIRMWARE,     LinkStep.CONFIRM),
    (Arrival.DAMAGED,    Asked.ADDED): Steps(LinkStep.RETRY,            LinkStep.RETRY),
    (Arrival.REFUSED,    Asked.ADDED): Steps(LinkStep.ANSWER,           LinkStep.CONFIRM),
    # a data block to a write does not decode (a write's reply is a code): GARBLED
}
#: The steps that ask again: on the last attempt, the link gives up instead (`LinkStep.GIVE_UP`).
ASK_AGAIN: Final = frozenset({LinkStep.RETRY, LinkStep.CONFIRM})
#: What is wrong with a code the link asks again about, by why it asks.
CODE_PROBLEMS: Final = {
    LinkStep.RETRY: "the module reports a damaged message ({code})",
    LinkStep.CONFIRM: "{code} on a line without a checksum, asking again to confirm it",
}


class Protection(enum.Enum):
    """What keeps a damaged frame from being taken for another on a line."""

    CHECKSUM = "checksum"  # crc16, stx: a damaged frame is discarded
    # open-driver, the port refusing a character of bad parity: one flipped bit is caught, two are not
    PARITY = "parity"
    NONE = "none"  # open-driver without a parity the port checks: a damaged frame can be any other


def protection(framing: Framing, *, parity_checked: bool) -> Protection:
    """The line's protection: the framing's checksum, else the parity its port checks
    (`platform.check_parity`)."""
    if framing.checked:
        return Protection.CHECKSUM
    return Protection.PARITY if parity_checked else Protection.NONE


class Cause(NamedTuple):
    """What most likely made a module answer a read as a write is answered, and what to do."""

    likeliest: str  # "{write}" and "{owed}": the write that went unanswered, how many
    also: str  # what else it may be ("" where nothing else is likely)
    remedy: str


_LATE = ("the late acknowledgement of {owed} to it ({write}) that went unanswered at first — it executed, "
         "as the retry did")
_DUPLICATE = ("a duplicated acknowledgement: a write to it delivered twice, or held and delivered after its "
              "retry, by something "
              "on the line (a gateway, a converter, a radio link)")
_DAMAGE = ("a damaged frame the module took for a write and executed, which may have changed any value or "
           "released its axes (10h/20h)")
_SLOW_PARTS = "find what on the line holds or repeats frames"
#: The likeliest cause of a read answered with an acknowledgement, by the line's protection and by
#: whether a write to that module went unanswered since its last data reply (`Link.owed`).
ACK_TO_READ: Final[dict[tuple[Protection, bool], Cause]] = {
    (Protection.CHECKSUM, True):  Cause(_LATE, "", _SLOW_PARTS),
    (Protection.CHECKSUM, False): Cause(_DUPLICATE, "", _SLOW_PARTS),
    (Protection.PARITY, True):    Cause(_LATE, "or, less likely, " + _DAMAGE
                                        + " with two bits flipped, which parity misses", _SLOW_PARTS),
    (Protection.PARITY, False):   Cause(_DUPLICATE, "or, less likely, " + _DAMAGE
                                        + " with two bits flipped, which parity misses",
                                        _SLOW_PARTS),
    (Protection.NONE, True):      Cause(_LATE, "or, as likely on a line without a checksum or parity, "
                                        + _DAMAGE,
                                        "use parity on the line, and " + _SLOW_PARTS),
    (Protection.NONE, False):     Cause(_DAMAGE, "or a duplicated acknowledgement", "use parity on the line"),
}


class Fault(enum.Enum):
    """What the line does to one exchange, as the emulator's fault injection plays it."""

    NONE = "none"
    REQUEST_LOST = "request lost"  # no module hears it: silence
    REQUEST_DAMAGED = "request damaged"  # a bit flipped: what the modules' receivers make of it
    REPLY_LOST = "reply lost"  # the module did it, the master hears nothing
    REPLY_DAMAGED = "reply damaged"  # the module did it, its reply has a bit flipped


#: The fault an exchange meets, by the fault injection's draws: lost (the drop rate's), damaged
#: (the corrupt rate's), and — drawn only when either is due — on the request's side rather than
#: the reply's. Both due: lost, as a frame that never arrives cannot arrive damaged.
FAULTS: Final[dict[tuple[bool, bool, bool], Fault]] = {
    # lost   damaged  the request's
    (False, False, False): Fault.NONE,
    (True, False, True): Fault.REQUEST_LOST,
    (True, True, True): Fault.REQUEST_LOST,
    (False, True, True): Fault.REQUEST_DAMAGED,
    (True, False, False): Fault.REPLY_LOST,
    (True, True, False): Fault.REPLY_LOST,
    (False, True, False): Fault.REPLY_DAMAGED,
}


Reply = int | codec.SystemReply | codec.ProgramsReply


@dataclass(frozen=True, slots=True)
class Verdict:
    """What came back to one attempt, and what the link does next."""

    arrival: Arrival
    step: LinkStep
    reply: Reply | None = None  # the reply decoded (None: nothing came, or it did not decode)
    problem: str = ""  # what went wrong, when the link asks again or gives up: for the log and the error

    @property
    def unconfirmed(self) -> int | None:
        """The code the next attempt is to confirm (heard once on a line without a checksum)."""
        return self.reply if self.step is LinkStep.CONFIRM and isinstance(self.reply, int) else None


def arrival(reply: Reply) -> Arrival:
    """What a decoded reply is, to the verdicts."""
    if not isinstance(reply, int):
        return Arrival.DATA
    if reply == ACCEPTED:
        return Arrival.ACCEPTED
    if reply == UNKNOWN_ID:
        return Arrival.UNKNOWN_ID
    return Arrival.DAMAGED if reply in DAMAGED_CODES else Arrival.REFUSED


def answered_as_write(request: bytes, raw: bytes | None) -> bool:
    """Whether `raw`, the reply message to the message `request`, says the module executed it as a write — a
    read answered with an acknowledgement — by the verdicts' table (`LinkStep.POSSIBLE_WRITE`); what a journal
    or an observer of the line decides with the link alike."""
    try:
        message = codec.decode_message(request)
    except codec.Rejected:
        return False  # no message of ours: nothing the link sends
    return judge(message, raw, checked=True, heard=None, attempts_left=1,
                 timeout=0.0).step is LinkStep.POSSIBLE_WRITE


def judge(message: codec.Message, raw: bytes | None, *, checked: bool, heard: int | None, attempts_left: int,
          timeout: float) -> Verdict:
    """The verdict on one attempt of `message`, whose reply message was `raw` (None: nothing
    within `timeout` seconds). `checked`: the framing has a checksum; `heard`: the code the attempt
    before asks to confirm (`Verdict.unconfirmed`); `attempts_left`: how many may follow this one."""
    reply: Reply | None = None
    if raw is None:
        came, problem = Arrival.NOTHING, f"no reply within {timeout:g} s"
    else:
        try:
            reply = codec.decode_reply(message, raw)
        except codec.BadReply as error:
            came, problem = Arrival.GARBLED, f"bad reply ({error})"
        else:
            came, problem = arrival(reply), ""
    steps = VERDICTS[came, asked(message)]
    step = steps.believed if checked or (heard is not None and reply == heard) else steps.heard_once
    if isinstance(reply, int) and step in CODE_PROBLEMS:
        problem = CODE_PROBLEMS[step].format(code=describe(reply))
    if step in ASK_AGAIN and attempts_left <= 0:
        step = LinkStep.GIVE_UP
    return Verdict(came, step, reply, problem)
