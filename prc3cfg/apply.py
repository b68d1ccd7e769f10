"""Running plans on the modules: steps in order, verification, repair, an exact account.

Owns execution: per module the steps in order, buses in parallel (a thread per line), the
modules of one line one after another. An error reply stops that module for good —
naming the step, the code, its meaning and what to do — while the other modules go on.
A module that stops answering (every retry lost) is not given up at once: every PRC 3
message is idempotent, so the module is read back and whatever still differs is planned
and sent again. Afterwards every touched module is read back and compared with what it
should hold; a difference (a write damaged on an `open-driver` line, a lost exchange, a
module changed on the floor meanwhile) is repaired, at most `REPAIRS` times. Success
means verified. Gating, snapshots and locks are the caller's (`prc3cfg.cli`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

from prc3cfg import codec
from prc3cfg.bustime import LineCost
from prc3cfg.error_codes import describe, remedy
from prc3cfg.errors import UserError
from prc3cfg.image import ModuleImage
from prc3cfg.link import Link, LinkError
from prc3cfg.planner import plan_module
from prc3cfg.readback import read_module

REPAIRS = 2
#: Reads to confirm a difference: on a line without a checksum a damaged reply looks like
#: one, so a difference counts only when two reads in a row agree on it.
CONFIRMING_READS = 4


@dataclass(slots=True)
class ModuleRun:
    """One module's part of an apply, and what happened to it."""

    bus: str
    address: int
    name: str
    desired: ModuleImage
    steps: tuple[codec.Message, ...]
    summaries: tuple[str, ...]
    sent: list[codec.Message] = field(default_factory=list)  # accepted, over all rounds
    failure: str | None = None
    refused: bool = False  # the module answered an error code: stop for good
    verified: bool = False
    repairs: int = 0

    @property
    def where(self) -> str:
        return f"bus {self.bus}, module {self.address} ({self.name})"

    @property
    def released_axes(self) -> bool:
        return any(m.RELEASES_AXES for m in self.sent)

    def run(self, link: Link, steps: Sequence[codec.Message], summaries: Sequence[str], tick: Callable[[], None]) -> bool:
        """Send steps in order; False at the first one not accepted (`failure` says why)."""
        for index, (message, summary) in enumerate(zip(steps, summaries), start=1):
            try:
                reply = link.request(self.address, message)
            except LinkError as error:
                self.failure = f"step {index} of {len(steps)} ({summary}): {error}"
                return False
            if reply != 0:  # a write is answered with a code word only (decode_reply sees to it)
                self.refused = True
                self.failure = (
                    f"{self.where}: step {index} of {len(steps)} ({summary}, {message.hex()}) was refused "
                    f"with {describe(reply)} — {remedy(reply)}"
                )
                return False
            self.sent.append(message)
            tick()
        return True

    def read_back(self, link: Link) -> ModuleImage:
        """The module's image: the desired one as soon as a read shows it, else two reads that agree."""
        managed = [n for n, p in enumerate(self.desired.programs, start=1) if p is not None]
        previous = read_module(link, self.address, managed, name=self.name)
        for _ in range(CONFIRMING_READS):
            if previous == self.desired:
                break
            current = read_module(link, self.address, managed, name=self.name)
            if current == previous:
                break
            previous = current
        return previous

    def converge(self, link: Link, cost: LineCost, tick: Callable[[], None], may_release_axes: bool) -> None:
        """Read back; while it differs from the desired image, plan and repair (at most REPAIRS times)."""
        for _ in range(REPAIRS + 1):
            try:
                actual = self.read_back(link)
            except LinkError as error:
                self.failure = f"verification: {error}"
                continue
            except UserError as error:
                self.failure = f"verification: {error}"
                return
            if actual == self.desired:
                self.verified, self.failure = True, None
                return
            if self.repairs == REPAIRS:
                break
            repair = plan_module(actual, self.desired, cost)
            if repair.releases_axes and not may_release_axes:
                self.failure = (
                    f"{self.where}: the read-back shows other system parameters; writing them would release "
                    "the axes — apply again with --allow-axis-release"
                )
                return
            self.repairs += 1
            if not self.run(link, [s.message for s in repair.steps], [s.summary for s in repair.steps], tick):
                if self.refused:
                    return
        self.failure = (
            f"{self.where}: still differs from the plant file after {REPAIRS} repairs"
            + (f" (last problem: {self.failure})" if self.failure else "")
            + " — check the line (damaged frames?) and the module, then apply again"
        )


def execute(
    runs: list[ModuleRun],
    links: dict[str, Link],
    costs: dict[str, LineCost],
    *,
    tick: Callable[[], None] = lambda: None,
    may_release_axes: bool = False,
) -> None:
    """Run every module's steps, then verify and repair; results are left in `runs`.

    Buses run in parallel; on one bus, all modules are written first, then verified.
    """
    per_bus: dict[str, list[ModuleRun]] = {}
    for run in runs:
        per_bus.setdefault(run.bus, []).append(run)

    def on_bus(bus: str, bus_runs: list[ModuleRun]) -> None:
        for run in bus_runs:
            run.run(links[bus], run.steps, run.summaries, tick)
        for run in bus_runs:
            if not run.refused:
                run.converge(links[bus], costs[bus], tick, may_release_axes)

    with ThreadPoolExecutor(max_workers=max(1, len(per_bus))) as pool:
        for future in [pool.submit(on_bus, bus, bus_runs) for bus, bus_runs in per_bus.items()]:
            future.result()
