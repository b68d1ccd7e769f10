"""The lines read back and planned as they are read — the read stage (`read_lines`, a `ReadBack` per line) and
the plan stage (`line_plan`, a `LinePlan`), pipelined per line (`read_and_plan_lines`) — and the plant's
`Planner` (`prc3cfg.core.plant_planner`) as the lines' threads share it: `SharedPlanner`.

Each line is read, planned and written in its own thread, and modules alike on any line are
planned once — so the planner is one, and the lines take turns with it, under one lock. The
core's planner takes no lock and probes no line: here a line's plan is drafted under the lock,
the addresses its broadcasts need silent are probed on the line outside it (another line's
planning need not wait for a probe's line time), and the line is settled under it again.

Everything here is called from the shell's own threads with values; nothing here calls the API
or the command line: what the lines' reading and planning give is for the caller to show.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING

from prc3cfg.core.image import Key, ModuleImage, Wanted
from prc3cfg.core.plant_plan import ModuleChange, PlantPlan
from prc3cfg.core.plant_planner import Planner
from prc3cfg.core.stages import LinePlan, ReadBack
from prc3cfg.core.what_to_read import Target
from prc3cfg.shell.probe import answering
from prc3cfg.shell.readback import read_all

if TYPE_CHECKING:
    from prc3cfg.shell.link.client import Link
    from prc3cfg.shell.sessions import OnRecord


class SharedPlanner:
    """A `Planner` of the modules `wanted` (each with its desired image) the lines' threads use one at a
    time."""

    def __init__(self, planner: Planner, wanted: Sequence[Wanted]) -> None:
        self._planner = planner
        self.wanted = tuple(wanted)
        self._by_key = {w.key: w for w in wanted}
        self._lock = threading.Lock()

    def plan_module(self, target: Target, actual: ModuleImage) -> None:
        """`Planner.plan_module`: the module `target` reads, planned as soon as it is read."""
        with self._lock:
            self._planner.plan_module(self._by_key[(target.bus, target.address)], actual)

    def plan_line(self, bus: str, actual: Mapping[Key, ModuleImage], link: Link | None) -> None:
        """One line planned (`Planner.draft_line`), the addresses its broadcasts need silent probed on
        `link` — the line's, under its lock, in this run — and settled with what answered
        (`Planner.settle_line`). Without a link (planning from saved images) no broadcast that needs a
        proof is planned."""
        with self._lock:
            draft = self._planner.draft_line(bus, self.wanted, actual, probing=link is not None)
        answered = None if link is None else answering(link, draft.to_prove)
        with self._lock:
            self._planner.settle_line(draft, answered)

    def line_changes(self, bus: str) -> list[ModuleChange]:
        """`Planner.line_changes`: the changes of a line settled."""
        with self._lock:
            return self._planner.line_changes(bus)

    def plan(self, actual: Mapping[Key, ModuleImage], buses: Iterable[str] | None = None) -> PlantPlan:
        """`Planner.plan`: the plant's plan — of the modules of `buses`, if given — of the lines settled (the
        others planned now, without a proof)."""
        lines = None if buses is None else set(buses)
        with self._lock:
            return self._planner.plan([w for w in self.wanted if lines is None or w.bus in lines], actual)


def line_plan(planner: SharedPlanner, read: ReadBack, link: Link | None) -> LinePlan:
    """The plan stage of a line `read_lines` read — each of its modules planned as it was read: the line
    settled, its broadcasts' silent addresses probed on `link` (`SharedPlanner.plan_line`), and its changes,
    to gate and write."""
    planner.plan_line(read.bus, read.images, link)
    return LinePlan(tuple(planner.line_changes(read.bus)), read.images)


def read_lines(targets: Iterable[Target], links: dict[str, Link], on_record: OnRecord, by: str,
               planner: SharedPlanner | None = None,
               *, progress: Callable[[], None] | None = None,
               then: Callable[[ReadBack], None] | None = None) -> dict[Key, ModuleImage]:
    """The read stage: every target read back (`read_all`: the lines at once), each line's read-back into its
    record as soon as it is in (`OnRecord.saw`, what `by` saw) and given to `then` — the plan stage
    (`line_plan`), in the line's thread, while the other lines are still read; with a `planner`, each module
    planned as soon as it is read."""

    def line_read(bus: str, images: dict[Key, ModuleImage]) -> None:
        on_record.saw(bus, images, by)
        if then is not None:
            then(ReadBack(bus, images))

    return read_all(targets, links, progress=progress, each=None if planner is None else planner.plan_module,
                    then=line_read)


def read_and_plan_lines(targets: Iterable[Target], links: dict[str, Link], on_record: OnRecord, by: str,
                        planner: SharedPlanner, *,
                  progress: Callable[[], None] | None = None,
                        then: Callable[[ReadBack, LinePlan], None] | None = None,
                  ) -> dict[Key, ModuleImage]:
    """The read and plan stages pipelined line by line (`read_lines`, `line_plan`): each line planned in its
    own thread as soon as its last module is read — the other lines still being read — then `then(read_back,
    line_plan)` (to gate and write the line)."""

    def plan(read: ReadBack) -> None:
        line = line_plan(planner, read, links[read.bus])
        if then is not None:
            then(read, line)

    return read_lines(targets, links, on_record, by, planner, progress=progress, then=plan)
