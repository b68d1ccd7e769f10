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
    Action,
    Event,
    NoTransition,
    Progress,
    State,
    repair_event,
    reply_event,
)
from prc3cfg.core.error_codes import ERROR_CODES

S, E, A = State, Event, Action

#: (state, event) → (next state, action): one case for every transition, written out again by hand.
CASES = [
    (S.WRITING, E.ACKNOWLEDGED, S.WRITING, A.SEND),
    (S.WRITING, E.ALL_SENT, S.VERIFYING, A.READ),
    (S.WRITING, E.NO_REPLY, S.VERIFYING, A.READ),
    (S.WRITING, E.ERROR_CODE_AFTER_BROADCAST, S.VERIFYING, A.READ),
    (S.WRITING, E.ERROR_CODE, S.REFUSED, A.READ),
    (S.WRITING, E.E12, S.REFUSED, A.READ),
    (S.WRITING, E.RUNNING, S.REFUSED, A.READ),
    (S.WRITING, E.CANCELLED, S.INTERRUPTED, A.STOP),
    (S.WRITING, E.LINE_STOPPED, S.FAILED, A.STOP),
    (S.VERIFYING, E.AGREES, S.VERIFIED, A.STOP),
    (S.VERIFYING, E.TRESPASSED, S.FAILED, A.STOP),
    (S.VERIFYING, E.DIFFERS, S.VERIFYING, A.PLAN_REPAIR),
    (S.VERIFYING, E.REPAIR_PLANNED, S.REPAIRING, A.SEND),
    (S.VERIFYING, E.REPAIR_UNCONSENTED, S.FAILED, A.STOP),
    (S.VERIFYING, E.NO_REPLY, S.VERIFYING, A.READ),
    (S.VERIFYING, E.READ_REFUSED, S.FAILED, A.STOP),
    (S.VERIFYING, E.NO_ROUND_LEFT, S.FAILED, A.GIVE_UP),
    (S.VERIFYING, E.NO_REPAIR_LEFT, S.FAILED, A.GIVE_UP),
    (S.VERIFYING, E.CANCELLED, S.INTERRUPTED, A.STOP),
    (S.VERIFYING, E.LINE_STOPPED, S.FAILED, A.STOP),
    (S.REPAIRING, E.ACKNOWLEDGED, S.REPAIRING, A.SEND),
    (S.REPAIRING, E.ALL_SENT, S.VERIFYING, A.READ),
    (S.REPAIRING, E.NO_REPLY, S.VERIFYING, A.READ),
    (S.REPAIRING, E.ERROR_CODE_AFTER_BROADCAST, S.REFUSED, A.READ),
    (S.REPAIRING, E.ERROR_CODE, S.REFUSED, A.READ),
    (S.REPAIRING, E.E12, S.REFUSED, A.READ),
    (S.REPAIRING, E.RUNNING, S.REFUSED, A.READ),
    (S.REPAIRING, E.CANCELLED, S.INTERRUPTED, A.STOP),
    (S.REPAIRING, E.LINE_STOPPED, S.FAILED, A.STOP),
    (S.REFUSED, E.AGREES, S.VERIFIED, A.STOP),
    (S.REFUSED, E.TRESPASSED, S.FAILED, A.STOP),
    (S.REFUSED, E.DIFFERS, S.FAILED, A.STOP),
    (S.REFUSED, E.NO_REPLY, S.REFUSED, A.READ),
    (S.REFUSED, E.READ_REFUSED, S.FAILED, A.STOP),
    (S.REFUSED, E.NO_ROUND_LEFT, S.FAILED, A.STOP),
    (S.REFUSED, E.CANCELLED, S.INTERRUPTED, A.STOP),
    (S.REFUSED, E.LINE_STOPPED, S.FAILED, A.STOP),
    (S.FAILED, E.LINE_STOPPED, S.FAILED, A.STOP),
    (S.INTERRUPTED, E.LINE_STOPPED, S.INTERRUPTED, A.STOP),
]


@pytest.mark.parametrize(("state", "event", "after", "action"), CASES, ids=[f"{s.name}-{e.name}" for s, e, _, _ in CASES])
def test_transition(state: State, event: Event, after: State, action: Action) -> None:
    progress = Progress(state).after(event)  # no round or repair had yet: no budget is spent
    assert (progress.state, progress.action) == (after, action)


def test_the_cases_are_every_transition_of_the_table() -> None:
    table = {(s, e) for s, events in TRANSITIONS.items() for e in events}
    cases = [(s, e) for s, e, _, _ in CASES]
    assert len(cases) == len(set(cases)) and set(cases) == table
    assert set(TRANSITIONS) == set(State)  # every state has its row, if only an empty one


@pytest.mark.parametrize(("state", "event"), list(itertools.product(State, Event)), ids=lambda x: x.name)
def test_every_pair_is_in_the_table_or_refused(state: State, event: Event) -> None:
    if event in TRANSITIONS[state]:
        progress = Progress(state).after(event)
        assert (progress.state, progress.action) == TRANSITIONS[state][event]
        return
    with pytest.raises(NoTransition, match=f"no transition for {event.name} in {state.name}") as refused:
        Progress(state).after(event)
    assert (refused.value.state, refused.value.event) == (state, event)


def test_the_ends_take_nothing_but_a_line_stopping() -> None:
    """A module verified is never told the line stopped (`stopped` leaves it be); a failed or
    interrupted one only that."""
    assert TRANSITIONS[S.VERIFIED] == {}
    assert set(TRANSITIONS[S.FAILED]) == set(TRANSITIONS[S.INTERRUPTED]) == {E.LINE_STOPPED}
    assert all(action in (A.STOP, A.GIVE_UP) for s in (S.VERIFIED, S.FAILED, S.INTERRUPTED) for _, action in TRANSITIONS[s].values())


# -- the budgets: a round is counted when a read is ordered, a repair when one is planned ----------

#: (progress, event) → progress after: where a budget is spent, its own event's transition.
BUDGETS = [
    pytest.param(Progress(S.WRITING), E.ALL_SENT, Progress(S.VERIFYING, A.READ, rounds=1), id="the first read is a round"),
    pytest.param(Progress(S.VERIFYING, A.READ, rounds=1), E.NO_REPLY, Progress(S.VERIFYING, A.READ, rounds=2), id="a lost read is a round"),
    pytest.param(Progress(S.VERIFYING, A.READ, rounds=ROUNDS), E.NO_REPLY, Progress(S.FAILED, A.GIVE_UP, rounds=ROUNDS),
                 id="no round left after a lost read"),
    pytest.param(Progress(S.REPAIRING, A.SEND, rounds=ROUNDS, repairs=1), E.ALL_SENT, Progress(S.FAILED, A.GIVE_UP, rounds=ROUNDS, repairs=1),
                 id="no round left to read a repair back"),
    pytest.param(Progress(S.REPAIRING, A.SEND, rounds=ROUNDS, repairs=1), E.NO_REPLY, Progress(S.FAILED, A.GIVE_UP, rounds=ROUNDS, repairs=1),
                 id="no round left after a repair's lost step"),
    pytest.param(Progress(S.REFUSED, A.READ, rounds=ROUNDS), E.NO_REPLY, Progress(S.FAILED, A.STOP, rounds=ROUNDS),
                 id="no round left for a refused module: its failure stands"),
    pytest.param(Progress(S.REPAIRING, A.SEND, rounds=ROUNDS, repairs=1), E.E12, Progress(S.FAILED, A.STOP, rounds=ROUNDS, repairs=1),
                 id="no round left after a repair refused"),
    pytest.param(Progress(S.VERIFYING, A.READ, rounds=1), E.DIFFERS, Progress(S.VERIFYING, A.PLAN_REPAIR, rounds=1), id="a repair to plan"),
    pytest.param(Progress(S.VERIFYING, A.PLAN_REPAIR, rounds=1), E.REPAIR_PLANNED, Progress(S.REPAIRING, A.SEND, rounds=1, repairs=1),
                 id="a repair planned is counted"),
    pytest.param(Progress(S.VERIFYING, A.READ, rounds=2, repairs=REPAIRS - 1), E.DIFFERS,
                 Progress(S.VERIFYING, A.PLAN_REPAIR, rounds=2, repairs=REPAIRS - 1), id="the last repair"),
    pytest.param(Progress(S.VERIFYING, A.READ, rounds=ROUNDS, repairs=REPAIRS), E.DIFFERS,
                 Progress(S.FAILED, A.GIVE_UP, rounds=ROUNDS, repairs=REPAIRS), id="no repair left"),
    pytest.param(Progress(S.VERIFYING, A.READ, rounds=ROUNDS, repairs=REPAIRS), E.AGREES,
                 Progress(S.VERIFIED, A.STOP, rounds=ROUNDS, repairs=REPAIRS), id="the last round's read agrees"),
    pytest.param(Progress(S.REFUSED, A.READ, rounds=ROUNDS), E.DIFFERS, Progress(S.FAILED, A.STOP, rounds=ROUNDS),
                 id="a refused module is never repaired"),
]


@pytest.mark.parametrize(("before", "event", "after"), BUDGETS)
def test_budget(before: Progress, event: Event, after: Progress) -> None:
    assert before.after(event) == after


def test_the_budgets() -> None:
    """Two repairs, and a verifying read before each and after the last."""
    assert (REPAIRS, ROUNDS) == (2, 3)


# -- whole courses: the events one module meets, from its first step to its end --------------------

COURSES = [
    pytest.param([E.ACKNOWLEDGED, E.ACKNOWLEDGED, E.ALL_SENT, E.AGREES], Progress(S.VERIFIED, A.STOP, rounds=1), id="written and verified"),
    pytest.param([E.ACKNOWLEDGED, E.CANCELLED], Progress(S.INTERRUPTED, A.STOP), id="Ctrl-C between two steps"),
    pytest.param([E.ALL_SENT, E.CANCELLED], Progress(S.INTERRUPTED, A.STOP, rounds=1), id="Ctrl-C while verifying"),
    pytest.param([E.ALL_SENT, E.NO_REPLY, E.NO_REPLY, E.NO_REPLY], Progress(S.FAILED, A.GIVE_UP, rounds=ROUNDS), id="never read back"),
    pytest.param([E.ALL_SENT, *[E.DIFFERS, E.REPAIR_PLANNED, E.ALL_SENT] * REPAIRS, E.DIFFERS],
                 Progress(S.FAILED, A.GIVE_UP, rounds=ROUNDS, repairs=REPAIRS), id="still differs after every repair"),
    pytest.param([E.ALL_SENT, E.NO_REPLY, E.DIFFERS, E.REPAIR_PLANNED, E.ALL_SENT, E.DIFFERS, E.REPAIR_PLANNED, E.ALL_SENT],
                 Progress(S.FAILED, A.GIVE_UP, rounds=ROUNDS, repairs=REPAIRS), id="a lost read costs the last repair its read-back"),
    pytest.param([E.NO_REPLY, E.DIFFERS, E.REPAIR_PLANNED, E.ACKNOWLEDGED, E.ALL_SENT, E.AGREES],
                 Progress(S.VERIFIED, A.STOP, rounds=2, repairs=1), id="a module that stopped answering, repaired"),
    pytest.param([E.ERROR_CODE_AFTER_BROADCAST, E.DIFFERS, E.REPAIR_PLANNED, E.ALL_SENT, E.AGREES],
                 Progress(S.VERIFIED, A.STOP, rounds=2, repairs=1), id="a refusal a lost broadcast explains, repaired"),
    pytest.param([E.ERROR_CODE_AFTER_BROADCAST, E.DIFFERS, E.REPAIR_PLANNED, E.ERROR_CODE_AFTER_BROADCAST, E.DIFFERS],
                 Progress(S.FAILED, A.STOP, rounds=2, repairs=1), id="the repair refused too: final"),
    pytest.param([E.ACKNOWLEDGED, E.E12, E.DIFFERS], Progress(S.FAILED, A.STOP, rounds=1), id="E12: read back, not repaired"),
    pytest.param([E.RUNNING, E.AGREES], Progress(S.VERIFIED, A.STOP, rounds=1), id="refused, yet the read-back agrees"),
    pytest.param([E.ERROR_CODE, E.NO_REPLY, E.NO_REPLY, E.NO_REPLY], Progress(S.FAILED, A.STOP, rounds=ROUNDS), id="refused, never read back"),
    pytest.param([E.ALL_SENT, E.DIFFERS, E.REPAIR_UNCONSENTED], Progress(S.FAILED, A.STOP, rounds=1), id="a repair that needs consent"),
    pytest.param([E.ALL_SENT, E.READ_REFUSED], Progress(S.FAILED, A.STOP, rounds=1), id="a read refused"),
    pytest.param([E.ALL_SENT, E.TRESPASSED], Progress(S.FAILED, A.STOP, rounds=1), id="an unmanaged program changed"),
    pytest.param([E.ALL_SENT, E.DIFFERS, E.REPAIR_PLANNED, E.LINE_STOPPED], Progress(S.FAILED, A.STOP, rounds=1, repairs=1), id="the line stopped"),
    pytest.param([E.ALL_SENT, E.DIFFERS, E.REPAIR_UNCONSENTED, E.LINE_STOPPED], Progress(S.FAILED, A.STOP, rounds=1),
                 id="failed, then the line stopped"),
]


@pytest.mark.parametrize(("events", "end"), COURSES)
def test_course(events: list[Event], end: Progress) -> None:
    progress = Progress()
    for event in events:
        progress = progress.after(event)
    assert progress == end


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
])  # fmt: skip
def test_repair_consent(releases_axes: bool, consented: bool, event: Event) -> None:
    assert repair_event(releases_axes, consented) is event
