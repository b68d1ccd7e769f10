"""Jump addresses → chains and `next:` (prc3cfg import), checked by rebuilding A from them."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from prc3cfg.core.chains import jumps_as_chains
from prc3cfg.core.image import Program


def rebuild(chains, nexts) -> dict[int, int]:
    """A per program, as the plant file's chain rules define it."""
    a: dict[int, int] = {}
    for chain in chains:
        programs = chain["programs"] if isinstance(chain, dict) else chain
        loop = isinstance(chain, dict) and chain.get("loop")
        for i, n in enumerate(programs):
            a[n] = programs[i + 1] if i + 1 < len(programs) else (programs[0] if loop else 0)
    a.update(nexts)
    return a


def programs_with(jumps: dict[int, int]) -> dict[int, Program]:
    return {n: Program(P=150, V=50, A=jumps.get(n, 0)) for n in range(1, 65)}


CASES = [
    ({}, [], {}),
    ({1: 2, 2: 3}, [[1, 2, 3]], {}),
    ({10: 11, 11: 12, 12: 10}, [{"programs": [10, 11, 12], "loop": True}], {}),
    ({5: 5}, [{"programs": [5], "loop": True}], {}),
    ({1: 3, 2: 3}, [], {1: 3, 2: 3}),  # two programs continue with the same one
]


def test_table():
    for jumps, chains, nexts in CASES:
        got_chains, got_nexts = jumps_as_chains(programs_with(jumps))
        assert (got_chains, got_nexts) == (chains, nexts), jumps


def test_path_into_a_loop_keeps_every_jump():
    chains, nexts = jumps_as_chains(programs_with({1: 2, 2: 3, 3: 2}))
    assert rebuild(chains, nexts) | {n: 0 for n in range(4, 65)} == {1: 2, 2: 3,
                                                                     3: 2} | {n: 0 for n in range(4, 65)}
    placed = [n for c in chains for n in (c["programs"] if isinstance(c, dict) else c)]
    assert len(placed) == len(set(placed)) and not set(placed) & set(nexts)


@settings(max_examples=300, deadline=None)
@given(st.dictionaries(st.integers(1, 64), st.integers(1, 64), max_size=30))
def test_any_jumps_are_rebuilt_exactly(jumps):
    chains, nexts = jumps_as_chains(programs_with(jumps))
    placed = [n for c in chains for n in (c["programs"] if isinstance(c, dict) else c)]
    assert len(placed) == len(set(placed)), "a program in two chains"
    assert not set(placed) & set(nexts), "a program with both a chain and next"
    rebuilt = rebuild(chains, nexts)
    assert {n: rebuilt.get(n, 0) for n in range(1, 65)} == {n: jumps.get(n, 0) for n in range(1, 65)}
