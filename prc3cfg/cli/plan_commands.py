"""`prc3cfg read`, `plan`, `apply` and `restore`: the plant file against the live modules."""

from __future__ import annotations

import contextlib
import json
import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from prc3cfg import render
from prc3cfg.apply import ModuleRun, execute
from prc3cfg.cli import Outcome, app
from prc3cfg.cli.common import (
    Key,
    ModuleOpt,
    PlantArg,
    RetriesOpt,
    TraceOpt,
    chosen_modules,
    line_cost,
    load_actual,
    make_plan,
    plant_links,
    plant_targets,
    progress_bar,
    read_images,
)
from prc3cfg.errors import UserError
from prc3cfg.plant import load_plant
from prc3cfg.image import ModuleImage
from prc3cfg.link.ports import EMULATOR_SCHEME, emulator_state_path
from prc3cfg.locks import line_lock
from prc3cfg.plantplan import PlanFileError, PlannedModule, PlantPlan, image_sha256, read_plan_file
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
) -> None:
    """Read back every module of the plant (system parameters and managed programs)."""
    loaded = load_plant(plant)
    pairs = chosen_modules(loaded, module)
    targets = plant_targets(pairs)
    with plant_links(loaded, {b.name for b, _ in pairs}, trace, retries) as links:
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
        out.write_text(json.dumps(document, indent=1) + "\n")
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
    out: Annotated[Optional[Path], typer.Option(help="Write the plan file (prc3cfg-plan/1).")] = None,
    actual: Annotated[Optional[Path], typer.Option(help="Plan against module images saved by `read --json`.")] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the plan as JSON.")] = False,
    markdown: Annotated[bool, typer.Option("--markdown", help="Print the plan as markdown (PR comments).")] = False,
    detailed_exitcode: Annotated[bool, typer.Option("--detailed-exitcode", help="Exit 0 no changes, 2 changes, 1 error.")] = False,
    module: ModuleOpt = None,
    trace: TraceOpt = None,
    retries: RetriesOpt = 5,
) -> None:
    """Read back, diff against the plant file and print the cheapest plan."""
    loaded = load_plant(plant)
    pairs = chosen_modules(loaded, module)
    if actual is not None:
        images = load_actual(actual, loaded, pairs)
    else:
        with plant_links(loaded, {b.name for b, _ in pairs}, trace, retries) as links:
            images = read_images(plant_targets(pairs), links)
    result = make_plan(loaded, pairs, images)
    _emit_plan(result, out=out, json_out=json_out, markdown=markdown)
    if detailed_exitcode and result.changes:
        raise Outcome(EXIT_CHANGES)


def _line_key(bus, plant_path: Path) -> str:
    if bus.port.startswith(EMULATOR_SCHEME):
        return str(emulator_state_path(plant_path.resolve(), bus.port))
    return bus.port


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
    """What was and was not written to one module, and how it ended."""
    head = f"bus {run.bus}, module {run.address} ({run.name})"
    if run.verified:
        repaired = f", after {run.repairs} repair round{'s' if run.repairs != 1 else ''}" if run.repairs else ""
        return f"✓ {head}: {len(run.sent)} messages written, verified{repaired}"
    written = ", ".join(m.hex() for m in run.sent) or "nothing"
    unsent = ", ".join(m.hex() for m in run.steps if m not in run.sent) or "—"
    return f"✗ {head}: written: {written}; not written: {unsent}\n    {run.failure}"


def _apply(
    loaded,
    pairs,
    *,
    desired: dict[Key, ModuleImage] | None,
    targets: list[Target],
    plan_file: Path | None,
    auto_approve: bool,
    allow_axis_release: bool,
    lock_timeout: float,
    trace: Path | None,
    retries: int,
) -> None:
    """Lock, read back, plan (or check the plan file), gate, snapshot, run, verify, account."""
    planned = None if plan_file is None else _read_plan_file(plan_file, loaded)  # before any time on the line
    buses = {b.name: b for b, _ in pairs}
    with contextlib.ExitStack() as stack:
        for bus in buses.values():
            stack.enter_context(
                line_lock(_line_key(bus, loaded.path), f"bus {bus.name} ({bus.port})", timeout=lock_timeout)
            )
        journal = Journal(loaded.path)
        stack.callback(journal.close)
        links = stack.enter_context(plant_links(loaded, buses, trace, retries, observer=journal.exchange))
        images = read_images(targets, links)
        if planned is None:
            the_plan = make_plan(loaded, pairs, images, desired)
            print(render.human(the_plan))
            runs = [
                ModuleRun(c.bus, c.address, c.name, c.desired, tuple(s.message for s in c.steps), tuple(s.summary for s in c.steps))
                for c in the_plan.changes
            ]
        else:
            runs = _runs_from_plan_file(plan_file, planned, pairs, images)
            print(f"Applying {plan_file}: {sum(len(r.steps) for r in runs)} messages to {len(runs)} modules")
        if not runs:
            print("Nothing to do: every module matches the plant file.")
            return
        _gate_axes([(r.bus, r.name, any(m.RELEASES_AXES for m in r.steps)) for r in runs], allow_axis_release, auto_approve)
        if not _confirm(f"Apply {sum(len(r.steps) for r in runs)} messages to {len(runs)} modules?", auto_approve):
            raise UserError("not applied — nothing was written")
        snapshot = Snapshot.take(loaded.path, loaded.sha256, {(r.bus, r.address): images[(r.bus, r.address)] for r in runs})
        print(f"Snapshot of the modules before writing: {snapshot.save()}")
        journal.record("apply", plant=loaded.name, plant_sha256=loaded.sha256, modules=[f"{r.bus}/{r.address}" for r in runs])
        costs = {name: line_cost(bus) for name, bus in buses.items()}
        with progress_bar(sum(len(r.steps) for r in runs), "applying") as tick:
            execute(runs, links, costs, tick=tick, may_release_axes=allow_axis_release)
        for run in runs:
            journal.record("result", bus=run.bus, address=run.address, verified=run.verified, failure=run.failure)
            print(_account(run), file=sys.stdout if run.verified else sys.stderr)
    released = [f"{r.bus}/{r.name}" for r in runs if r.released_axes]
    if released:
        print(f"⚠ Travel to reference point required before production on: {', '.join(released)}")
    failed = [r for r in runs if not r.verified]
    print(f"Journal: {journal.path}")
    if failed:
        raise UserError(f"apply failed on {len(failed)} of {len(runs)} modules (see above) — the snapshot above restores them")
    print(f"Apply complete: {len(runs)} modules written and verified.")


def _read_plan_file(path: Path, loaded) -> list[PlannedModule]:
    """The plan file's modules; refused when it is damaged or the plant file changed since it was made."""
    try:
        _, plant_sha, planned = read_plan_file(json.loads(path.read_text()))
    except (OSError, ValueError, PlanFileError) as error:
        raise UserError(f"{path}: {error}") from None
    if plant_sha != loaded.sha256:
        raise UserError(f"{path}: stale plan — the plant file {loaded.path} changed since the plan was made; plan again")
    return planned


def _runs_from_plan_file(path: Path, planned: list[PlannedModule], pairs, images: dict[Key, ModuleImage]) -> list[ModuleRun]:
    """The plan file's steps, refused when any module changed since the plan was made."""
    modules = {(bus.name, m.address): m for bus, m in pairs}
    runs = []
    for entry in planned:
        module = modules.get((entry.bus, entry.address))
        if module is None:
            raise UserError(f"{path}: bus {entry.bus}, module {entry.address} is not among the modules to apply — plan again")
        if image_sha256(images[(entry.bus, entry.address)]) != entry.state_sha256:
            raise UserError(
                f"{path}: stale plan — bus {entry.bus}, module {entry.address} ({entry.name}) changed since the "
                "plan was made (teach-in or another apply?); nothing was written — plan again"
            )
        if entry.steps:
            runs.append(ModuleRun(entry.bus, entry.address, entry.name, module.desired_image(), entry.steps,
                                  tuple(m.hex() for m in entry.steps)))  # fmt: skip
    return runs


ApproveOpt = Annotated[bool, typer.Option("--auto-approve", help="Do not ask for confirmation.")]
AxesOpt = Annotated[bool, typer.Option("--allow-axis-release", help="Allow steps that release the axes (10h, 20h).")]
LockOpt = Annotated[float, typer.Option("--lock-timeout", help="Seconds to wait for another apply on the same line.")]


@app.command()
def apply(
    plant: Annotated[Optional[Path], typer.Argument(help="The plant file (YAML).", show_default=False)] = None,
    plan_file: Annotated[Optional[Path], typer.Option("--plan", help="Apply this plan file, without planning again.")] = None,
    auto_approve: ApproveOpt = False,
    allow_axis_release: AxesOpt = False,
    lock_timeout: LockOpt = 0.0,
    module: ModuleOpt = None,
    trace: TraceOpt = None,
    retries: RetriesOpt = 5,
) -> None:
    """Plan and apply the plant file (or apply a plan file), then verify by reading back."""
    if plant is None and plan_file is None:
        raise UserError("apply: name the plant file, or a plan file with --plan")
    if plant is None:
        try:
            plant = Path(json.loads(plan_file.read_text())["plant_path"])
        except (OSError, ValueError, KeyError, TypeError):
            raise UserError(f"{plan_file}: name the plant file too: prc3cfg apply PLANT --plan {plan_file}") from None
    loaded = load_plant(plant)
    pairs = chosen_modules(loaded, module)
    _apply(
        loaded, pairs, desired=None, targets=plant_targets(pairs), plan_file=plan_file,
        auto_approve=auto_approve, allow_axis_release=allow_axis_release, lock_timeout=lock_timeout,
        trace=trace, retries=retries,
    )  # fmt: skip


@app.command()
def restore(
    snapshot: Annotated[Path, typer.Argument(help="A snapshot under .prc3cfg/snapshots/.", show_default=False)],
    auto_approve: ApproveOpt = False,
    allow_axis_release: AxesOpt = False,
    lock_timeout: LockOpt = 0.0,
    trace: TraceOpt = None,
    retries: RetriesOpt = 5,
) -> None:
    """Plan and apply the modules back to a snapshot an apply took, with the same gates."""
    taken = Snapshot.load(snapshot)
    loaded = load_plant(taken.plant_path)
    pairs = [(bus, m) for bus, m in loaded.modules() if (bus.name, m.address) in taken.images]
    if len(pairs) != len(taken.images):
        raise UserError(f"{snapshot}: the plant file {taken.plant_path} no longer has every module of the snapshot — nothing was written")
    targets = [
        Target(bus.name, m.address, m.name, tuple(n for n, p in enumerate(taken.images[(bus.name, m.address)].programs, 1) if p is not None))
        for bus, m in pairs
    ]
    _apply(
        loaded, pairs, desired=taken.images, targets=targets, plan_file=None,
        auto_approve=auto_approve, allow_axis_release=allow_axis_release, lock_timeout=lock_timeout,
        trace=trace, retries=retries,
    )  # fmt: skip
