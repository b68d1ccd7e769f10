"""The states the write phase's DP keeps (`parts_states.States.undominated`): none that another it keeps
beats.

A state is the room left in the last 40h and 41h and, per live 42h..46h field, the programs a 21h
took out of it; one ahead of another in some fields can gain at most those fields' headers over it,
so it goes where it costs that much more. Costs are sums of the same prices in different orders, so
two that are the same cost may differ by a rounding (1e-17 s): the same cost all the same.
"""

from __future__ import annotations

import random

from hypothesis import given
from hypothesis import strategies as st

from prc3cfg.core.planner.parts_states import STATE_BITS, States
from prc3cfg.core.planner.terms import NEAR

#: Seconds: a 40h..45h's header and two item prices of crc16 at 9600 baud (roughly), to sum costs from.
HEADER, ITEM, PART = 0.0114583, 0.0045833333333333334, 0.0022916666666666667


def packed(fields: tuple[int, ...]) -> int:
    return sum(value << (STATE_BITS * f) for f, value in enumerate(fields))


def beats(b: tuple[tuple[int, ...], float], a: tuple[tuple[int, ...], float],
          worth: tuple[float, ...]) -> bool:
    """Whether state b beats a: a costs at least what being ahead of b in its fields can gain it (to NEAR)."""
    (fields_a, cost_a), (fields_b, cost_b) = a, b
    gain = sum(w for w, x, y in zip(worth, fields_a, fields_b) if x > y)
    return cost_a - cost_b >= gain - NEAR


def test_a_state_the_same_cost_as_one_ahead_of_it_goes_whichever_comes_first() -> None:
    states = States((HEADER, HEADER), (15, 15))
    behind, ahead = packed((6, 3)), packed((6, 4))
    same = ITEM + ITEM + HEADER
    # the second pair differs by rounding
    for costs in ((same, same), (ITEM + (ITEM + HEADER), HEADER + ITEM + ITEM)):
        for order in ((behind, ahead), (ahead, behind)):
            kept = states.undominated(dict(zip(order, costs)))
            assert list(kept) == [ahead]


@given(st.integers(0, 2**32), st.integers(0, 2))
def test_no_state_kept_is_beaten_by_another_kept(seed: int, live: int) -> None:
    rnd = random.Random(seed)
    worth = (HEADER, HEADER, *[HEADER * rnd.choice([1, 2, 3]) for _ in range(live)])
    needed = (15, 15, *[rnd.randint(1, 6) for _ in range(live)])
    states = States(worth, needed)
    given_states: dict[tuple[int, ...], float] = {}
    for _ in range(rnd.randint(1, 60)):
        fields = tuple(rnd.randint(0, n) for n in needed)
        prices = [rnd.choice([ITEM, PART, HEADER]) for _ in range(rnd.randint(1, 12))]
        rnd.shuffle(prices)
        given_states[fields] = sum(prices)  # left to right: the same prices in another order round otherwise
    by_packed = {packed(fields): fields for fields in given_states}
    kept = states.undominated({packed(fields): cost for fields, cost in given_states.items()})
    assert kept, "the cheapest state is always kept"
    pairs = [(by_packed[state], cost) for state, cost in kept.items()]
    for a in pairs:
        assert not any(beats(b, a, worth) for b in pairs if b is not a), (a, pairs)
    cheapest = min(given_states.values())
    assert min(kept.values()) <= cheapest + NEAR
