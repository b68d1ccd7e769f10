"""A plan for a whole plant: per bus, per module, the steps to send and what they were planned from.

A plan is data: per bus, per module, the steps to send (the PRC 3 message, exactly as it
goes on the line), what they were planned from (each module's read-back, and the plant file's hash,
so a stale plan can be refused) and what they are predicted to do. The optimiser that makes a
module's steps is `prc3cfg.core.planner`; rendering is `prc3cfg.core.render`; the plan file
`prc3cfg-plan/1`, written and read back, is `prc3cfg.core.plan_file`.

A bus may start with broadcasts (`prc3cfg.core.broadcast_search`): steps sent once to address 0 that
every module of the line processes — the leading `broadcasts` steps of each module of that bus. Pure.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from math import fsum

from prc3cfg.core.bustime import LineCost
from prc3cfg.core.image import ModuleImage
from prc3cfg.core.planner import ModulePlan, Step
from prc3cfg.core.what_to_read import read_messages, verification_time, with_known


@dataclass(frozen=True, slots=True)
class ModuleChange:
    """One module of a plant plan: where it is, what it holds, what it should hold, the steps.

    The first `broadcasts` steps are its bus's broadcasts; `plan.bus_time` counts its own steps only.
    `cost` prices its line's exchanges: what reading it back and verifying it take."""

    bus: str
    name: str
    actual: ModuleImage
    desired: ModuleImage
    plan: ModulePlan
    broadcasts: int = 0
    system_unset: bool = False  # the module reported E12: its plan writes the system parameters first
    cost: LineCost | None = None
    #: a targeted read's: the plant file's whole image, `desired` being cut to what was read — its other
    #: programs the line's record showed held (`prc3cfg.core.what_to_read`)
    wanted: ModuleImage | None = None
    #: an apply's: the managed programs planned from the factory's, not read — `actual` holds the factory's
    #: there (`what_to_read.assumed`), and the verification reads them back whatever the steps
    assumed: tuple[int, ...] = ()

    def as_known(self, image: ModuleImage) -> ModuleImage:
        """`image` (the read-back, or what the plan leaves) with the programs taken as known filled in:
        what a picture of the module's chains shows, never a chain cut where a program was not read."""
        return image if self.wanted is None else with_known(image, self.wanted)

    @property
    def reading_time(self) -> float:
        """Seconds the read-back it was planned from took on the line: a 50h and the fewest 51h/52h."""
        return 0.0 if self.cost is None else fsum(self.cost.message_time(self.address, m)
                                                  for m in read_messages(self.programs_read))

    @property
    def programs_read(self) -> tuple[int, ...]:
        """The programs its read-back read: those `actual` holds but the ones planned from the factory's."""
        return tuple(n for n, program in enumerate(self.actual.programs, 1) if program is not None
                     and n not in self.assumed)

    @property
    def verifying_time(self) -> float:
        """Seconds the verifying read-back takes on the line (`Verify.FLOOR`: what the steps can change)."""
        return 0.0 if self.cost is None else verification_time(self.actual, self.plan.predicted, self.steps,
                                                               self.cost, self.assumed)

    @property
    def address(self) -> int:
        return self.plan.address

    @property
    def steps(self) -> tuple[Step, ...]:
        return self.plan.steps

    @property
    def releases_axes(self) -> bool:
        return self.plan.releases_axes


@dataclass(frozen=True, slots=True)
class LineProof:
    """What a line's probes found at the addresses its plant file does not list (before a broadcast):
    `silent` — none answered, the broadcasts reach only the plan's modules; `answered` — modules the
    plant file does not know are on the line, so it gets no broadcast."""

    bus: str
    silent: tuple[int, ...] = ()
    answered: tuple[int, ...] = ()


@dataclass(frozen=True, slots=True)
class Oldest:
    """The oldest evidence a targeted plan took from the line's record instead of reading it: the module
    ("bus/name"), since when its record's oldest value was read or verified (ISO 8601, UTC), and by whom."""

    module: str
    since: str
    by: str


@dataclass(frozen=True, slots=True)
class Reading:
    """How a plan's read-back was targeted (`prc3cfg.core.what_to_read`): the record it was compared with,
    in words, the modules not read at all (none: every module's system block is read), per module read
    the managed programs not read — taken as known from the record, with who verified them when
    (`taken`, "bus/name" → words; the `oldest` of them) — and the modules read in full, each with why. A
    plan without one read every chosen module in full."""

    base: str
    modules_not_read: tuple[str, ...]  # "bus/name"
    programs_not_read: dict[tuple[str, int], tuple[int, ...]]
    not_as_verified: tuple[str, ...] = ()  # "bus/name (why)": read in full, not taken from the record
    # "bus/name" → whose read or verification its unread programs rest on, when
    taken: dict[str, str] = field(default_factory=dict)
    oldest: Oldest | None = None  # of the modules whose programs were taken: None when none was


@dataclass(frozen=True, slots=True)
class PlantPlan:
    """Every module's change, the broadcasts of each bus, and what they cost on the line."""

    plant: str
    plant_path: str
    plant_sha256: str
    modules: tuple[ModuleChange, ...]
    broadcast_time: float = 0.0  # every bus's broadcasts, once each, and the probes that proved them safe
    unshared_bus_time: float | None = None  # the same changes without broadcasts, where some were shared
    # per line probed: what answered at the addresses the plant does not list
    proofs: tuple[LineProof, ...] = ()
    reading: Reading | None = None  # a targeted read-back: what was read, what was taken as last verified
    #: the chosen modules a write found in a fault state (E09, E21, …) no write since was acknowledged by, as
    #: the records read with the lines said — the plan's headline words ("booth-a/booth-a-right is in E21
    #: (…)")
    faults: tuple[str, ...] = ()
    #: an apply's with no question between the plan and the writes: each line written as soon as its own plan
    #: is whole, while other lines are still read (`prc3cfg.shell.by_line`) — its time is reckoned so
    by_line: bool = False

    def proof(self, bus: str) -> LineProof | None:
        return next((p for p in self.proofs if p.bus == bus), None)

    @property
    def changes(self) -> tuple[ModuleChange, ...]:
        return tuple(m for m in self.modules if m.steps)

    @property
    def bus_time(self) -> float:
        return fsum(m.plan.bus_time for m in self.modules) + self.broadcast_time

    def phases(self) -> dict[str, float]:
        """The time the operator waits for an apply of this plan, by phase, by the bus-time model — as an
        apply measures them (`prc3cfg.shell.phases`): reading back until every line is read, writing until
        every line has written, verifying the rest. The lines run at once, each line's modules one after
        another: an apply that asks before writing (or runs a plan file) writes every line once all are
        read, one that does not (`by_line`) writes each line as soon as it is read — a line read sooner is
        written, or verified too, while another is still read. Writing counts each line's broadcasts once;
        the probes that proved them are not counted."""
        times = []
        for bus, modules in self.buses().items():
            cost = modules[0].cost
            shared = (fsum(cost.broadcast_time(step.message) for step in self.broadcasts(bus))
                      if cost is not None else 0.0)
            times.append((fsum(m.reading_time for m in modules),
                          fsum(m.plan.bus_time for m in modules) + shared,
                          fsum(m.verifying_time for m in modules)))
        read = max((r for r, _, _ in times), default=0.0)
        if not self.by_line:  # every line's writes begin together
            writing = max((w for _, w, _ in times), default=0.0)
            return {"reading": read, "writing": writing,
                    "verifying": max((w + v for _, w, v in times), default=0.0) - writing}
        written = max([read] + [r + w for r, w, _ in times])
        return {"reading": read, "writing": written - read,
                "verifying": max([written] + [r + w + v for r, w, v in times]) - written}

    def broadcasts(self, bus: str) -> tuple[Step, ...]:
        """The steps sent once to address 0 on `bus`, before any module's own steps."""
        return next((m.steps[: m.broadcasts] for m in self.modules if m.bus == bus and m.broadcasts), ())

    @property
    def naive_bus_time(self) -> float:
        return fsum(m.plan.naive_bus_time for m in self.modules)

    @property
    def message_count(self) -> int:
        """Messages on the lines: every module's own steps, and each broadcast once."""
        own = sum(len(m.steps) - m.broadcasts for m in self.modules)
        return own + sum(len(self.broadcasts(b)) for b in self.buses())

    @property
    def axis_releases(self) -> tuple[ModuleChange, ...]:
        return tuple(m for m in self.modules if m.releases_axes)

    def buses(self) -> dict[str, list[ModuleChange]]:
        grouped: dict[str, list[ModuleChange]] = {}
        for module in self.modules:
            grouped.setdefault(module.bus, []).append(module)
        return grouped
