"""What one module's apply does next (`prc3cfg.core.apply_states`), as tables of cases: every
transition, every pair the table refuses, the budgets of rounds and repairs, whole courses of an
apply from the first step to its end, and what a write's reply and a repair's consent are to it."""

from __future__ import annotations

import itertools

import pytest

from prc3cfg.core.apply_states import (
    REPAIRS,
    ROUNDS,
    TRANSITIONS,
    Course,
    Event,
    Next,
    NoTransition,
    State,
    repair_event,
    reply_event,
)
from prc3cfg.core.error_codes import ERROR_CODES

S, E, N = State, Event, Next

#: (state, event) → (next state, action): one case for every transition, written out again by hand.
CASES = [
    (S.WRITING, E.ACKNOWLEDGED, S.WRITING, N.SEND),
    (S.WRITING, E.ALL_SENT, S.VERIFYING, N.READ),
    (S.WRITING, E.NO_REPLY, S.VERIFYING, N.READ),
    (S.WRITING, E.ERROR_CODE_AFTER_BROADCAST, S.VERIFYING, N.READ),
    (S.WRITING, E.ERROR_CODE, S.REFUSED, N.READ),
    (S.WRITING, E.E12, S.REFUSED, N.READ),
    (S.WRITING, E.RUNNING, S.REFUSED, N.READ),
    (S.WRITING, E.CANCELLED, S.INTERRUPTED, N.STOP),
    (S.WRITING, E.LINE_STOPPED, S.FAILED, N.STOP),
    (S.VERIFYING, E.AGREES, S.VERIFIED, N.STOP),
    (S.VERIFYING, E.TRESPASSED, S.FAILED, N.STOP),
    (S.VERIFYING, E.DIFFERS, S.VERIFYING, N.PLAN_REPAIR),
    (S.VERIFYING, E.REPAIR_PLANNED, S.REPAIRING, N.SEND),
    (S.VERIFYING, E.REPAIR_UNCONSENTED, S.FAILED, N.STOP),
    (S.VERIFYING, E.NO_REPLY, S.VERIFYING, N.READ),
    (S.VERIFYING, E.READ_REFUSED, S.FAILED, N.STOP),
    (S.VERIFYING, E.NO_ROUND_LEFT, S.FAILED, N.GIVE_UP),
    (S.VERIFYING, E.NO_REPAIR_LEFT, S.FAILED, N.GIVE_UP),
    (S.VERIFYING, E.CANCELLED, S.INTERRUPTED, N.STOP),
    (S.VERIFYING, E.LINE_STOPPED, S.FAILED, N.STOP),
    (S.REPAIRING, E.ACKNOWLEDGED, S.REPAIRING, N.SEND),
    (S.REPAIRING, E.ALL_SENT, S.VERIFYING, N.READ),
    (S.REPAIRING, E.NO_REPLY, S.VERIFYING, N.READ),
    (S.REPAIRING, E.ERROR_CODE_AFTER_BROADCAST, S.REFUSED, N.READ),
    (S.REPAIRING, E.ERROR_CODE, S.REFUSED, N.READ),
    (S.REPAIRING, E.E12, S.REFUSED, N.READ),
    (S.REPAIRING, E.RUNNING, S.REFUSED, N.READ),
    (S.REPAIRING, E.CANCELLED, S.INTERRUPTED, N.STOP),
    (S.REPAIRING, E.LINE_STOPPED, S.FAILED, N.STOP),
    (S.REFUSED, E.AGREES, S.VERIFIED, N.STOP),
    (S.REFUSED, E.TRESPASSED, S.FAILED, N.STOP),
    (S.REFUSED, E.DIFFERS, S.FAILED, N.STOP),
    (S.REFUSED, E.NO_REPLY, S.REFUSED, N.READ),
    (S.REFUSED, E.READ_REFUSED, S.FAILED, N.STOP),
    (S.REFUSED, E.NO_ROUND_LEFT, S.FAILED, N.STOP),
    (S.REFUSED, E.CANCELLED, S.INTERRUPTED, N.STOP),
    (S.REFUSED, E.LINE_STOPPED, S.FAILED, N.STOP),
    (S.FAILED, E.LINE_STOPPED, S.FAILED, N.STOP),
    (S.INTERRUPTED, E.LINE_STOPPED, S.INTERRUPTED, N.STOP),
]


@pytest.mark.parametrize(("state", "event", "after", "action"), CASES,
                         ids=[f"{s.name}-{e.name}" for s, e, _, _ in CASES])
def test_transition(state: State, event: Event, after: State, action: Next) -> None:
    course = Course(state).after(event)  # no round or repair had yet: no budget is spent
    assert (course.state, course.action) == (after, action)


def test_the_cases_are_every_transition_of_the_table() -> None:
    table = {(s, e) for s, events in TRANSITIONS.items() for e in events}
    cases = [(s, e) for s, e, _, _ in CASES]
    assert len(cases) == len(set(cases)) and set(cases) == table
    assert set(TRANSITIONS) == set(State)  # every state has its row, if only an empty one


@pytest.mark.parametrize(("state", "event"), list(itertools.product(State, Event)), ids=lambda x: x.name)
def test_every_pair_is_in_the_table_or_refused(state: State, event: Event) -> None:
    if event in TRANSITIONS[state]:
        course = Course(state).after(event)
        assert (course.state, course.action) == TRANSITIONS[state][event]
        return
    with pytest.raises(NoTransition, match=f"no transition for {event.name} in {state.name}") as refused:
        Course(state).after(event)
    assert (refused.value.state, refused.value.event) == (state, event)


def test_the_ends_take_nothing_but_a_line_stopping() -> None:
    """A module verified is never told the line stopped (`stopped` leaves it be); a failed or
    interrupted one only that."""
    assert TRANSITIONS[S.VERIFIED] == {}
    assert set(TRANSITIONS[S.FAILED]) == set(TRANSITIONS[S.INTERRUPTED]) == {E.LINE_STOPPED}
    assert all(action in (N.STOP, N.GIVE_UP) for s in (S.VERIFIED, S.FAILED, S.INTERRUPTED)
               for _, action in TRANSITIONS[s].values())


# -- the budgets: a round is counted when a read is ordered, a repair when one is planned ----------

#: (course, event) → course after: where a budget is spent, its own event's transition.
BUDGETS = [
    pytest.param(Course(S.WRITING), E.ALL_SENT, Course(S.VERIFYING, N.READ, rounds=1),
                 id="the first read is a round"),
    pytest.param(Course(S.VERIFYING, N.READ, rounds=1), E.NO_REPLY, Course(S.VERIFYING, N.READ, rounds=2),
                 id="a lost read is a round"),
    pytest.param(Course(S.VERIFYING, N.READ, rounds=ROUNDS), E.NO_REPLY,
                 Course(S.FAILED, N.GIVE_UP, rounds=ROUNDS),
                 id="no round left after a lost read"),
    pytest.param(Course(S.REPAIRING, N.SEND, rounds=ROUNDS, repairs=1), E.ALL_SENT,
                 Course(S.FAILED, N.GIVE_UP, rounds=ROUNDS, repairs=1),
                 id="no round left to read a repair back"),
    pytest.param(Course(S.REPAIRING, N.SEND, rounds=ROUNDS, repairs=1), E.NO_REPLY,
                 Course(S.FAILED, N.GIVE_UP, rounds=ROUNDS, repairs=1),
                 id="no round left after a repair's lost step"),
    pytest.param(Course(S.REFUSED, N.READ, rounds=ROUNDS), E.NO_REPLY,
                 Course(S.FAILED, N.STOP, rounds=ROUNDS),
                 id="no round left for a refused module: its failure stands"),
    pytest.param(Course(S.REPAIRING, N.SEND, rounds=ROUNDS, repairs=1), E.E12,
                 Course(S.FAILED, N.STOP, rounds=ROUNDS, repairs=1),
                 id="no round left after a repair refused"),
    pytest.param(Course(S.VERIFYING, N.READ, rounds=1), E.DIFFERS,
                 Course(S.VERIFYING, N.PLAN_REPAIR, rounds=1), id="a repair to plan"),
    pytest.param(Course(S.VERIFYING, N.PLAN_REPAIR, rounds=1), E.REPAIR_PLANNED,
                 Course(S.REPAIRING, N.SEND, rounds=1, repairs=1),
                 id="a repair planned is counted"),
    pytest.param(Course(S.VERIFYING, N.READ, rounds=2, repairs=REPAIRS - 1), E.DIFFERS,
                 Course(S.VERIFYING, N.PLAN_REPAIR, rounds=2, repairs=REPAIRS - 1), id="the last repair"),
    pytest.param(Course(S.VERIFYING, N.READ, rounds=ROUNDS, repairs=REPAIRS), E.DIFFERS,
                 Course(S.FAILED, N.GIVE_UP, rounds=ROUNDS, repairs=REPAIRS), id="no repair left"),
    pytest.param(Course(S.VERIFYING, N.READ, rounds=ROUNDS, repairs=REPAIRS), E.AGREES,
                 Course(S.VERIFIED, N.STOP, rounds=ROUNDS, repairs=REPAIRS), id="the last round's "
                                                                                "read agrees"),
    pytest.param(Course(S.REFUSED, N.READ, rounds=ROUNDS), E.DIFFERS, Course(S.FAILED, N.STOP, rounds=ROUNDS),
                 id="a refused module is never repaired"),
]


@pytest.mark.parametrize(("before", "event", "after"), BUDGETS)
def test_budget(before: Course, event: Event, after: Course) -> None:
    assert before.after(event) == after


def test_the_budgets() -> None:
    """Two repairs, and a verifying read before each and after the last."""
    assert (REPAIRS, ROUNDS) == (2, 3)


# -- whole courses: the events one module meets, from its first step to its end --------------------

COURSES = [
    pytest.param([E.ACKNOWLEDGED, E.ACKNOWLEDGED, E.ALL_SENT, E.AGREES], Course(S.VERIFIED, N.STOP, rounds=1),
                 id="written and verified"),
    pytest.param([E.ACKNOWLEDGED, E.CANCELLED], Course(S.INTERRUPTED, N.STOP), id="Ctrl-C between two steps"),
    pytest.param([E.ALL_SENT, E.CANCELLED], Course(S.INTERRUPTED, N.STOP, rounds=1),
                 id="Ctrl-C while verifying"),
    pytest.param([E.ALL_SENT, E.NO_REPLY, E.NO_REPLY, E.NO_REPLY], Course(S.FAILED, N.GIVE_UP, rounds=ROUNDS),
                 id="never read back"),
    pytest.param([E.ALL_SENT, *[E.DIFFERS, E.REPAIR_PLANNED, E.ALL_SENT] * REPAIRS, E.DIFFERS],
                 Course(S.FAILED, N.GIVE_UP, rounds=ROUNDS, repairs=REPAIRS),
                 id="still differs after every repair"),
    pytest.param([E.ALL_SENT, E.NO_REPLY, E.DIFFERS, E.REPAIR_PLANNED, E.ALL_SENT, E.DIFFERS,
                  E.REPAIR_PLANNED, E.ALL_SENT],
                 Course(S.FAILED, N.GIVE_UP, rounds=ROUNDS, repairs=REPAIRS),
                 id="a lost read costs the last repair its read-back"),
    pytest.param([E.NO_REPLY, E.DIFFERS, E.REPAIR_PLANNED, E.ACKNOWLEDGED, E.ALL_SENT, E.AGREES],
                 Course(S.VERIFIED, N.STOP, rounds=2, repairs=1),
                 id="a module that stopped answering, repaired"),
    pytest.param([E.ERROR_CODE_AFTER_BROADCAST, E.DIFFERS, E.REPAIR_PLANNED, E.ALL_SENT, E.AGREES],
                 Course(S.VERIFIED, N.STOP, rounds=2, repairs=1),
                 id="a refusal a lost broadcast explains, repaired"),
    pytest.param([E.ERROR_CODE_AFTER_BROADCAST, E.DIFFERS, E.REPAIR_PLANNED, E.ERROR_CODE_AFTER_BROADCAST,
                  E.DIFFERS],
                 Course(S.FAILED, N.STOP, rounds=2, repairs=1), id="the repair refused too: final"),
    pytest.param([E.ACKNOWLEDGED, E.E12, E.DIFFERS], Course(S.FAILED, N.STOP, rounds=1),
                 id="E12: read back, not repaired"),
    pytest.param([E.RUNNING, E.AGREES], Course(S.VERIFIED, N.STOP, rounds=1),
                 id="refused, yet the read-back agrees"),
    pytest.param([E.ERROR_CODE, E.NO_REPLY, E.NO_REPLY, E.NO_REPLY], Course(S.FAILED, N.STOP, rounds=ROUNDS),
                 id="refused, never read back"),
    pytest.param([E.ALL_SENT, E.DIFFERS, E.REPAIR_UNCONSENTED], Course(S.FAILED, N.STOP, rounds=1),
                 id="a repair that needs consent"),
    pytest.param([E.ALL_SENT, E.READ_REFUSED], Course(S.FAILED, N.STOP, rounds=1), id="a read refused"),
    pytest.param([E.ALL_SENT, E.TRESPASSED], Course(S.FAILED, N.STOP, rounds=1),
                 id="an unmanaged program changed"),
    pytest.param([E.ALL_SENT, E.DIFFERS, E.REPAIR_PLANNED, E.LINE_STOPPED],
                 Course(S.FAILED, N.STOP, rounds=1, repairs=1), id="the line stopped"),
    pytest.param([E.ALL_SENT, E.DIFFERS, E.REPAIR_UNCONSENTED, E.LINE_STOPPED],
                 Course(S.FAILED, N.STOP, rounds=1),
                 id="failed, then the line stopped"),
]


@pytest.mark.parametrize(("events", "end"), COURSES)
def test_course(events: list[Event], end: Course) -> None:
    course = Course()
    for event in events:
        course = course.after(event)
    assert course == end


# -- what a write's reply and a repair's consent are to the table -------------------------------

REPLIES = [
    (0, False, E.ACKNOWLEDGED),
    (0, True, E.ACKNOWLEDGED),
    (23, False, E.E12),
    (23, True, E.E12),  # only a 10h/20h clears it: no lost broadcast explains it
    (16, False, E.RUNNING),
    (20, True, E.RUNNING),  # it may be moving: no repair loop
    (15, False, E.ERROR_CODE),
    (15, True, E.ERROR_CODE_AFTER_BROADCAST),
    (117, True, E.ERROR_CODE_AFTER_BROADCAST),
]


@pytest.mark.parametrize(("code", "after_broadcast", "event"), REPLIES)
def test_reply(code: int, after_broadcast: bool, event: Event) -> None:
    assert code == 0 or code in ERROR_CODES  # the cases are the manual's codes
    assert reply_event(code, after_broadcast=after_broadcast) is event


@pytest.mark.parametrize(("releases_axes", "consented", "event"), [
    (False, False, E.REPAIR_PLANNED),
    (False, True, E.REPAIR_PLANNED),
    (True, True, E.REPAIR_PLANNED),
    (True, False, E.REPAIR_UNCONSENTED),
])
def test_repair_consent(releases_axes: bool, consented: bool, event: Event) -> None:
    assert repair_event(releases_axes, consented) is event
