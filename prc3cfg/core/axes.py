"""What an apply concludes of a module's axes: released, not, or possibly (`Release`).

A 10h/20h releases the axes, and a module whose axes were released must travel to its reference
point before it runs again. Which of the three a module's run is, is the apply's to conclude
(`prc3cfg.shell.apply.ModuleRun.released`) from what went out, what was acknowledged and what the
verifying read-back shows; the account says it (`prc3cfg.core.render`), and the journal and the API's
result name every module not `NO` (`to_travel`). Pure.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable
from typing import Protocol, TypeVar


class Release(enum.Enum):
    """Whether a module's axes were released (10h/20h) and it must travel to its reference point."""

    NO = "no"
    YES = "yes"
    POSSIBLY = "possibly"  # a 10h/20h went out unacknowledged, and no read-back settles it


class Concluded(Protocol):
    """A module's run as far as its axes go (`prc3cfg.shell.apply.ModuleRun`)."""

    @property
    def released(self) -> Release: ...


R = TypeVar("R", bound=Concluded)


def to_travel(runs: Iterable[R]) -> list[R]:
    """The runs whose axes were — or may have been — released: they must travel to their reference point."""
    return [run for run in runs if run.released is not Release.NO]
