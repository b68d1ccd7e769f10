"""The init DP of one init kind (`init_dp._one_kind`) is the DP of several (`init_dp._kinds`) written
out for one: the same back pointers and the same costs after the last program, to the last bit, on
charge tables full of ties (the DP breaks them by state) and with programs outside the plan file."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from prc3cfg.core.image import PROGRAM_COUNT
from prc3cfg.core.planner.init_dp import TIE, _kinds, _one_kind

#: Seconds: few values, so that sums tie, and the same less TIE, as `Charges` gives an init kind.
CHARGES = (0.0, 0.0045833333333333334, 0.0114583, 0.016041633333333334, 0.05)
REFUND, INIT_RANGE = 0.0022916666666666667, 0.0389583


@given(
    st.lists(st.tuples(st.sampled_from(CHARGES), st.sampled_from(CHARGES), st.booleans()),
             min_size=PROGRAM_COUNT, max_size=PROGRAM_COUNT),
    st.lists(st.booleans(), min_size=PROGRAM_COUNT, max_size=PROGRAM_COUNT),
)
def test_one_kind_is_the_dp_of_several_with_one(rows: list[tuple[float, float, bool]],
                                                managed: list[bool]) -> None:
    table = [(kept, initialised - TIE if tied else initialised) for kept, initialised, tied in rows]
    back, cost = _one_kind(tuple(managed), table, REFUND, INIT_RANGE)
    back_all, cost_all = _kinds(tuple(managed), table, 1, REFUND, INIT_RANGE)
    assert [tuple(step) for step in back] == [tuple(step) for step in back_all]
    assert cost == cost_all
