"""Read and plan: the plant file, its modules, what to read of them, and the plan.

`load` and `select` the plant's modules; what to read (`targets`, `reads`, `Reads`, the reads of
a plan file, `plan_file_reads`) and the line's record it rests on; `read` them back, each line's
read-back into its record (`read_targets`); `plan` from the read-back, or `make_plan` from images at hand,
each module planned as soon as it is read (`read_and_plan`); `drift`, and what the plant file
leaves alone (`left_alone`). Does not own proving a plan file and writing (`prc3cfg.api._apply`),
nor the planner itself (`prc3cfg.core.plant_planner`).
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from prc3cfg.api._types import Pairs
from prc3cfg.core import what_to_read
from prc3cfg.core.device import can_clamp
from prc3cfg.core.error_codes import fault_said
from prc3cfg.core.image import MAX_MODULE_ADDRESS, Key, ModuleImage, Wanted, images_from_json
from prc3cfg.core.plan_file import RECORD, PlanFile, StalePlan
from prc3cfg.core.plant_plan import Oldest, PlantPlan, Reading
from prc3cfg.core.plant_planner import Line, Planner
from prc3cfg.core.render import Drift, drift_changes
from prc3cfg.core.text import shown
from prc3cfg.core.what_to_read import Known, Target
from prc3cfg.errors import UserError
from prc3cfg.plant import Bus, Plant, parse_plant
from prc3cfg.shell import line_record, pending_records
from prc3cfg.shell.files import JSON_LIMIT, FileProblem, Why, read_json
from prc3cfg.shell.planning import SharedPlanner, read_and_plan_lines, read_lines
from prc3cfg.shell.plant_files import load_plant, plant_bytes
from prc3cfg.shell.platform import resolved
from prc3cfg.shell.probe import probe_timeout
from prc3cfg.shell.records import applied_copy
from prc3cfg.shell.sessions import LineOptions, Lines, OnRecord, bus_line_keys, line_cost, lines, on_record

if TYPE_CHECKING:
    from prc3cfg.shell.link.client import Link


def load(path: str | Path) -> Plant:
    """The plant file at `path`; `PlantError` with every problem, one line each."""
    return load_plant(path)


def select(plant: Plant, names: Iterable[str] | None = None) -> Pairs:
    """(bus, module) pairs of the plant, limited to the named modules; unknown names are an error."""
    pairs = list(plant.modules())
    if not names:
        return pairs
    wanted = set(names)
    unknown = wanted - {module.name for _, module in pairs}
    if unknown:
        raise UserError(
            f"{plant.path}: no module named {', '.join(sorted(unknown))} — the plant's modules are "
            + ", ".join(module.name for _, module in pairs)
        )
    return [(bus, module) for bus, module in pairs if module.name in wanted]


def targets(pairs: Pairs) -> list[Target]:
    """What to read of each module: its managed programs, and every program its plant system
    parameters could clamp."""
    return what_to_read.in_full(to_plan(pairs, None))


def record(held: OnRecord) -> dict[Key, Known]:
    """What the records of these buses' lines say their modules hold, by (bus, address)."""
    return {(bus, address): known for bus, line in held.records.items()
            for address, known in line.known().items()}


def as_it_stands(plant: Plant, buses: Iterable[Bus]) -> OnRecord:
    """What is on record of these buses' lines, read now — outside a command holding the lines (`lines` reads
    it under their locks)."""
    return on_record({bus.name: bus_line_keys(plant, bus) for bus in buses})


@dataclass(frozen=True)
class Reads:
    """What a plan reads: the modules (of those chosen) and their targets, and for a targeted
    read-back the record it was compared with, in words (None: every chosen module in full), the
    modules read in full with why ("bus/name (why)", worked out from the targets and the
    read-back) and whose verification the programs not read rest on (`known`). Nothing of it is
    taken from a plan file."""

    pairs: Pairs
    targets: list[Target]
    base: str | None = None
    # read in full before any evidence: not on record, too old, E12
    why: dict[Key, str] = field(default_factory=dict)
    known: dict[Key, Known] = field(default_factory=dict)
    # an apply's: factory-fresh modules' managed programs planned from the factory's (`commissioned`)
    from_factory: bool = False

    def reading(self, chosen: Pairs, images: dict[Key, ModuleImage]) -> Reading | None:
        """What the plan says it read now and took as known, once `images` are read."""
        if self.base is None:
            return None
        unread = tuple(f"{bus.name}/{m.name}" for bus, m in chosen if (bus.name, m.address) not in images)
        skipped = {key: self._taken(m.desired_image(), images[key]) for bus, m in chosen
                   if (key := (bus.name, m.address)) in images}
        other = what_to_read.read_in_full(to_plan(chosen, None), self.targets, images, self.why)
        # a module whose programs were not read is on the record (`to_read`), but for an apply
        # of a plan file whose record changed since: left out, and the plan file's `taken`
        # then refused (`plan_file.check_plan`)
        resting = {f"{bus.name}/{m.name}": self.known[key] for bus, m in chosen
                   if skipped.get(key := (bus.name, m.address)) and key in self.known}
        oldest = min(resting.items(), key=lambda item: datetime.fromisoformat(item[1].since), default=None)
        return Reading(self.base, unread, skipped, other,
                       {name: known.said() for name, known in resting.items()},
                       None if oldest is None else Oldest(oldest[0], oldest[1].since, oldest[1].by))

    def _taken(self, desired: ModuleImage, image: ModuleImage) -> tuple[int, ...]:
        """The managed programs `image` lacks that were taken from the line's record: not those planned from
        the factory's."""
        assumed = what_to_read.assumed(desired, image) if self.from_factory else ()
        return tuple(n for n in what_to_read.not_read(desired, image) if n not in assumed)


def commissioned(wanted: Reads) -> Reads:
    """An apply's reads: a factory-fresh module's managed programs planned from the factory's, not read before
    writing, and read back after (`what_to_read.factory_fresh`)."""
    return replace(wanted, targets=what_to_read.commissioning(wanted.targets), from_factory=True)


def reads(plant: Plant, pairs: Pairs, full_read: bool = False, held: OnRecord | None = None) -> Reads:
    """What to read of the chosen modules: everything (`targets`) with `full_read` or when the lines'
    records know none of them; else of each module its system block and the managed programs the
    record does not show holding the plant file's values (`what_to_read.for_plan`) — every managed
    program of one the record does not know, knows from too long ago, or that reported E12 since; and
    every program of the module of each line whose record is the oldest (`what_to_read.with_rolling`).
    `held`: what is on record of the lines, as the command holding them read it (else read now)."""
    buses = {bus.name: bus for bus, _ in pairs}
    held = as_it_stands(plant, buses.values()) if held is None else held
    known: dict[Key, Known] = {}
    overruled: dict[Key, str] = {}
    for bus in () if full_read else buses.values():
        on_line, newer = held.records[bus.name].entries()
        known |= {(bus.name, address): k for address, k in on_line.items()}
        overruled |= {(bus.name, address): said for address, said in newer.items()}
    # another user's E12: read the module in full, never write for it
    for key, said in e12_claims(buses.values(), held).items():
        known.pop(key, None)
        overruled.setdefault(key, said)
    # of no use without a record
    unset = unset_systems(buses.values(), held) if known or overruled else frozenset()
    max_age = {name: bus.record_max_age for name, bus in buses.items()}
    targeted = what_to_read.for_plan(to_plan(pairs, None), known, overruled, unset, max_age,
                                     datetime.now(UTC))
    if targeted is None:
        return Reads(pairs, targets(pairs))
    to_read, why = what_to_read.with_rolling(*targeted, known)
    return Reads(pairs, to_read, RECORD, why=why, known=known)


def read_targets(targets_: list[Target], held: Lines, options: LineOptions, command: str, plant: Plant,
                 planner: SharedPlanner | None = None) -> dict[Key, ModuleImage]:
    """Every target read back, each line's read-back into its record as `command`'s (`planning.read_lines`) —
    with a `planner`, each module planned as soon as it is read and each line as soon as its last module is,
    while the other lines are still being read: the lines never wait for all of the planning. A Ctrl-C stops
    after the exchange in flight (`Interrupted`) — also one that came during the last exchanges, when the read
    ended anyway: it is not forgotten."""
    options.progress.start("reading modules", len(targets_))
    with options.deferred():
        by, advance = line_record.who(command, plant.path), options.progress.advance
        links, on_record = held.links, held.on_record
        images = (read_lines(targets_, links, on_record, by, progress=advance) if planner is None
                  else read_and_plan_lines(targets_, links, on_record, by, planner, progress=advance))
    if options.cancel is not None:
        options.cancel.check()
    return images


def read_and_plan(plant: Plant, pairs: Pairs, to_read: list[Target], held: Lines, options: LineOptions,
                  desired: dict[Key, ModuleImage] | None = None, *, command: str,
                  only_read: bool = False,
                  from_factory: bool = False) -> tuple[dict[Key, ModuleImage], PlantPlan]:
    """Read back and plan (`read_targets` with a planner). `only_read`, `from_factory`: see `Planner`."""
    planner = shared_planner(plant, pairs, held.on_record, desired, only_read=only_read,
                             from_factory=from_factory)
    images = read_targets(to_read, held, options, command, plant, planner)
    return images, planner.plan(images)


def shared_planner(plant: Plant, pairs: Pairs, held: OnRecord, desired: dict[Key, ModuleImage] | None = None,
                   *,
                   only_read: bool = False, from_factory: bool = False) -> SharedPlanner:
    """The planner of these modules to `desired` (else the plant file's) the lines' threads share, with the
    E12s on record (`unset_systems`). `only_read`, `from_factory`: see `Planner`."""
    unset = unset_systems({bus.name: bus for bus, _ in pairs}.values(), held)
    return SharedPlanner(planner_for(plant, pairs, unset, only_read=only_read, from_factory=from_factory),
                         to_plan(pairs, desired))


def read(plant: Plant, modules: Iterable[str] | None = None, options: LineOptions | None = None, *,
         command: str = "read", links: Mapping[str, Link] | None = None) -> dict[Key, ModuleImage]:
    """Read back the chosen modules: system parameters, managed programs, and every program the
    plant's system parameters could clamp — by (bus, address); what was read goes into the lines'
    records as `command`'s. Over the plant file's ports, or the `links` given by bus, already open
    (every function that reads takes them)."""
    options = options or LineOptions()
    pairs = select(plant, modules)
    with lines(plant, {bus.name for bus, _ in pairs}, options, given=links) as held:
        return read_targets(targets(pairs), held, options, command, plant)


def load_images(path: Path, plant: Plant, modules: Iterable[str] | None = None) -> dict[Key, ModuleImage]:
    """Module images saved by `prc3cfg read --json`, matched to the plant's modules by bus and address."""
    remedy = "save the images again with prc3cfg read --json"
    entries = read_input(path, "the file prc3cfg read --json wrote", remedy)
    try:
        saved = [(entry.get("bus"), image) for entry, image in zip(entries, images_from_json(entries))]
    except ValueError as error:
        raise UserError(f"{path}: not a list of module images as `prc3cfg read --json` writes ({error}) "
                        f"— {remedy}") from None
    # 32 × 30 modules: not every image for every module
    by_address: dict[int, list[tuple[Any, ModuleImage]]] = {}
    for bus_name, image in saved:
        by_address.setdefault(image.address, []).append((bus_name, image))
    images: dict[Key, ModuleImage] = {}
    for bus, module in select(plant, modules):
        found = [img for b, img in by_address.get(module.address, ()) if b in (None, bus.name)]
        if len(found) != 1:
            raise UserError(
                f"{path}: {'no' if not found else 'more than one'} image for bus {bus.name}, module "
                f"{module.address} ({module.name}) — {remedy}"
            )
        missing = [n for n in module.managed_programs() if found[0].programs[n - 1] is None]
        if missing:
            raise UserError(f"{path}: the image of bus {bus.name}, module {module.address} lacks program "
                            f"{missing[0]}, "
                            f"which the plant manages — {remedy}")
        unread = [n for n, p in enumerate(found[0].programs, start=1) if p is None]
        if unread and can_clamp(found[0].system, module.desired_system()):
            raise UserError(f"{path}: the image of bus {bus.name}, module {module.address} lacks program "
                            f"{unread[0]}, "
                            f"which the plant's system parameters would clamp — {remedy}")
        images[(bus.name, module.address)] = found[0]
    return images


def read_input(path: Path, what: str, remedy: str, limit: int = JSON_LIMIT) -> Any:
    """A JSON file prc3cfg wrote (`what`: "the plan file …"), within `limit` bytes; one line otherwise."""
    try:
        return read_json(path, limit)
    except FileProblem as problem:
        raise UserError(f"{problem.where(path)}: {problem} — "
                        f"{remedy if problem.why is Why.NOT_JSON else f'name {what}'}") from None


def plan(plant: Plant, modules: Iterable[str] | None = None, *, images: dict[Key, ModuleImage] | None = None,
         options: LineOptions | None = None, previous: Path | None = None, full_read: bool = False,
         links: Mapping[str, Link] | None = None) -> PlantPlan:
    """The cheapest plan from what the modules hold (read back now, or `images` as `read` or
    `load_images` gave them) to the plant file. Read back now: only what the change from a base
    touches (`previous`, else the plant file last applied in full here: `base`, `reads`) — every
    chosen module in full without a base, or with `full_read`."""
    options = options or LineOptions()
    pairs = select(plant, modules)
    if images is not None:
        return make_plan(plant, pairs, images)
    with lines(plant, {bus.name for bus, _ in pairs}, options, purpose="plan", given=links) as held:
        wanted = reads(plant, pairs, full_read, held.on_record)
        read_, planned = read_and_plan(plant, wanted.pairs, wanted.targets, held, options, command="plan",
                                        only_read=wanted.base is not None)
        return replace(planned, reading=wanted.reading(pairs, read_), faults=in_fault(pairs, held.on_record))


def in_fault(pairs: Pairs, held: OnRecord) -> tuple[str, ...]:
    """The chosen modules a write found in a fault state (E09, E21, …) that no write since was acknowledged
    by, as the plan's headline names them: "booth-a/booth-a-right is in E21 (positioning error)" — another
    user's record told as their claim (`pending_records.Pending.owner`). From the lines' records as read under
    their locks (`OnRecord`)."""
    chosen = {(bus.name, module.address): f"{bus.name}/{module.name}" for bus, module in pairs}
    said = []
    for bus in dict.fromkeys(bus.name for bus, _ in pairs):
        for record in held.of(pending_records.FAULT, bus):
            if (bus, record.address) in chosen and record.code is not None:
                claim = f" ({record.owner}'s record says so)" if record.owner is not None else ""
                said.append(f"{chosen[bus, record.address]} is in {fault_said(record.code)}{claim}")
    return tuple(dict.fromkeys(said))


def make_plan(plant: Plant, pairs: Pairs, actual: dict[Key, ModuleImage],
              desired: dict[Key, ModuleImage] | None = None,
              links: Mapping[str, Link] | None = None, unset: frozenset[Key] = frozenset(), *,
              only_read: bool = False) -> PlantPlan:
    """Plan every chosen module from its read-back to its desired image (the plant file's by default),
    then broadcast what the modules of a line share, where every receiver is known — proven by the
    line's probes on its link in `links` (`SharedPlanner.plan_line`). `only_read`: see `Planner`."""
    planner = SharedPlanner(planner_for(plant, pairs, unset, only_read=only_read), to_plan(pairs, desired))
    for bus in dict.fromkeys(w.bus for w in planner.wanted):
        if links is not None and bus in links:
            planner.plan_line(bus, actual, links[bus])
    return planner.plan(actual)


def planner_for(plant: Plant, pairs: Pairs, unset: frozenset[Key], *, only_read: bool = False,
                from_factory: bool = False) -> Planner:
    """A `Planner` of the lines of these modules' buses."""
    buses = {bus.name: bus for bus, _ in pairs}
    return Planner(plant.name, str(resolved(plant.path)), plant.sha256,
                   {name: _line(bus) for name, bus in buses.items()}, unset,
                   only_read=only_read, from_factory=from_factory)


def _line(bus: Bus) -> Line:
    """A bus as the planning sees its line: complete when the plant lists all 30 addresses, or says
    it lists every module there (`only_these_modules: true`)."""
    listed = frozenset(m.address for m in bus.modules)
    complete = len(listed) == MAX_MODULE_ADDRESS or bus.only_these_modules
    return Line(bus.name, line_cost(bus), listed, complete, probe_timeout(bus.timeout))


def to_plan(pairs: Pairs, desired: dict[Key, ModuleImage] | None) -> list[Wanted]:
    """The modules to plan, each with its desired image: of `desired`, else the plant file's."""
    return [Wanted(bus.name, m.address, m.name,
                   m.desired_image() if desired is None else desired[(bus.name, m.address)])
            for bus, m in pairs]


def unset_systems(buses: Iterable[Bus], held: OnRecord) -> frozenset[Key]:
    """The modules of these buses that reported E12 to an earlier apply of this user's or root's and were
    not cleared since (as `held` has it): their plan writes the system parameters first (a 10h/20h)."""
    return frozenset((r.bus, r.address) for bus in buses for r in held.of(pending_records.E12, bus.name)
                     if r.owner is None)


def e12_claims(buses: Iterable[Bus], held: OnRecord) -> dict[Key, str]:
    """The modules of these buses another user's record says reported E12, with whose claim: a reason to
    read them in full, never to release their axes — only the module's own refusal (code 23, to a write
    of this run) or this user's or root's record makes a plan write the system parameters."""
    said = {}
    for bus in buses:
        for r in held.of(pending_records.E12, bus.name):
            # keyed by the plant's bus: the record's own bus name is part of the claim
            if r.owner is not None:
                said[(bus.name, r.address)] = (f"{r.owner}'s record says it reported E12 (system parameters "
                                               f"not set), from {shown(r.time)}")
    return said


def plan_file_reads(path: Path, planned: PlanFile, pairs: Pairs, held: OnRecord) -> Reads:
    """What to read for a plan file: every chosen module in full, or — for a plan made from a
    targeted read-back — exactly the modules and programs its plan read, with the line's record as
    evidence; refused as stale when the record no longer shows a module holding what the plan took
    as known without reading it (another apply or read since, or the record outgrew its age)."""
    if not planned.targeted:
        return Reads(pairs, targets(pairs))
    chosen = plan_file_pairs(planned, pairs)
    entries = {(e.bus, e.address): e for e in planned.modules}
    desired = {(bus.name, m.address): m.desired_image() for bus, m in chosen}
    max_age = {bus.name: bus.record_max_age for bus, _ in chosen}
    to_read, stale = what_to_read.for_plan_file([entries[key] for key in desired], desired, record(held),
                                                max_age, datetime.now(UTC))
    if stale is not None:
        raise StalePlan(f"{path}: stale plan — bus {stale.bus}, module {stale.address} ({stale.name}): the "
                        "line's record no longer shows it "
                        "holding what the plan took as known without reading it (written or read by another "
                        "run since, or "
                        "older than record_max_age); nothing was written — plan again")
    return Reads(chosen, to_read, RECORD)


def plan_file_pairs(planned: PlanFile, pairs: Pairs) -> Pairs:
    """The modules a plan file's apply reads, in the plan file's order: every chosen one, or for a targeted
    plan those of its plan among them (the rest is refused by `prove`) — picked here only."""
    if not planned.targeted:
        return pairs
    names = {(bus.name, m.address): (bus, m) for bus, m in pairs}
    return [names[(e.bus, e.address)] for e in planned.modules if (e.bus, e.address) in names]


def left_alone(plant: Plant, previous: Path | None = None) -> list[str]:
    """What the plant file no longer describes — modules, and programs under `unmanaged_programs:
    keep` — which stays on the hardware as it is: against `previous` (the plant file as it was, e.g.
    on the main branch), else against the copy last applied in full from here (`.prc3cfg/applied/`).
    A file of the plant file's own bytes — the copy after an apply, the file not edited since — leaves
    nothing out, and is not read as a plant again (8 × 30 modules: 0.5 s)."""
    path = applied_copy(plant.path) if previous is None else previous
    try:
        data = plant_bytes(path)
        before = None if hashlib.sha256(data).hexdigest() == plant.sha256 else parse_plant(path, data)
    except UserError:
        if previous is not None:
            raise  # named by the caller: its problems are said
        return []  # never applied in full here, or a copy this prc3cfg cannot read: nothing to compare
    if before is None:
        return []
    now = {(bus.name, m.address): m for bus, m in plant.modules()}
    notes = []
    for bus, old in before.modules():
        new = now.get((bus.name, old.address))
        if new is None:
            notes.append(f"{bus.name}/{old.name} (address {old.address}) is no longer in the plant file: "
                         "it stays on the hardware as it is, no longer managed")
        elif new.unmanaged_programs == "keep":
            gone = sorted(set(old.managed_programs()) - set(new.managed_programs()))
            if gone:
                which = f"program {gone[0]}" if len(gone) == 1 else f"programs {', '.join(map(str, gone))}"
                notes.append(f"{bus.name}/{new.name}: {which} no longer in the plant file "
                             "(unmanaged_programs: keep): "
                             "it stays on the module as it is")
    return notes


def drift(plant: Plant, modules: Iterable[str] | None = None, *, images: dict[Key, ModuleImage] | None = None,
          options: LineOptions | None = None, links: Mapping[str, Link] | None = None) -> list[Drift]:
    """The chosen modules that drifted from the plant file — read back now, or as `images` —
    reported as drift, not as a plan (`prc3cfg plan --refresh-only`)."""
    if images is None:
        images = read(plant, modules, options, command="plan --refresh-only", links=links)
    found = []
    for bus, module in select(plant, modules):
        said = drift_changes(module.desired_image(), images[(bus.name, module.address)])
        if said:
            found.append(Drift(bus.name, module.address, module.name,
                               tuple(change["text"] for change in said), tuple(said)))
    return found
