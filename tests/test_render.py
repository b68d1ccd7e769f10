"""How plans show jumps and field names to people."""

from __future__ import annotations

import pytest

from prc3cfg.image import ModuleImage, Program
from prc3cfg.render import field_name, jumps


def image_with(jumps_: dict[int, int]) -> ModuleImage:
    factory = ModuleImage.factory(1)
    return factory.with_programs({n: Program(P=150, V=50, A=a) for n, a in jumps_.items()})


@pytest.mark.parametrize(
    ("jumps_", "within", "expected"),
    [
        ({}, {1, 2}, set()),
        ({1: 2, 2: 3}, {1, 2, 3}, {"chain 1 → 2 → 3 → stop"}),
        ({10: 11, 11: 12, 12: 10}, {10, 11, 12}, {"chain 10 → 11 → 12 → 10"}),
        ({1: 3, 2: 3}, {1, 2, 3}, {"jump 1 → 3", "jump 2 → 3"}),
        ({3: 10}, {3}, {"jump 3 → 10"}),  # 10 is not managed: nothing is claimed about it
        ({1: 2, 2: 1, 5: 6}, {1, 2, 5, 6}, {"chain 1 → 2 → 1", "chain 5 → 6 → stop"}),
    ],
)
def test_jumps(jumps_, within, expected):
    assert jumps(image_with(jumps_), within) == expected


@pytest.mark.parametrize(
    ("symbol", "name"),
    [("S1", "upper reversing point"), ("S12", "sync conveyor sequence"), ("Vr", "relative speed"), ("T", "dwell"), ("F2", "F2")],
)
def test_field_name(symbol, name):
    assert field_name(symbol) == name
