"""`prc3cfg read`, `plan`, `apply` and `restore`: the plant file against the live modules."""

from __future__ import annotations

import contextlib
import json
import sys
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from prc3cfg import __version__, render
from prc3cfg.apply import ModuleRun, Release, Verify, execute
from prc3cfg.cli import Outcome, app, click_errors
from prc3cfg.cli.common import (
    CANCEL,
    Key,
    LockOpt,
    ModuleOpt,
    PlantArg,
    RetriesOpt,
    TraceOpt,
    check_output,
    chosen_modules,
    line_cost,
    load_actual,
    make_plan,
    plant_links,
    plant_targets,
    progress_bar,
    read_images,
    read_input,
    write_output,
)
from prc3cfg.errors import Interrupted, UserError
from prc3cfg.plant import load_plant
from prc3cfg.image import ModuleImage
from prc3cfg.planner import StepProblem, plan_from_steps
from prc3cfg.plantplan import PlanFile, PlanFileError, PlantPlan, image_sha256, read_plan_file
from prc3cfg.readback import Target
from prc3cfg.records import Journal, Snapshot

EXIT_CHANGES = 2


@app.command()
def read(
    plant: PlantArg,
    json_out: Annotated[bool, typer.Option("--json", help="Print a list of module images (device units).")] = False,
    module: ModuleOpt = None,
    trace: TraceOpt = None,
    retries: RetriesOpt = 5,
    lock_timeout: LockOpt = 0.0,
) -> None:
    """Read back every module of the plant (system parameters, managed programs, and the
    programs the plant's system parameters would clamp)."""
    loaded = load_plant(plant)
    pairs = chosen_modules(loaded, module)
    targets = plant_targets(pairs)
    with plant_links(loaded, {b.name for b, _ in pairs}, trace, retries, lock_timeout=lock_timeout) as links:
        images = read_images(targets, links)
    if json_out:
        print(json.dumps([{"bus": bus.name, **images[(bus.name, m.address)].to_json()} for bus, m in pairs], indent=1))
        return
    for bus, m in pairs:
        image = images[(bus.name, m.address)]
        print(f"bus {bus.name}, module {m.address} ({m.name})")
        print("  system: " + ", ".join(
            f"{render.field_name(k)} {render.format_value(k, v)}" for k, v in image.system.to_json().items()))  # fmt: skip
        for number, program in enumerate(image.programs, start=1):
            if program is not None:
                values = ", ".join(f"{render.field_name(k)} {render.format_value(k, v)}" for k, v in program.to_json().items() if k != "A")
                print(f"  program {number}: {values}" + (f", next {program.A}" if program.A else ""))


def _emit_plan(plan: PlantPlan, *, out: Path | None, json_out: bool, markdown: bool) -> None:
    document = plan.to_json()
    for bus in document["buses"]:
        for entry, change in zip(bus["modules"], plan.buses()[bus["name"]]):
            entry["changes"] = render.changes_json(change)
            entry["warning"] = render.AXIS_WARNING if change.releases_axes else None
    if out is not None:
        write_output(out, json.dumps(document, indent=1) + "\n", "--out")
    if json_out:
        print(json.dumps(document, indent=1))
    elif markdown:
        print(render.markdown(plan))
    else:
        print(render.human(plan))
        if out is not None:
            print(f"Plan written to {out}; apply it with: prc3cfg apply --plan {out}")


@app.command()
def plan(
    plant: PlantArg,
    out: Annotated[Optional[Path], typer.Option(callback=lambda v: check_output(v, "--out"), help="Write the plan file (prc3cfg-plan/1).")] = None,
    actual: Annotated[Optional[Path], typer.Option(help="Plan against module images saved by `read --json`.")] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the plan as JSON.")] = False,
    markdown: Annotated[bool, typer.Option("--markdown", help="Print the plan as markdown (PR comments).")] = False,
    detailed_exitcode: Annotated[bool, typer.Option("--detailed-exitcode", help="Exit 0 no changes, 2 changes, 1 error.")] = False,
    module: ModuleOpt = None,
    trace: TraceOpt = None,
    retries: RetriesOpt = 5,
    lock_timeout: LockOpt = 0.0,
) -> None:
    """Read back, diff against the plant file and print the cheapest plan."""
    check_output(out, "--out", plant=plant)
    check_output(trace, "--trace", plant=plant)
    loaded = load_plant(plant)
    pairs = chosen_modules(loaded, module)
    if actual is not None:
        images = load_actual(actual, loaded, pairs)
    else:
        with plant_links(loaded, {b.name for b, _ in pairs}, trace, retries, lock_timeout=lock_timeout, purpose="plan") as links:
            images = read_images(plant_targets(pairs), links)
    result = make_plan(loaded, pairs, images)
    _emit_plan(result, out=out, json_out=json_out, markdown=markdown)
    if detailed_exitcode and result.changes:
        raise Outcome(EXIT_CHANGES)


def _confirm(question: str, auto: bool) -> bool:
    if auto:
        return True
    if not sys.stdin.isatty():
        raise UserError(f"{question} — no terminal to ask: pass --auto-approve to apply without asking")
    return typer.confirm(question, default=False)


def _gate_axes(plan_modules: list[tuple[str, str, bool]], allow: bool, auto: bool) -> None:
    """Refuse steps that release the axes unless allowed; an interactive run asks, naming the modules."""
    releasing = [f"{bus}/{name}" for bus, name, releases in plan_modules if releases]
    if not releasing or allow:
        return
    names = ", ".join(releasing)
    if auto or not sys.stdin.isatty():
        raise UserError(
            f"the plan releases the axes of {names} (10h/20h: they must travel to their reference point "
            "before production) — nothing was written; apply again with --allow-axis-release"
        )
    if not typer.confirm(f"⚠ The axes of {names} will be released and must travel to their reference point. Allow?", default=False):
        raise UserError(f"axis release of {names} not allowed — nothing was written")


def _account(run: ModuleRun) -> str:
    """What was and was not written to one module, and what a read-back says it holds now."""
    head = f"bus {run.bus}, module {run.address} ({run.name})"
    if run.verified:
        repaired = f", after {run.repairs} repair round{'s' if run.repairs != 1 else ''}" if run.repairs else ""
        received = f" and {run.broadcasts} broadcast{'s' if run.broadcasts != 1 else ''} received" if run.broadcasts else ""
        return f"✓ {head}: {len(run.written)} message{'s' if len(run.written) != 1 else ''} written{received}, verified{repaired}"
    lines = [f"✗ {head}: {run.failure}"]
    if not run.sent:
        lines.append("    nothing was sent to it")
    else:
        lines.append("    written: " + ("; ".join(s.summary for s in run.written) or "nothing acknowledged"))
        if run.unacknowledged:
            lines.append("    sent, not acknowledged: " + "; ".join(s.summary for s in run.unacknowledged))
        if run.unsent:
            lines.append("    not sent: " + "; ".join(s.summary for s in run.unsent))
        if run.final is None:
            lines.append("    not read back: what the module holds is not known")
        elif run.unchanged:
            lines.append("    read back: unchanged, as before the apply")
        else:
            lines.append("    read back, it differs from the plant file: " + "; ".join(render.differences(run.final, run.desired)))
    return "\n".join(lines)


def _travel_list(runs: list[ModuleRun]) -> str | None:
    released = [r for r in runs if r.released is not Release.NO]
    if not released:
        return None
    names = ", ".join(
        f"{r.bus}/{r.name}" + (" (possibly: its 10h/20h went out unacknowledged)" if r.released is Release.POSSIBLY else "")
        for r in released
    )
    return f"⚠ Travel to reference point required before production on: {names}"


def _apply(
    loaded,
    pairs,
    *,
    desired: dict[Key, ModuleImage] | None,
    targets: list[Target],
    plan_file: tuple[Path, Any] | None,
    auto_approve: bool,
    allow_axis_release: bool,
    lock_timeout: float,
    trace: Path | None,
    retries: int,
    verify: Verify,
) -> None:
    """Lock, read back, plan (or prove the plan file), gate, snapshot, run, verify, account."""
    planned = None if plan_file is None else _read_plan_file(*plan_file, loaded)  # before any time on the line
    buses = {b.name: b for b, _ in pairs}
    with contextlib.ExitStack() as stack:
        journal = Journal(loaded.path)  # its file is made at the first record: not for a busy line
        stack.callback(journal.close)
        links = stack.enter_context(
            plant_links(loaded, buses, trace, retries, observer=journal.exchange, lock_timeout=lock_timeout, purpose="apply")
        )
        images = read_images(targets, links)
        if planned is None:
            the_plan = make_plan(loaded, pairs, images, desired)
        else:
            the_plan = _plan_from_file(plan_file[0], planned, loaded, pairs, images)
            print(f"Applying {plan_file[0]}, proved against the modules as read back now:")
        print(render.human(the_plan))
        runs = [ModuleRun(c.bus, c.address, c.name, c.actual, c.desired, c.steps, c.plan.predicted, c.broadcasts)
                for c in the_plan.changes]  # fmt: skip
        if not runs:
            print("Nothing to do: every module matches the plant file.")
            return
        _gate_axes([(r.bus, r.name, any(s.releases_axes for s in r.steps)) for r in runs], allow_axis_release, auto_approve)
        if not _confirm(f"Apply {sum(len(r.steps) for r in runs)} messages to {len(runs)} modules?", auto_approve):
            raise UserError("not applied — nothing was written")
        with CANCEL.deferred():  # from the snapshot to the last line of the account, a signal waits its turn
            snapshot = Snapshot.take(loaded.path, loaded.sha256, {(r.bus, r.address): images[(r.bus, r.address)] for r in runs})
            snapshot_path = snapshot.save()
            print(f"Snapshot of the modules before writing: {snapshot_path}")
            journal.record("apply", plant=loaded.name, plant_sha256=loaded.sha256, snapshot=str(snapshot_path),
                           modules=[f"{r.bus}/{r.address}" for r in runs])  # fmt: skip
            costs = {name: line_cost(bus) for name, bus in buses.items()}
            with progress_bar(the_plan.message_count, "applying") as tick:
                execute(runs, links, costs, tick=tick, may_release_axes=allow_axis_release, verify=verify)
            _report(runs, journal, snapshot_path)


def _report(runs: list[ModuleRun], journal: Journal, snapshot_path: Path) -> None:
    """The account of every module, the reference-travel list, where the records are; then the outcome.

    The journal is written first: it must be whole even when stdout has gone (`| head`)."""
    released = [r for r in runs if r.released is not Release.NO]
    for run in runs:
        journal.record(
            "result", bus=run.bus, address=run.address, verified=run.verified, failure=run.failure,
            released_axes=run.released.value, written=[s.message.hex() for s in run.written],
            interrupted=run.interrupted,
        )  # fmt: skip
    if released:
        journal.record("travel_to_reference_point", modules=[f"{r.bus}/{r.address}" for r in released])
    if CANCEL.requested:
        journal.record("interrupted")
    for run in runs:
        print(_account(run), file=sys.stdout if run.verified else sys.stderr)
    if (travel := _travel_list(runs)) is not None:
        print(travel)
    print(f"Journal: {journal.path}")
    failed = [r for r in runs if not r.verified]
    if CANCEL.requested:
        touched = sum(1 for r in failed if r.sent)
        print(f"Interrupted: {len(runs) - len(failed)} of {len(runs)} modules written and verified, "
              + (f"{touched} written in part — restore them with: prc3cfg restore {snapshot_path}" if touched
                 else "nothing sent to the others"))  # fmt: skip
        raise Interrupted()
    if failed:
        raise UserError(
            f"apply failed on {len(failed)} of {len(runs)} modules (see above) — restore with: prc3cfg restore {snapshot_path}"
        )
    print(f"Apply complete: {len(runs)} modules written and verified.")


def _read_plan_file(path: Path, document: Any, loaded) -> PlanFile:
    """The plan file; refused when it is damaged, made by another prc3cfg, or the plant file changed since."""
    try:
        planned = read_plan_file(document)
    except PlanFileError as error:
        raise UserError(f"{path}: {error}") from None
    if planned.version != __version__:
        raise UserError(f"{path}: made by prc3cfg {planned.version}, this is {__version__} — plan again with this version")
    if planned.plant_sha256 != loaded.sha256:
        raise UserError(f"{path}: stale plan — the plant file {loaded.path} changed since the plan was made; plan again")
    return planned


def _plan_from_file(path: Path, planned: PlanFile, loaded, pairs, images: dict[Key, ModuleImage]) -> PlantPlan:
    """The plan file's plan, proved before anything is written.

    Refused when a module changed since the plan was made; when a module's steps do anything
    but turn its read-back into the plant file's image (`run_steps` names the rule they
    break); and when they are not exactly the steps — broadcasts included — that prc3cfg
    plans from this read-back: the plant file and the read-back are the same as when the file
    was made, so any difference is an edit. What is applied is then that plan.
    """
    modules = {(bus.name, m.address): (bus, m) for bus, m in pairs}
    chosen = []
    for entry in planned.modules:
        where = f"bus {entry.bus}, module {entry.address}"
        if (entry.bus, entry.address) not in modules:
            raise UserError(f"{path}: {where} is not among the modules to apply — plan again")
        bus, module = modules[(entry.bus, entry.address)]
        if entry.name != module.name:
            raise UserError(f"{path}: {where} is called {entry.name!r} in the plan but {module.name!r} in the plant file — plan again")
        if image_sha256(images[(entry.bus, entry.address)]) != entry.state_sha256:
            raise UserError(
                f"{path}: stale plan — {where} ({entry.name}) changed since the plan was made "
                "(teach-in or another apply?); nothing was written — plan again"
            )
        chosen.append((bus, module))
    ours = make_plan(loaded, chosen, images)
    for entry, change in zip(planned.modules, ours.modules):
        edited = (f"{path}: bus {entry.bus}, module {entry.address} ({entry.name}): {{}} — the plan file was changed "
                  "after it was made; nothing was written: plan again and review it")  # fmt: skip
        theirs, steps = list(entry.steps), [step.message for step in change.steps]
        try:
            plan_from_steps(change.actual, change.desired, theirs, line_cost(modules[(entry.bus, entry.address)][0]))
        except StepProblem as problem:
            if problem.index:  # the step that breaks a rule
                raise UserError(edited.format(problem)) from None
            raise UserError(edited.format(f"{_first_difference(theirs, steps)}, and {problem}")) from None
        if theirs != steps:
            raise UserError(edited.format(_first_difference(theirs, steps)))
        if entry.broadcasts != change.broadcasts:
            raise UserError(edited.format(f"{entry.broadcasts} of its steps are marked broadcast, where the plan has {change.broadcasts}"))
    return ours


def _first_difference(theirs: list, ours: list) -> str:
    """Where a plan file's steps part from the plan made from the same read-back."""
    index = next(i for i, (a, b) in enumerate(zip([*theirs, None], [*ours, None]), 1) if a != b)
    said = theirs[index - 1].hex() if index <= len(theirs) else "missing"
    planned = ours[index - 1].hex() if index <= len(ours) else "nothing"
    return f"step {index} is {said}, where the plan made from this read-back has {planned}"


ApproveOpt = Annotated[bool, typer.Option("--auto-approve", help="Do not ask for confirmation.")]
AxesOpt = Annotated[bool, typer.Option("--allow-axis-release", help="Allow steps that release the axes (10h, 20h).")]
VerifyOpt = Annotated[Verify, typer.Option(help="floor: read back what the steps could have changed; full: the system and every program read before.")]


@app.command()
def apply(
    ctx: typer.Context,
    plant: Annotated[Optional[Path], typer.Argument(help="The plant file (YAML).", show_default=False)] = None,
    plan_file: Annotated[Optional[Path], typer.Option("--plan", help="Apply this plan file as reviewed (refused if stale or edited).")] = None,
    auto_approve: ApproveOpt = False,
    allow_axis_release: AxesOpt = False,
    lock_timeout: LockOpt = 0.0,
    module: ModuleOpt = None,
    trace: TraceOpt = None,
    retries: RetriesOpt = 5,
    verify: VerifyOpt = Verify.FLOOR,
) -> None:
    """Plan and apply the plant file (or apply a plan file), then verify by reading back."""
    if plant is None and plan_file is None:
        raise click_errors.UsageError("name the plant file, or a plan file with --plan", ctx=ctx)
    plan = None
    if plan_file is not None:
        plan = (plan_file, read_input(plan_file, "the plan file prc3cfg plan --out wrote", "make the plan again"))
    if plant is None:
        recorded = plan[1].get("plant_path") if isinstance(plan[1], dict) else None
        if not isinstance(recorded, str) or not Path(recorded).is_file():
            raise UserError(f"{plan_file}: the plant file it was made from is not at {recorded!r} — name it: "
                            f"prc3cfg apply PLANT --plan {plan_file}")  # fmt: skip
        plant = Path(recorded)
    check_output(trace, "--trace", plant=plant)
    loaded = load_plant(plant)
    pairs = chosen_modules(loaded, module)
    _apply(
        loaded, pairs, desired=None, targets=plant_targets(pairs), plan_file=plan,
        auto_approve=auto_approve, allow_axis_release=allow_axis_release, lock_timeout=lock_timeout,
        trace=trace, retries=retries, verify=verify,
    )  # fmt: skip


@app.command()
def restore(
    snapshot: Annotated[Path, typer.Argument(help="A snapshot under .prc3cfg/snapshots/.", show_default=False)],
    auto_approve: ApproveOpt = False,
    allow_axis_release: AxesOpt = False,
    lock_timeout: LockOpt = 0.0,
    trace: TraceOpt = None,
    retries: RetriesOpt = 5,
    verify: VerifyOpt = Verify.FLOOR,
) -> None:
    """Plan and apply the modules back to a snapshot an apply took, with the same gates."""
    taken = Snapshot.load(snapshot)
    loaded = load_plant(taken.plant_path)
    pairs = [(bus, m) for bus, m in loaded.modules() if (bus.name, m.address) in taken.images]
    if len(pairs) != len(taken.images):
        raise UserError(f"{snapshot}: the plant file {taken.plant_path} no longer has every module of the snapshot — nothing was written")
    targets = [
        Target(bus.name, m.address, m.name, tuple(n for n, p in enumerate(image.programs, 1) if p is not None), image.system)
        for bus, m in pairs
        for image in [taken.images[(bus.name, m.address)]]
    ]
    _apply(
        loaded, pairs, desired=taken.images, targets=targets, plan_file=None,
        auto_approve=auto_approve, allow_axis_release=allow_axis_release, lock_timeout=lock_timeout,
        trace=trace, retries=retries, verify=verify,
    )  # fmt: skip
