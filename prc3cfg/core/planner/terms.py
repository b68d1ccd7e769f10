"""The planner search's shared terms: the masks of fields it writes, the types its DPs pass
around, the messages a candidate may use, and how close two costs must be to be the same.

Prices are added with `math.fsum` wherever they are compared (Python 3.12's `sum()` of floats
rounds otherwise than 3.11's: a near-tie must be decided alike on every version, or a plan made
on one is refused as edited on the other).

Owns those terms. Does not own the search (`write_phase`, `init_search`) or the prices (`pricing`).
"""

from __future__ import annotations

import operator
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from prc3cfg.core import codec
from prc3cfg.core.planner.problem import FIELD_BIT, P_BIT, PLAIN_FIELDS, V_BIT

INF = float("inf")
#: What a program (index) with a difference mask costs to fix, in seconds.
Residual = Callable[[int, int], float]
#: An init kind (`problem` KEEP, INIT_BEFORE, INIT_AFTER) per program.
Kinds = tuple[int, ...]
#: Per program, a charge (seconds) per init kind, in the order of `problem.kinds` (`Charges`).
Table = list[Sequence[float]]
#: First and last index of consecutive programs (a 33h run).
Run = tuple[int, int]
#: A link (True) or unlink range: (link?, first, last index), a 30h or 31h.
Range = tuple[bool, int, int]
PLAIN_BITS = tuple(FIELD_BIT[name] for name in PLAIN_FIELDS)
#: The bits of `PLAIN_FIELDS` as one mask.
PLAIN_MASK = sum(PLAIN_BITS)
#: The field bits of each difference mask.
FIELDS_OF = [tuple(bit for bit in FIELD_BIT.values() if mask & bit) for mask in range(1 << len(FIELD_BIT))]
#: The fields of 40h..45h, in `Writes.items` order.
ITEM_BITS = (P_BIT, V_BIT, *PLAIN_BITS)
ESTIMATE = operator.attrgetter("estimate")
#: The message of one field of arbitrary programs (40h..46h, `codec.FIELD_KINDS`), by FIELD_BIT.
KIND_OF_BIT = {FIELD_BIT[name]: kind for name, kind in codec.FIELD_KINDS.items()}
#: Costs closer than this (seconds) are the same cost, the difference rounding's (the DP's sums of the
#: same prices in another order): a state the same cost as one ahead of it is beaten (`States`).
#: `States.windows_kept` rounds its starts' costs to NEAR_DIGITS to sort them.
NEAR_DIGITS = 12
NEAR = 10.0**-NEAR_DIGITS


@dataclass(frozen=True, slots=True)
class Channels:
    """The per-field messages a candidate may use."""

    plain: int  # FIELD_BIT mask of the Vr, T, F1, F2 whose 42h..45h is open
    positions: bool  # 40h
    speeds: bool  # 41h
    parts: bool  # 33h / 32h
    addresses: bool  # 46h

    @classmethod
    def everything(cls, open_: bool) -> Channels:
        return cls(PLAIN_MASK if open_ else 0, open_, open_, open_, open_)


def all_of(masks: tuple[int, ...]) -> int:
    """The union of `masks`."""
    union = 0
    for mask in masks:
        union |= mask
    return union


def all_runs(runs: tuple[Run, ...]) -> int:
    """The programs of `runs` as one mask."""
    return sum((1 << (last + 1)) - (1 << first) for first, last in runs)
