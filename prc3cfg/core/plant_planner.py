"""A plant's plan, made line by line: each line planned as soon as its modules are read.

- `Line`: a line as the planning sees it — what its exchanges cost, which addresses the plant
  lists there and whether it says it lists every module of the line, how long a probe waits.
- `Wanted`: one module to plan, with the image it should hold.
- `PlanCache`: the module plans of a plant by what they depend on (`broadcast_search.alike`), so that
  modules alike on any line are planned once (a plant commissioned from factory defaults is one
  plan per line profile), and the broadcast search's memo.
- `Planner`: the plan of each line — its modules' own plans (each as soon as its module is
  read: `plan_module`), then its broadcasts where every receiver is known — and the plant's plan
  from them (`PlantPlan`).

A broadcast reaches every module on the line, so it needs proof that nobody else is there. A
line is planned in two steps, and the proof is got between them by the caller: `draft_line`
plans it and names, in `LineDraft.to_prove`, the addresses the plant does not list that must be
found silent for the broadcasts that save line time; the caller probes them on the line, under
its lock, in this run (`prc3cfg.shell.planning`), and `settle_line` takes what answered — or None,
where it could not probe (planning from saved images): no broadcast then. Reading the modules,
locking and probing the lines is the caller's, and so is taking turns with one planner among
the lines' threads (`prc3cfg.shell.planning.SharedPlanner`); what a plant file says, the
plant's (`prc3cfg.plant`). Pure: nothing here reads or writes outside, calls out or locks.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from math import fsum

from prc3cfg.core import broadcast_search, codec, what_to_read
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.image import MAX_MODULE_ADDRESS, Key, ModuleImage, Wanted
from prc3cfg.core.planner import ModulePlan, UnreachableImage, plan_module
from prc3cfg.core.plant_plan import LineProof, ModuleChange, PlantPlan
from prc3cfg.errors import UserError

#: Which of the addresses given answer a 50h (`PROOF_PROBES` tries each): the line's, under its lock.

#: The longest a probe waits at an address (or the line's time-out, if shorter) — a scan's, a
#: broadcast's proof: a module answers a 50h within tens of milliseconds even at 9600 baud.
PROBE_TIMEOUT = 0.2
#: Probes of each address the plant does not list before a broadcast: a reply lost once on a noisy
#: line must not pass for an empty address.
PROOF_PROBES = 2


@dataclass(frozen=True, slots=True)
class Line:
    """A bus's line as the planning sees it. `complete`: the plant says it lists every module of
    the line (all 30 addresses, or `only_these_modules: true`) — to be proven by probing the rest."""

    bus: str
    cost: LineCost
    listed: frozenset[int]
    complete: bool
    probe_timeout: float

    def unlisted(self) -> list[int]:
        """The addresses of the line where the plant lists no module."""
        return [a for a in range(1, MAX_MODULE_ADDRESS + 1) if a not in self.listed]

    def proof_time(self) -> float:
        """The line time of proving every unlisted address silent (`PROOF_PROBES` probes each)."""
        each = self.cost.silence_time(codec.ReadSystem(), self.probe_timeout)
        return len(self.unlisted()) * PROOF_PROBES * each


@dataclass(frozen=True, slots=True)
class _PlanKey:
    """What a module's own plan depends on: `broadcast_search.alike`, and whether it reported E12."""

    alike: tuple[object, ...]
    system_unset: bool


class PlanCache:
    """The plans of modules alike but for their address, made once; and the broadcast search's memo
    (`broadcast_search.share`)."""

    def __init__(self) -> None:
        self._plans: dict[_PlanKey, ModulePlan] = {}
        self.sharing = broadcast_search.SharingMemo()

    def plan(self, actual: ModuleImage, desired: ModuleImage, cost: LineCost,
             system_unset: bool = False) -> ModulePlan:
        """`plan_module`, once for modules alike but for their address."""
        key = _PlanKey(broadcast_search.alike(actual, desired, cost), system_unset)
        found = self._plans.get(key)
        if found is None:
            found = plan_module(actual, desired, cost, system_unset=system_unset)
            # the desired programs themselves where predicted alike: the cache holds a plan of every module
            programs = tuple(want if want == have else have
                             for have, want in zip(found.predicted.programs, desired.programs))
            found = self._plans[key] = replace(found, predicted=replace(found.predicted, programs=programs))
        if found.address == actual.address:
            return found
        return replace(found, address=actual.address,
                       predicted=replace(found.predicted, address=actual.address))


@dataclass(frozen=True, slots=True)
class LineDraft:
    """A line planned but for the proof its broadcasts need (`Planner.draft_line`): its modules' changes,
    the broadcasts that would save line time (None: none), and the addresses `to_prove` silent first."""

    bus: str
    changes: list[ModuleChange]
    shared: broadcast_search.Shared | None = None
    to_prove: tuple[int, ...] = ()


@dataclass(frozen=True, slots=True)
class _Planned:
    """One line's part of the plan: its modules' changes, its broadcasts' line time, its proof."""

    changes: list[ModuleChange]
    broadcast_time: float = 0.0
    proof: LineProof | None = None


class Planner:
    """The plan of a plant, made line by line — each line as soon as its modules are read (the lines'
    threads take turns with one planner, `prc3cfg.shell.planning`: its `PlanCache` is shared, so
    modules alike on any line are planned once).

    `only_read`: a targeted read-back — each module's desired image is cut to the programs read
    (`what_to_read.within_read`): what was not read is not written. `from_factory`: an apply's — the managed
    programs a factory-fresh module's read-back lacks are planned from the factory's (`what_to_read.assumed`),
    and written or not as they differ; the verification reads them back (`ModuleChange.assumed`)."""

    def __init__(self, plant: str, plant_path: str, plant_sha256: str, lines: Mapping[str, Line],
                 unset: frozenset[Key] = frozenset(), *, only_read: bool = False,
                 from_factory: bool = False) -> None:
        self.plant, self.plant_path, self.plant_sha256 = plant, plant_path, plant_sha256
        self.lines, self.unset, self.only_read, self.from_factory = lines, unset, only_read, from_factory
        self._cache = PlanCache()
        self._planned: dict[str, _Planned] = {}

    def plan_module(self, wanted: Wanted, actual: ModuleImage) -> None:
        """Plan one module as soon as it is read, while the rest of its line is read: its own plan is
        kept (`PlanCache`) for `draft_line`, which then only decides the line's broadcasts."""
        self._change(self.lines[wanted.bus], wanted, actual)

    def line_changes(self, bus: str) -> list[ModuleChange]:
        """The changes of a line `settle_line` settled, in the order of its modules."""
        return list(self._planned[bus].changes)

    def draft_line(self, bus: str, modules: Sequence[Wanted], actual: Mapping[Key, ModuleImage], *,
                   probing: bool = True) -> LineDraft:
        """Plan the modules of one line among `modules`, and the broadcasts that save line time — where
        the plant lists every module of the line and the plan covers them all. They need every other
        address found silent first (`to_prove`: a declaration in a file is no proof), whose probes cost
        line time the broadcasts must save too; `settle_line` takes what the probes found. Without
        `probing` (nothing can probe the line) no broadcast is searched for where one needs a proof."""
        line = self.lines[bus]
        changes = [self._change(line, wanted, actual[wanted.key]) for wanted in modules if wanted.bus == bus]
        covered = line.complete and {c.address for c in changes} == line.listed
        if not changes or not covered or (line.unlisted() and not probing):
            return LineDraft(bus, changes)
        receivers = [broadcast_search.SharingModule(c.actual, c.desired, c.plan) for c in changes]
        shared = broadcast_search.share(receivers, line.cost, self._cache.sharing, line.proof_time())
        return (LineDraft(bus, changes, shared, tuple(line.unlisted())) if shared.broadcasts
                else LineDraft(bus, changes))

    def settle_line(self, draft: LineDraft, answered: Sequence[int] | None) -> None:
        """The line's plan, of its `draft` and what answered at the addresses it had to prove silent —
        None where they could not be probed (planning from saved images): a broadcast that needs a proof
        is then left out, as where a module answered (and the plan names it: the plant file is wrong
        about its line)."""
        bus, changes, shared = draft.bus, draft.changes, draft.shared
        if shared is None or (draft.to_prove and answered is None):
            self._planned[bus] = _Planned(changes)
        elif answered:
            self._planned[bus] = _Planned(changes, proof=LineProof(bus, answered=tuple(answered)))
        else:
            line = self.lines[bus]
            changes = [replace(c, plan=plan_, broadcasts=len(shared.broadcasts))
                       for c, plan_ in zip(changes, shared.plans)]
            seconds = fsum(line.cost.broadcast_time(step.message) for step in shared.broadcasts)
            proof = LineProof(bus, silent=draft.to_prove) if draft.to_prove else None
            self._planned[bus] = _Planned(changes, seconds + (line.proof_time() if proof else 0.0), proof)

    def _change(self, line: Line, wanted: Wanted, actual: ModuleImage) -> ModuleChange:
        unset = wanted.key in self.unset
        assumed = what_to_read.assumed(wanted.desired, actual) if self.from_factory else ()
        actual = what_to_read.from_factory(actual, assumed)
        desired = what_to_read.within_read(wanted.desired, actual) if self.only_read else wanted.desired
        try:
            module_plan = self._cache.plan(actual, desired, line.cost, unset)
        except UnreachableImage as error:
            raise UserError(f"bus {wanted.bus}, module {wanted.address} ({wanted.name}): {error}") from None
        return ModuleChange(wanted.bus, wanted.name, actual, desired, module_plan, system_unset=unset,
                            cost=line.cost,
                            wanted=wanted.desired if self.only_read else None, assumed=assumed)

    def plan(self, modules: Sequence[Wanted], actual: Mapping[Key, ModuleImage]) -> PlantPlan:
        """The plant's plan, in the order of `modules`: lines not settled yet are planned now, without
        the broadcasts that need a proof (none could be got)."""
        buses = list(dict.fromkeys(wanted.bus for wanted in modules))
        for bus in buses:
            if bus not in self._planned:
                self.settle_line(self.draft_line(bus, modules, actual, probing=False), None)
        changes = {(c.bus, c.address): c for planned in self._planned.values() for c in planned.changes}
        ordered = tuple(changes[wanted.key] for wanted in modules)
        broadcast_time = fsum(planned.broadcast_time for planned in self._planned.values())
        proofs = tuple(proof for bus in buses if (proof := self._planned[bus].proof) is not None)
        return PlantPlan(self.plant, self.plant_path, self.plant_sha256, ordered, broadcast_time,
                         None if not broadcast_time else self._unshared(ordered), proofs)

    def _unshared(self, ordered: tuple[ModuleChange, ...]) -> float:
        """The same changes as addressed plans only (for the plan's "without broadcasts" figure)."""
        return fsum(self._cache.plan(c.actual, c.desired, self.lines[c.bus].cost, c.system_unset).bus_time
                    for c in ordered)
