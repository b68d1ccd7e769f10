"""Running plans on the modules: steps in order, verification, repair, an exact account.

Owns execution: per module the steps in order, buses in parallel (a thread per line), the
modules of one line one after another. An error reply stops that module — naming the step,
the code, its meaning and what to do — while the other modules go on; a module that stops
answering stops the same way. Afterwards every touched module is read back and compared
with what it should hold; a difference (a write damaged on an `open-driver` line, a module
changed on the floor meanwhile) is planned and repaired again, at most `REPAIRS` times.
Success means verified. Gating, snapshots and locks are the caller's (`prc3cfg.cli`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

from prc3cfg import codec
from prc3cfg.bustime import LineCost
from prc3cfg.error_codes import describe, remedy
from prc3cfg.errors import UserError
from prc3cfg.image import ModuleImage
from prc3cfg.link import Link
from prc3cfg.planner import plan_module
from prc3cfg.readback import read_module

REPAIRS = 2


@dataclass(slots=True)
class ModuleRun:
    """One module's part of an apply, and what happened to it."""

    bus: str
    address: int
    name: str
    desired: ModuleImage
    steps: tuple[codec.Message, ...]
    summaries: tuple[str, ...] = ()
    sent: list[codec.Message] = field(default_factory=list)  # accepted, over all rounds
    failure: str | None = None
    verified: bool = False
    repairs: int = 0
    released_axes: bool = False

    @property
    def where(self) -> str:
        return f"bus {self.bus}, module {self.address} ({self.name})"

    def run(self, link: Link, steps: Iterable[codec.Message], summaries: Iterable[str], tick: Callable[[], None]) -> bool:
        """Send steps in order; False (with `failure` set) at the first that is not accepted."""
        steps, summaries = list(steps), list(summaries)
        for index, (message, summary) in enumerate(zip(steps, summaries), start=1):
            try:
                reply = link.request(self.address, message)
            except UserError as error:
                self.failure = f"step {index} of {len(steps)} ({summary}): {error}"
                return False
            if reply != 0:
                code = reply if isinstance(reply, int) else -1
                self.failure = (
                    f"{self.where}: step {index} of {len(steps)} ({summary}, {message.hex()}) was refused with "
                    f"{describe(code)} — {remedy(code)}"
                )
                return False
            self.sent.append(message)
            self.released_axes |= message.RELEASES_AXES
            tick()
        return True


def _by_bus(runs: Iterable[ModuleRun]) -> dict[str, list[ModuleRun]]:
    grouped: dict[str, list[ModuleRun]] = {}
    for run in runs:
        grouped.setdefault(run.bus, []).append(run)
    return grouped


def _verify(run: ModuleRun, link: Link, cost: LineCost, tick: Callable[[], None], may_release_axes: bool) -> None:
    """Read back; while it differs from the desired image, plan and repair (at most REPAIRS times)."""
    managed = [n for n, p in enumerate(run.desired.programs, start=1) if p is not None]
    try:
        for _ in range(REPAIRS + 1):
            actual = read_module(link, run.address, managed, name=run.name)
            if actual == run.desired:
                run.verified = True
                return
            if run.repairs == REPAIRS:
                break
            repair = plan_module(actual, run.desired, cost)
            if repair.releases_axes and not may_release_axes:
                run.failure = (
                    f"{run.where}: read-back shows different system parameters; repairing them would "
                    "release the axes — apply again with --allow-axis-release"
                )
                return
            run.repairs += 1
            if not run.run(link, [s.message for s in repair.steps], [s.summary for s in repair.steps], tick):
                return
    except UserError as error:
        run.failure = f"verification: {error}"
        return
    run.failure = (
        f"{run.where}: still differs from the plant file after {REPAIRS} repairs — "
        "check the line (damaged frames?) and the module, then apply again"
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

    def on_bus(bus: str, bus_runs: list[ModuleRun]) -> None:
        for run in bus_runs:
            run.run(links[bus], run.steps, run.summaries or [m.hex() for m in run.steps], tick)
        for run in bus_runs:
            if run.failure is None:
                _verify(run, links[bus], costs[bus], tick, may_release_axes)

    per_bus = _by_bus(runs)
    with ThreadPoolExecutor(max_workers=max(1, len(per_bus))) as pool:
        for future in [pool.submit(on_bus, bus, bus_runs) for bus, bus_runs in per_bus.items()]:
            future.result()
