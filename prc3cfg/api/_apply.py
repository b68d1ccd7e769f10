"""Apply and restore: the workflow from the read-back (or a plan file, proved) to the written modules.

`apply` and `restore` check what must hold before a line is opened (a reason, parity, records that
can be kept), read back and plan the whole plant and pass the `Gates`, or — with no
question to ask — write each line as soon as its plan is whole (`prc3cfg.shell.by_line`). Plan files:
`read_plan`, `prove`, `plan_document`, `plan_file_plant`. Does not own the writes, the snapshot and
the journal (`prc3cfg.shell.engine`), nor what a plan file is (`prc3cfg.core.plan_file`).
"""

from __future__ import annotations

import contextlib
import hashlib
import time
from collections.abc import Callable, Collection, Iterable, Mapping
from dataclasses import replace
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from prc3cfg.api._plan import (
    Reads,
    commissioned,
    make_plan,
    plan_file_pairs,
    plan_file_reads,
    read_and_plan,
    read_input,
    read_targets,
    reads,
    record,
    select,
    shared_planner,
    to_plan,
    unset_systems,
)
from prc3cfg.api._plant import reason_for
from prc3cfg.api._policy import PolicyReport, policy
from prc3cfg.api._types import (
    ApplyFailed,
    ApplyInterrupted,
    ApplyResult,
    AxisReleaseRefused,
    Gates,
    NotApproved,
    Pairs,
    RecordsFailed,
)
from prc3cfg.core import plan_file, what_to_read
from prc3cfg.core.image import Key, ModuleImage
from prc3cfg.core.plan_file import RECORD, PlanFile
from prc3cfg.core.plant_plan import PlantPlan
from prc3cfg.core.stages import Consent, LinePlan
from prc3cfg.errors import Interrupted, UserError
from prc3cfg.plant import Bus, Plant
from prc3cfg.shell import audit, line_record, machine_folder, pending_records
from prc3cfg.shell.apply import Verify
from prc3cfg.shell.by_line import ByLine, LinePlanned, next_stage
from prc3cfg.shell.cancel import Cancellation
from prc3cfg.shell.engine import APPLIED, Keeping, Writing, Written
from prc3cfg.shell.plant_files import load_plant
from prc3cfg.shell.records import Journal, Snapshot, applied_copy, check_writable, save_applied
from prc3cfg.shell.records import header as run_header
from prc3cfg.shell.sessions import LineOptions, OnRecord, bus_line_keys, line_cost, lines

if TYPE_CHECKING:
    from prc3cfg.shell.link.client import Link


def read_plan(path: Path, plant: Plant) -> PlanFile:
    """A plan file, refused (one line) when damaged, made by another prc3cfg or for another plant file."""
    try:
        alike = plan_file.same_text(plant.path.read_bytes())
    # gone since it was loaded: the plant file's own digest alone, which the lines' check then finds changed
    except OSError:
        alike = frozenset()
    return plan_file.to_apply(_plan_input(path), path, plant.path, plant.sha256, alike, plant.name)


def plan_document(path: Path) -> dict[str, Any]:
    """A plan file to show (`prc3cfg show PLAN.json`), checked, its summaries worked out again from its
    bytes."""
    return plan_file.to_show(_plan_input(path), path)


def _plan_input(path: Path) -> Any:
    return read_input(path, "the plan file prc3cfg plan --out wrote", "make the plan again",
                      plan_file.PLAN_LIMIT)


def plan_file_plant(path: Path) -> Path:
    """The plant file a plan file was made from, where it says it is."""
    document = _plan_input(path)
    try:
        plan_file.within_bounds(document)  # what it says is shown: a name of 10 MB is not
    except plan_file.PlanFileError as error:
        raise UserError(f"{path}: {error}") from None
    recorded = document.get("plant_path") if isinstance(document, dict) else None
    if not isinstance(recorded, str) or not Path(recorded).is_file():
        raise UserError(f"{path}: the plant file it was made from is not at {recorded!r} — name it: "
                        f"prc3cfg apply PLANT --plan {path}")
    return Path(recorded)


def prove(path: Path, planned: PlanFile, plant: Plant, pairs: Pairs, images: dict[Key, ModuleImage],
          held: OnRecord,
          links: Mapping[str, Link] | None = None) -> PlantPlan:
    """The plan file's plan, proved before anything is written (`prc3cfg.core.plan_file`): what is
    applied is then the plan prc3cfg makes from this read-back."""
    modules = {(bus.name, m.address): (bus, m) for bus, m in pairs}
    plan_file.check_modules(path, planned, {key: m.name for key, (_, m) in modules.items()}, images)
    chosen = [modules[(entry.bus, entry.address)] for entry in planned.modules]
    buses = {bus.name: bus for bus, _ in chosen}.values()
    ours = make_plan(plant, chosen, images, links=links, unset=unset_systems(buses, held),
                     only_read=planned.targeted)
    # what this apply read, and whose verification what it did not read rests on: its line's record now
    if planned.targeted:
        ours = replace(ours, reading=Reads(chosen, [], RECORD, known=record(held)).reading(pairs, images))
    plan_file.check_plan(path, planned, ours, {bus.name: line_cost(bus) for bus, _ in chosen})
    return ours


def apply(
    plant: Plant,
    modules: Iterable[str] | None = None,
    *,
    plan_file: Path | None = None,
    gates: Gates = Gates(),
    verify: Verify = Verify.FLOOR,
    options: LineOptions | None = None,
    previous: Path | None = None,
    full_read: bool = False,
    reason: str | None = None,
    links: Mapping[str, Link] | None = None,
    overrides: Mapping[str, str] | None = None,
    now: datetime | None = None,
) -> ApplyResult:
    """Lock, read back, plan (or prove `plan_file`), pass the `gates`, snapshot, write, verify.

    What is read back is what `plan` reads (`previous`, `full_read`); for `plan_file`, exactly
    what its plan read. `reason` (else `PRC3CFG_REASON`) goes into the records' header — a bus
    with `require_reason` refuses to start without one. The plant's policy is judged at `now` (default:
    `_policy.policy_now`) before the line is opened: `PolicyRefused` unless what refuses is soft and its kind
    is in `overrides` (kind → reason), which the header records with the user. Returns the result when every
    module verified; raises `ApplyFailed` or `ApplyInterrupted`, each with the result, otherwise; before
    anything is written, any other `UserError`.
    """
    # before any time on the line
    planned = None if plan_file is None else (plan_file, read_plan(plan_file, plant))
    pairs = select(plant, modules)
    # just before the line opens (a window may have opened since the plan), on what the apply writes: a plan
    # file's modules with steps — another line's window does not hold back a plan file for this one
    writes = modules if planned is None else [m.name for bus, m in pairs
                                              if (bus.name, m.address) in _with_steps(planned[1])]
    said = _policy_gate(policy(plant, writes, now) if writes is None or writes else None, overrides, options)

    def wanted(held: OnRecord) -> Reads:
        if planned is not None:
            return plan_file_reads(*planned, pairs, held)
        # a factory-fresh module is commissioned: the programs it will be written are not read
        # first, but after
        return reads(plant, pairs, True, held) if full_read else commissioned(reads(plant, pairs, held=held))

    on_lines = pairs if planned is None else plan_file_pairs(planned[1], pairs)
    return _apply(plant, pairs, on_lines, wanted, None, planned, gates, verify, options or LineOptions(),
                  reason=reason, links=links,
                  policy_said=said)


def _with_steps(planned: PlanFile) -> set[Key]:
    """The modules a plan file writes to: those with steps."""
    return {(entry.bus, entry.address) for entry in planned.modules if entry.steps}


def _policy_gate(judged: PolicyReport | None, overrides: Mapping[str, str] | None,
                 options: LineOptions | None) -> dict[str, Any] | None:
    """What the policy's `gate` lets through, for the journal's header (`PolicyRefused` otherwise); each
    advisory finding and each override said."""
    said = None if judged is None else judged.gate(overrides or {})
    for finding, line in () if judged is None else judged.findings:
        if finding.level == "advisory":
            (options or LineOptions()).tell(line)
    for overridden in (said or {}).get("overridden", ()):
        (options or LineOptions()).tell(f"{overridden['finding']} — overridden by {overridden['user']}: "
                                        f"{overridden['reason']}")
    return said


def restore(snapshot: Path, *, gates: Gates = Gates(), verify: Verify = Verify.FLOOR,
            options: LineOptions | None = None,
            onto_current_lines: bool = False, reason: str | None = None,
            links: Mapping[str, Link] | None = None,
            overrides: Mapping[str, str] | None = None, now: datetime | None = None) -> ApplyResult:
    """Plan and apply the modules back to what a snapshot holds, with the same gates as `apply` —
    onto the lines it was taken on: a bus of the plant file that now names another line (port or
    framing) is refused, unless `onto_current_lines`; and a snapshot that its journal does not
    show as written (`prc3cfg.shell.audit.snapshot_checked`) is refused. The plant's policy windows
    are judged at `now` as `apply` judges them (`overrides`); no envelope judges a snapshot."""
    options = options or LineOptions()
    taken = Snapshot.load(snapshot)
    if (note := audit.snapshot_checked(snapshot, taken)) is not None:
        options.tell(note)
    plant = load_plant(taken.plant_path)
    pairs = [(bus, m) for bus, m in plant.modules() if (bus.name, m.address) in taken.images]
    if len(pairs) != len(taken.images):
        raise UserError(f"{snapshot}: the plant file {taken.plant_path} no longer has every module of the "
                        "snapshot — nothing was written")
    for bus in {bus.name: bus for bus, _ in pairs}.values():
        line = taken.lines.get(bus.name)
        if line is None or onto_current_lines:
            continue
        if not line.same_line(bus.port, bus.framing, bus_line_keys(plant, bus)):
            raise UserError(f"{snapshot}: taken on bus {bus.name} at {line.port} ({line.framing}), which "
                            f"the plant file now puts at {bus.port} ({bus.framing}) — restoring there would "
                            "write one line's modules onto another; nothing was written: give "
                            "--onto-current-lines if that is what you mean")
    judged = policy(plant, [m.name for _, m in pairs], now)
    said = _policy_gate(None if judged is None else judged.only("window"), overrides, options)
    # every program the snapshot holds
    wanted = Reads(pairs, what_to_read.in_full(to_plan(pairs, taken.images)))
    return _apply(plant, pairs, pairs, lambda _: wanted, taken.images, None, gates, verify, options,
                  reason=reason, links=links,
                  policy_said=said)


def _apply(plant: Plant, chosen: Pairs, on_lines: Pairs, wanted_of: Callable[[OnRecord], Reads],
           desired: dict[Key, ModuleImage] | None, plan_file: tuple[Path, PlanFile] | None, gates: Gates,
           verify: Verify,
           options: LineOptions, *, reason: str | None = None, links: Mapping[str, Link] | None = None,
           policy_said: dict[str, Any] | None = None) -> ApplyResult:
    """Apply (or restore) `chosen`, reading the modules `on_lines`: what to read of them is worked out from
    the lines' records as read under the lines' locks (`wanted_of`); `policy_said` (what the policy found and
    what was overridden) goes into the journal's header."""
    buses = {bus.name: bus for bus, _ in on_lines}
    command = "restore" if desired is not None else "apply"
    reason = _ready(plant, buses.values(), reason, command)
    said = run_header(command, plant.path, plant.name, plant.sha256, reason=reason,
                      plan_file=plan_file[0] if plan_file else None,
                      argv=options.command_line, policy=policy_said)
    # its file is made at the first record: not for a busy line
    journal = Journal(plant.path, said, audit.follow(plant.path))
    records = pending_records.Releases(command, journal.path)
    # each line's identities, resolved once
    keys = {name: bus_line_keys(plant, bus) for name, bus in buses.items()}
    if options.cancel is None:  # the event that stops the lines when a record cannot be kept
        options = replace(options, cancel=Cancellation())
    assert options.cancel is not None
    keeping = Keeping(plant, buses, keys, journal, records, options.cancel.event)
    try:
        with lines(plant, buses, options, purpose="apply", observer=keeping.observe,
                   announce=keeping.announce, records=keeping,
                   given=links, identities=keys) as held:
            earlier = tuple(r for r in held.on_record.pending if r.kind == pending_records.RELEASE)
            wanted = wanted_of(held.on_record)
            writing = Writing(plant, keys, buses, held, keeping, verify, options, records.command)
            whole = None
            if plan_file is not None or gates.asks:
                try:
                    whole = _whole_plan(plant, chosen, wanted, desired, plan_file, gates, writing, options)
                except Interrupted:
                    keeping.stopped_reading()
                    raise
            # from the first read when each line is written as soon as its plan is whole, else from the
            # snapshot, to the end of the account, a signal waits its turn
            with options.deferred():
                written = (_by_line(plant, wanted, chosen, desired, gates, writing) if whole is None
                           else _write_whole(writing, *whole))
                if written.verified and desired is None and len(chosen) == len(plant.modules()):
                    written = _keep_applied(plant, written, keeping)
                return _judged(written, journal.path, earlier, records,
                               at_once=not any(link.takes_line_time for link in held.links.values()))
    except (ApplyFailed, ApplyInterrupted):
        raise  # a result: its journal says what was written
    # refused before any write (a gate, a stale plan, a line): the journal it began says why
    except UserError as stopped:
        if journal.begun:
            with contextlib.suppress(OSError):  # not kept: the refusal itself is what the person is told
                journal.record("refused", why=str(stopped))
        raise
    finally:
        keeping.close()


def _ready(plant: Plant, buses: Collection[Bus], reason: str | None, command: str) -> str | None:
    """What must hold before an apply opens a line: a reason where a bus requires one (`reason_for`,
    given back), error detection or its risk accepted, and records that can be kept."""
    reason = reason_for(plant, buses, reason, command)
    for bus in buses:
        if not bus.detects_damage and not bus.accept_undetected_damage:
            raise UserError(f"{plant.path}: bus {bus.name}: {bus.framing} with parity none detects no "
                            "damage — a damaged frame can "
                            "become another write, a read a write, a module's address the broadcast 0; "
                            "nothing was written: set "
                            "parity: even (or odd) on the bus and its devices, or accept the risk with "
                            "accept_undetected_damage: true")
    check_writable(plant.path)  # before the line: an apply that cannot keep its records writes nothing
    # nor one that could not record an axis release before its frame, or drop a module from its line's record
    machine_folder.folder()
    machine_folder.folder(line_record.KIND, line_record.WHAT)
    return reason


def _judged(written: Written, journal: Path, earlier: tuple[pending_records.Pending, ...],
            records: pending_records.Releases, *, at_once: bool) -> ApplyResult:
    """The result of what the writes came to: `RecordsFailed`, `ApplyInterrupted` or `ApplyFailed`
    unless every module verified."""
    result = ApplyResult(written.plan, written.runs, written.snapshot, journal, earlier, records.path,
                         written.took, written.unread, at_once)
    if written.trouble is not None:
        raise RecordsFailed(result, written.trouble, written.lost)
    if written.interrupted:
        raise ApplyInterrupted(result)
    if not result.verified:
        raise ApplyFailed(result)
    return result


def _by_line(plant: Plant, wanted: Reads, chosen: Pairs, desired: dict[Key, ModuleImage] | None, gates: Gates,
             writing: Writing) -> Written:
    """No question stands between the plan and the writes (`Gates.asks`): each line written as soon as its own
    plan is whole (`ByLine`); here, between the stages the lines' threads run, each line's plan shown before
    its writes (`Gates.show_line`) and gated (`gate`, the consent sent back to the line), and the plant's
    shown once whole (`Gates.show`), with what it read (`Reads.reading`)."""
    planner = shared_planner(plant, wanted.pairs, writing.held.on_record, desired,
                             only_read=wanted.base is not None,
                             from_factory=wanted.from_factory)
    by_line = ByLine(writing, planner, wanted.targets)
    stages = by_line.run()
    consent: Consent | None = None
    while (planned := next_stage(stages, consent)) is not None:
        consent = None
        if isinstance(planned, LinePlanned):
            if gates.show_line is not None:
                gates.show_line(planned.plan)
            consent = gate(planned.plan, gates, writing.command)
            continue
        the_plan = replace(planned.plan, reading=wanted.reading(chosen, planned.read), by_line=True)
        if gates.show is not None:
            gates.show(the_plan)
        writing.whole(the_plan, planned.at)
    written = by_line.account()
    return replace(written, plan=replace(written.plan, reading=wanted.reading(chosen, by_line.images),
                                         by_line=True))


def _whole_plan(plant: Plant, chosen: Pairs, wanted: Reads, desired: dict[Key, ModuleImage] | None,
                plan_file: tuple[Path, PlanFile] | None,
                gates: Gates, writing: Writing,
                options: LineOptions) -> tuple[PlantPlan, dict[Key, ModuleImage], Consent, float]:
    """Read back and plan the whole plant (or prove the plan file), show it and pass the gate: the plan, what
    was read, the consent to release axes the answers gave (`gate`), and the seconds the reading took."""
    pairs, to_read, links = wanted.pairs, wanted.targets, writing.links
    started = time.monotonic()
    if plan_file is None:
        images, the_plan = read_and_plan(plant, pairs, to_read, writing.held, options, desired,
                                         command=writing.command,
                                          only_read=wanted.base is not None, from_factory=wanted.from_factory)
        the_plan = replace(the_plan, reading=wanted.reading(chosen, images))
    else:
        images = read_targets(to_read, writing.held, options, writing.command, plant)
        the_plan = prove(*plan_file, plant, chosen, images, writing.held.on_record, links)
    reading = time.monotonic() - started
    if gates.show is not None:
        gates.show(the_plan)
    return the_plan, images, gate(the_plan, gates, writing.command), reading


def gate(the_plan: PlantPlan, gates: Gates, command: str) -> Consent:
    """The gate stage, between the plan and the writes — a line's plan or the plant's — on the caller's
    thread: the modules whose axes the answers consent to release (`Gates.allow_axis_release`, asked only when
    the plan releases any), once `Gates.approve` approved the plan; `AxisReleaseRefused` or `NotApproved`
    else, nothing written. A plan that changes nothing asks nothing."""
    if not the_plan.changes:
        return Consent()
    releasing = [f"{m.bus}/{m.name}" for m in the_plan.axis_releases]
    allow = gates.allow_axis_release
    allowed = allow(releasing) if callable(allow) and releasing else allow is True
    if releasing and not allowed:
        raise AxisReleaseRefused(
            f"the plan releases the axes of {', '.join(releasing)} (10h/20h: they must travel to their "
            f"reference point before production) — nothing was written; {command} again with "
            "--allow-axis-release"
        )
    if gates.approve is not None and not gates.approve(the_plan):
        raise NotApproved(f"not {'restored' if command == 'restore' else 'applied'} — nothing was written")
    return Consent(frozenset((m.bus, m.address) for m in the_plan.axis_releases) if allowed else frozenset())


def _write_whole(writing: Writing, the_plan: PlantPlan, images: dict[Key, ModuleImage], consent: Consent,
                 reading: float) -> Written:
    """The whole plan written, every line at once: the write stages (`Writing.write`) of every line's changes,
    the account."""
    if not the_plan.changes:
        return Written(the_plan)
    writing.whole(the_plan)
    writing.write(LinePlan(the_plan.modules, images), consent)
    return writing.account(the_plan, {"reading": reading})


def told(result: ApplyResult) -> None:
    """The account of `result` — `released` and `earlier` — has been shown to the operator: the
    records of those releases, kept on disk since before their frames left, can go
    (`prc3cfg.shell.pending_records`). Until this is called, every command on these lines warns of them."""
    pending_records.told(result.records, result.earlier)


def _keep_applied(plant: Plant, written: Written, keeping: Keeping) -> Written:
    """The plant file just applied in full and verified on every module, kept for `left_alone` — if
    it is still the one applied (gone or changed: `left_alone` goes on comparing with the copy an
    earlier apply kept). A copy the disk refuses is the apply's trouble: the account says so."""
    try:
        text = plant.path.read_bytes()
    except OSError:
        return written
    if hashlib.sha256(text).hexdigest() != plant.sha256:
        return written
    try:
        save_applied(plant.path, text)
    except OSError as error:
        keeping.failed(APPLIED, error, applied_copy(plant.path))
        return replace(written, trouble=keeping.trouble, lost=tuple(keeping.lost))
    return written
