"""`prc3cfg read`, `plan`, `apply` and `restore`: the plant file against the live modules.

Arguments, prompts and output only: the work is `prc3cfg.api`'s.
"""

from __future__ import annotations

import contextlib
import json
import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from prc3cfg import api, render
from prc3cfg.api import ApplyFailed, ApplyInterrupted, ApplyResult, Gates, Verify
from prc3cfg.apply import ModuleRun, Release
from prc3cfg.cli import Outcome, app, click_errors
from prc3cfg.cli.common import (
    LockOpt,
    ModuleOpt,
    PlantArg,
    RetriesOpt,
    TraceOpt,
    check_output,
    line_options,
    print_lines,
    write_output,
)
from prc3cfg.errors import UserError
from prc3cfg.plantplan import PlantPlan

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
    check_output(trace, "--trace", plant=plant)
    loaded = api.load(plant)
    pairs = api.select(loaded, module)
    with line_options(trace, retries, lock_timeout) as options:
        images = api.read(loaded, module, options)
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


def _emit_plan(plan: PlantPlan, *, out: Path | None, json_out: bool, markdown: bool, notes: list[str]) -> None:
    document = plan.to_json() | {"left_alone": notes}
    for bus in document["buses"]:
        for entry, change in zip(bus["modules"], plan.buses()[bus["name"]]):
            entry["changes"] = render.changes_json(change)
            entry["warning"] = render.AXIS_WARNING if change.releases_axes else None
    if out is not None:
        write_output(out, json.dumps(document, indent=1) + "\n", "--out")
    if json_out:
        print(json.dumps(document, indent=1))
    elif markdown:
        print(render.markdown(plan) + "".join(f"\n> Left as it is: {note}" for note in notes))
    else:
        print_lines("\n".join([render.human(plan), *(f"Left as it is: {note}" for note in notes)]))
        if out is not None:
            print(f"Plan written to {out}; apply it with: prc3cfg apply --plan {out}")


def _targeting(modules: list[str] | None) -> None:
    """Terraform's -target warning: a plan of some modules is not the plan of the plant."""
    if modules:
        print(f"⚠ Only {', '.join(modules)} (--module): the rest of the plant file is left out of this "
              "plan — run without --module to see everything it would change")  # fmt: skip


def _drift(images: dict, pairs) -> int:
    """What the modules hold other than the plant file says — drift (Teach In, work on the floor),
    not a plan; the number of modules that drifted."""
    drifted = 0
    for bus, module in pairs:
        differences = render.differences(images[(bus.name, module.address)], module.desired_image())
        if differences:
            drifted += 1
            print(f"~ bus {bus.name}, module {module.address} ({module.name}) differs from the plant file:")
            print("\n".join(f"    {text}" for text in differences))
    print(f"Drift: {drifted} of {len(pairs)} module{'s' if len(pairs) != 1 else ''} hold{'s' if drifted == 1 else ''} "
          "something other than the plant file says." if drifted else "No drift: every module holds what the plant file says.")  # fmt: skip
    return drifted


@app.command()
def plan(
    plant: PlantArg,
    out: Annotated[Optional[Path], typer.Option(callback=lambda v: check_output(v, "--out"), help="Write the plan file (prc3cfg-plan/1).")] = None,
    actual: Annotated[Optional[Path], typer.Option(help="Plan against module images saved by `read --json`.")] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the plan as JSON.")] = False,
    markdown: Annotated[bool, typer.Option("--markdown", help="Print the plan as markdown (PR comments).")] = False,
    detailed_exitcode: Annotated[bool, typer.Option("--detailed-exitcode", help="Exit 0 no changes, 2 changes, 1 error.")] = False,
    refresh_only: Annotated[bool, typer.Option("--refresh-only", help="Report drift (what the modules hold other than the plant file says), no plan.")] = False,
    module: ModuleOpt = None,
    trace: TraceOpt = None,
    retries: RetriesOpt = 5,
    lock_timeout: LockOpt = 0.0,
) -> None:
    """Read back, diff against the plant file and print the cheapest plan."""
    check_output(out, "--out", plant=plant)
    check_output(trace, "--trace", plant=plant)
    loaded = api.load(plant)
    if not json_out:
        _targeting(module)
    images = None if actual is None else api.load_images(actual, loaded, module)
    if refresh_only:
        if images is None:
            with line_options(trace, retries, lock_timeout) as options:
                images = api.read(loaded, module, options)
        if _drift(images, api.select(loaded, module)) and detailed_exitcode:
            raise Outcome(EXIT_CHANGES)
        return
    with line_options(trace, retries, lock_timeout) as options:
        result = api.plan(loaded, module, images=images, options=options)
    _emit_plan(result, out=out, json_out=json_out, markdown=markdown, notes=[] if module else api.left_alone(loaded))
    if detailed_exitcode and result.changes:
        raise Outcome(EXIT_CHANGES)


def _gates(plan_file: Path | None, auto_approve: bool, allow_axis_release: bool) -> Gates:
    """Show the plan; ask about axis releases and the apply itself on a terminal, unless told not to."""

    def show(the_plan: PlantPlan) -> None:
        if plan_file is not None:
            print(f"Applying {plan_file}, proved against the modules as read back now:")
        print_lines(render.human(the_plan))
        if not the_plan.changes:
            print("Nothing to do: every module matches the plant file.")

    def allow(names: list[str]) -> bool:
        listed = ", ".join(names)
        if auto_approve or not sys.stdin.isatty():
            return False  # refused, naming the flag
        if not typer.confirm(f"⚠ The axes of {listed} will be released and must travel to their reference point. Allow?", default=False):
            raise UserError(f"axis release of {listed} not allowed — nothing was written")
        return True

    def approve(the_plan: PlantPlan) -> bool:
        question = f"Apply {the_plan.message_count} messages to {len(the_plan.changes)} modules?"
        if auto_approve:
            return True
        if not sys.stdin.isatty():
            raise UserError(f"{question} — no terminal to ask: pass --auto-approve to apply without asking")
        return typer.confirm(question, default=False)

    return Gates(show=show, allow_axis_release=True if allow_axis_release else allow, approve=approve)


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


def _report(result: ApplyResult) -> None:
    """The account of every module, the reference-travel list, where the records are."""
    for run in result.runs:
        print(_account(run), file=sys.stdout if run.verified else sys.stderr)
    if (travel := _travel_list(list(result.runs))) is not None:
        print(travel)
    print(f"Journal: {result.journal}")


@contextlib.contextmanager
def _accounted() -> None:
    """Run an apply; whatever becomes of it after its first write, say what it did."""
    try:
        yield
    except ApplyInterrupted as stopped:
        _report(stopped.result)
        failed = [r for r in stopped.result.runs if not r.verified]
        touched = sum(1 for r in failed if r.sent)
        print(f"Interrupted: {len(stopped.result.runs) - len(failed)} of {len(stopped.result.runs)} modules written and verified, "
              + (f"{touched} written in part — restore them with: prc3cfg restore {stopped.result.snapshot}" if touched
                 else "nothing sent to the others"))  # fmt: skip
        raise
    except ApplyFailed as failed:
        _report(failed.result)
        raise


def _applied(result: ApplyResult) -> None:
    if result.runs:
        _report(result)
        print(f"Apply complete: {len(result.runs)} modules written and verified.")


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
    plant = plant if plant is not None else api.plan_file_plant(plan_file)
    check_output(trace, "--trace", plant=plant)
    loaded = api.load(plant)
    _targeting(module)
    with line_options(trace, retries, lock_timeout) as options, _accounted():
        result = api.apply(loaded, module, plan_file=plan_file, gates=_gates(plan_file, auto_approve, allow_axis_release),
                           verify=verify, options=options)  # fmt: skip
    _applied(result)


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
    with line_options(trace, retries, lock_timeout) as options, _accounted():
        result = api.restore(snapshot, gates=_gates(None, auto_approve, allow_axis_release), verify=verify, options=options)
    _applied(result)
