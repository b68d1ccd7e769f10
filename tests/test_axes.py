"""Whether a module's axes were released (`prc3cfg.core.axes.released`), as a table: each row a run as the
apply sees it — what went out, what was acknowledged, what the verifying read-back shows — and the conclusion
the account, the journal and the travel list take from it. Every combination of the facts is in a row's reach
(`test_every_combination_is_one_rule`)."""

from __future__ import annotations

import itertools

import pytest

from prc3cfg.core.axes import Release, released

FACTS = ("acknowledged", "sent", "possibly_written", "exposed", "read_back", "changed")

#: (facts that hold, the conclusion, why) — the facts not named are false.
ROWS = [
    ({"acknowledged", "sent", "read_back", "changed"}, Release.YES, "a 10h/20h acknowledged: released"),
    ({"acknowledged", "sent"}, Release.YES, "acknowledged, no read-back after: released all the same"),
    ({"acknowledged", "sent", "read_back"}, Release.YES,
     "acknowledged although the block reads as before: the module said so"),
    (set(), Release.NO, "nothing sent, nothing seen"),
    ({"read_back"}, Release.NO, "read back as before, nothing sent"),
    ({"sent"}, Release.POSSIBLY, "sent unacknowledged, no read-back: it may have been executed"),
    ({"sent", "read_back"}, Release.NO, "sent unacknowledged, the block reads as before: not executed"),
    ({"sent", "read_back", "changed"}, Release.YES, "sent unacknowledged, the block changed: executed"),
    ({"possibly_written", "read_back"}, Release.POSSIBLY,
     "a read answered as a write, the block as before: a 10h leaves defaults as they were"),
    ({"possibly_written", "read_back", "changed"}, Release.YES,
     "a read answered as a write, the block changed"),
    ({"possibly_written"}, Release.POSSIBLY, "a read answered as a write, no read-back"),
    ({"exposed", "read_back", "changed"}, Release.YES,
     "no write sent, but a damaged frame changed the block on a line without checks"),
    ({"exposed", "read_back"}, Release.NO, "on a line without checks, nothing sent and the block as before"),
]


@pytest.mark.parametrize(("holds", "expected", "why"), ROWS, ids=[why for _, _, why in ROWS])
def test_a_run_s_facts_conclude_its_axes(holds: set[str], expected: Release, why: str) -> None:
    assert released(**{fact: fact in holds for fact in FACTS}) is expected, why


def test_every_combination_is_one_rule() -> None:
    """Over all 64 combinations: an acknowledged release is always YES; a changed block on a line without
    checks or after a read answered as a write is YES; NO only where no write went out or the block reads as
    before — an apply never says NO of a module whose block it saw change, nor of one whose 10h/20h it could
    not follow."""
    for values in itertools.product((False, True), repeat=len(FACTS)):
        facts = dict(zip(FACTS, values))
        if facts["changed"] and not facts["read_back"]:
            continue  # a change is only seen by a read-back
        said = released(**facts)
        if facts["acknowledged"] or (facts["changed"]
                                     and (facts["sent"] or facts["exposed"] or facts["possibly_written"])):
            assert said is Release.YES, facts
        if said is Release.NO:
            assert not facts["changed"] or not (facts["sent"] or facts["exposed"]
                                                or facts["possibly_written"]), facts
            assert facts["read_back"] or not (facts["sent"] or facts["possibly_written"]), facts
