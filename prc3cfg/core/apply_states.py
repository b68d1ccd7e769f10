"""What one module's apply does next: its states, the events that move it, and every transition.

Everything that decides a module's course through an apply lives here, in the table at the top —
whether its steps go on, when it is read back, when it is repaired, when a refusal is final,
when it gives up — and `prc3cfg.shell.apply.ModuleRun` only does what it says: it sends, reads,
plans a repair, and tells the table what happened (h11's `_state.py` keeps HTTP's this way).

A module begins `WRITING` its own steps (the bus's broadcasts went before them, to every module at
once). Every way the writing ends but Ctrl-C leads to a verifying read-back: `VERIFYING` compares
it with the plant file and plans a repair of what differs; `REPAIRING` sends that repair, and
the read-back follows again. A module that answered an error code is `REFUSED`: read back once
more, for the account — the refusal stands unless the read-back shows it as the plant file wants
it — and never repaired. It ends `VERIFIED`, `FAILED` or `INTERRUPTED`.

Two budgets bound the rounds, and take a transition of their own when spent (h11's
"state-triggered" transitions): `ROUNDS` verifying reads (a `NO_REPLY` one counts), `REPAIRS` repairs.

Does not own what is read (`prc3cfg.core.what_to_read`), what a repair writes (`prc3cfg.core.planner`)
nor what the account says (`prc3cfg.core.render`); the failure's words are the shell's, from the
event. Pure.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from prc3cfg.core.error_codes import ACCEPTED


class State(enum.Enum):
    """Where a module's apply is."""

    WRITING = "writing"  # its own steps go out, one by one
    VERIFYING = "verifying"  # read back; a difference is planned as a repair
    REPAIRING = "repairing"  # a repair's steps go out
    REFUSED = "refused"  # it answered an error code: read back for the account, never repaired
    VERIFIED = "verified"
    FAILED = "failed"
    INTERRUPTED = "interrupted"  # Ctrl-C (or nothing could be sent to it)


class Event(enum.Enum):
    """What happened: a write's reply, a read-back's finding, a repair planned, Ctrl-C, a line stopped."""

    ACKNOWLEDGED = "acknowledged"  # a write answered 0
    E12 = "E12"  # a write answered 23 (system parameters not set): every write but 10h/20h is refused
    RUNNING = "running"  # a write answered 16 or 20: the module is not in STOP, it may be moving
    ERROR_CODE = "error code"  # a write answered any other code
    #: … from a module that received broadcasts: a lost broadcast (none is answered) may be the cause
    ERROR_CODE_AFTER_BROADCAST = "error code after broadcast"
    ALL_SENT = "all sent"  # every step acknowledged
    NO_REPLY = "no reply"  # an exchange (write or read) lost or damaged after every retry
    AGREES = "agrees"  # the read-back shows the plant file's image
    TRESPASSED = "trespassed"  # … and a program the plant does not manage other than before
    DIFFERS = "differs"
    READ_REFUSED = "read refused"  # a read answered an error code, or another module answered it
    REPAIR_PLANNED = "repair planned"
    #: the repair would release the axes (10h/20h) of a module whose release the plan agreed to did not
    REPAIR_UNCONSENTED = "repair unconsented"
    NO_ROUND_LEFT = "no round left"  # the budgets' own events, given by `Course.after`
    NO_REPAIR_LEFT = "no repair left"
    CANCELLED = "cancelled"  # Ctrl-C, before an exchange or between its attempts
    LINE_STOPPED = "line stopped"  # a module of the line executed a damaged frame: nothing more is sent on it


class Next(enum.Enum):
    """What the shell does next."""

    SEND = "send"  # the next step (the plan's own, or the repair's)
    READ = "read"  # a verifying read-back
    PLAN_REPAIR = "plan a repair"
    GIVE_UP = "give up"  # done, not verified after every round: say so
    STOP = "stop"  # done: verified, or `failure` says why not


#: Every transition: state → event → (next state, action). A pair not here cannot happen (`NoTransition`).
TRANSITIONS: dict[State, dict[Event, tuple[State, Next]]] = {
    State.WRITING: {
        Event.ACKNOWLEDGED: (State.WRITING, Next.SEND),
        Event.ALL_SENT: (State.VERIFYING, Next.READ),
        # every PRC 3 message is idempotent: read back, and send again whatever still differs
        Event.NO_REPLY: (State.VERIFYING, Next.READ),
        # final, unless a lost broadcast explains it: the read-back and an addressed repair get
        # their chance first
        Event.ERROR_CODE_AFTER_BROADCAST: (State.VERIFYING, Next.READ),
        Event.ERROR_CODE: (State.REFUSED, Next.READ),
        # only a 10h/20h clears E12, and this plan has none for it: the next plan writes the system first
        Event.E12: (State.REFUSED, Next.READ),
        # it moves: none of its steps may go now, nor be repeated in a loop
        Event.RUNNING: (State.REFUSED, Next.READ),
        Event.CANCELLED: (State.INTERRUPTED, Next.STOP),
        Event.LINE_STOPPED: (State.FAILED, Next.STOP),
    },
    State.VERIFYING: {
        Event.AGREES: (State.VERIFIED, Next.STOP),
        Event.TRESPASSED: (State.FAILED, Next.STOP),  # no plan may write those programs: nothing to repair
        Event.DIFFERS: (State.VERIFYING, Next.PLAN_REPAIR),
        Event.REPAIR_PLANNED: (State.REPAIRING, Next.SEND),
        # it needs a plan of its own, shown and agreed to
        Event.REPAIR_UNCONSENTED: (State.FAILED, Next.STOP),
        Event.NO_REPLY: (State.VERIFYING, Next.READ),  # the next round reads again
        Event.READ_REFUSED: (State.FAILED, Next.STOP),
        Event.NO_ROUND_LEFT: (State.FAILED, Next.GIVE_UP),
        Event.NO_REPAIR_LEFT: (State.FAILED, Next.GIVE_UP),
        Event.CANCELLED: (State.INTERRUPTED, Next.STOP),
        Event.LINE_STOPPED: (State.FAILED, Next.STOP),
    },
    State.REPAIRING: {
        Event.ACKNOWLEDGED: (State.REPAIRING, Next.SEND),
        Event.ALL_SENT: (State.VERIFYING, Next.READ),
        Event.NO_REPLY: (State.VERIFYING, Next.READ),
        # a repair is addressed: no lost broadcast explains its refusal
        Event.ERROR_CODE_AFTER_BROADCAST: (State.REFUSED, Next.READ),
        Event.ERROR_CODE: (State.REFUSED, Next.READ),
        Event.E12: (State.REFUSED, Next.READ),
        Event.RUNNING: (State.REFUSED, Next.READ),
        Event.CANCELLED: (State.INTERRUPTED, Next.STOP),
        Event.LINE_STOPPED: (State.FAILED, Next.STOP),
    },
    State.REFUSED: {
        Event.AGREES: (State.VERIFIED, Next.STOP),  # the read-back shows the plant file's image all the same
        Event.TRESPASSED: (State.FAILED, Next.STOP),
        Event.DIFFERS: (State.FAILED, Next.STOP),  # the refusal stands: the failure names it
        Event.NO_REPLY: (State.REFUSED, Next.READ),
        Event.READ_REFUSED: (State.FAILED, Next.STOP),
        Event.NO_ROUND_LEFT: (State.FAILED, Next.STOP),
        Event.CANCELLED: (State.INTERRUPTED, Next.STOP),
        Event.LINE_STOPPED: (State.FAILED, Next.STOP),
    },
    State.VERIFIED: {},
    State.FAILED: {
        Event.LINE_STOPPED: (State.FAILED, Next.STOP),  # the line's stop is what the account says of it
    },
    State.INTERRUPTED: {
        Event.LINE_STOPPED: (State.INTERRUPTED, Next.STOP),
    },
}

#: Repairs of one module, at most.
REPAIRS = 2
#: Verifying rounds of one module, at most: a read-back before each repair and one after the last.
ROUNDS = REPAIRS + 1

#: The codes of a module that is not in STOP (program active, not in STOP: §4.4): it takes writes to
#: its other programs, so an apply would change the stroke of a moving machine — it is left alone.
NOT_IN_STOP = frozenset({16, 20})
SYSTEM_UNSET = 23  # E12: every write but 10h/20h refused

#: A write's reply (a code word), as an event; any code not here is an `ERROR_CODE`.
REPLIES: dict[int, Event] = ({ACCEPTED: Event.ACKNOWLEDGED, SYSTEM_UNSET: Event.E12}
                              | dict.fromkeys(NOT_IN_STOP, Event.RUNNING))


class NoTransition(ValueError):
    """An event the table has no transition for in the state: the shell drove the apply wrong."""

    def __init__(self, state: State, event: Event) -> None:
        super().__init__(f"no transition for {event.name} in {state.name}")
        self.state, self.event = state, event


@dataclass(frozen=True, slots=True)
class Course:
    """One module's apply so far: its state, what the shell does next, and the verifying rounds and
    repairs it has had."""

    state: State = State.WRITING
    action: Next = Next.SEND
    rounds: int = 0
    repairs: int = 0

    def after(self, event: Event) -> Course:
        """The table's transition for `event`; then, where the next action would take a round or a
        repair more than the budget allows, the budget's (`NO_ROUND_LEFT`, `NO_REPAIR_LEFT`)."""
        try:
            state, action = TRANSITIONS[self.state][event]
        except KeyError:
            raise NoTransition(self.state, event) from None
        repairs = self.repairs + (event is Event.REPAIR_PLANNED)
        if action is Next.READ and self.rounds == ROUNDS:
            return Course(state, action, self.rounds, repairs).after(Event.NO_ROUND_LEFT)
        if action is Next.PLAN_REPAIR and repairs == REPAIRS:
            return Course(state, action, self.rounds, repairs).after(Event.NO_REPAIR_LEFT)
        return Course(state, action, self.rounds + (action is Next.READ), repairs)


class Coursed:
    """What a module's course says of it, for whatever holds one as `course`: the run while it goes on
    (`prc3cfg.shell.apply.ModuleRun`) and the outcome it leaves (`prc3cfg.core.outcome.ModuleOutcome`)."""

    __slots__ = ()
    course: Course

    @property
    def verified(self) -> bool:
        return self.course.state is State.VERIFIED

    @property
    def interrupted(self) -> bool:
        return self.course.state is State.INTERRUPTED

    @property
    def repairs(self) -> int:
        return self.course.repairs


def reply_event(code: int, *, after_broadcast: bool) -> Event:
    """A write's reply as an event; `after_broadcast`: the module received the bus's broadcasts."""
    if code in REPLIES:
        return REPLIES[code]
    return Event.ERROR_CODE_AFTER_BROADCAST if after_broadcast else Event.ERROR_CODE


def repair_event(releases_axes: bool, consented: bool) -> Event:
    """A repair planned goes out unless it would release the axes (10h/20h) of a module whose release
    the operator did not agree to with the plan shown (`consented`)."""
    return Event.REPAIR_UNCONSENTED if releases_axes and not consented else Event.REPAIR_PLANNED
