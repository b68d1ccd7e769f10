"""The plant's `Planner` (`prc3cfg.core.plant_planner`) as the lines' threads share it: `SharedPlanner`.

Each line is read, planned and written in its own thread, and modules alike on any line are
planned once — so the planner is one, and the lines take turns with it, under one lock. The
core's planner takes no lock and probes no line: here a line's plan is drafted under the lock,
the addresses its broadcasts need silent are probed on the line outside it (another line's
planning need not wait for a probe's line time), and the line is settled under it again.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

from prc3cfg.core.image import Key, ModuleImage, Wanted
from prc3cfg.core.plant_plan import ModuleChange, PlantPlan
from prc3cfg.core.plant_planner import Planner
from prc3cfg.shell.probe import answering

if TYPE_CHECKING:
    from prc3cfg.shell.link.client import Link


class SharedPlanner:
    """A `Planner` the lines' threads use one at a time."""

    def __init__(self, planner: Planner) -> None:
        self._planner = planner
        self._lock = threading.Lock()

    def plan_module(self, wanted: Wanted, actual: ModuleImage) -> None:
        """`Planner.plan_module`: a module planned as soon as it is read."""
        with self._lock:
            self._planner.plan_module(wanted, actual)

    def plan_line(self, bus: str, modules: Sequence[Wanted], actual: Mapping[Key, ModuleImage], link: Link | None) -> None:
        """One line planned (`Planner.draft_line`), the addresses its broadcasts need silent probed on
        `link` — the line's, under its lock, in this run — and settled with what answered
        (`Planner.settle_line`). Without a link (planning from saved images) no broadcast that needs a
        proof is planned."""
        with self._lock:
            draft = self._planner.draft_line(bus, modules, actual, probing=link is not None)
        answered = None if link is None else answering(link, draft.to_prove)
        with self._lock:
            self._planner.settle_line(draft, answered)

    def line_changes(self, bus: str) -> list[ModuleChange]:
        """`Planner.line_changes`: the changes of a line settled."""
        with self._lock:
            return self._planner.line_changes(bus)

    def plan(self, modules: Sequence[Wanted], actual: Mapping[Key, ModuleImage]) -> PlantPlan:
        """`Planner.plan`: the plant's plan of the lines settled (the others planned now, without a proof)."""
        with self._lock:
            return self._planner.plan(modules, actual)
