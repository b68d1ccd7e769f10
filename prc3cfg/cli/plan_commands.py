"""`prc3cfg read`, `plan`, `apply` and `restore`: the plant file against the live modules.

Arguments, prompts and output only: the work is `prc3cfg.api`'s.
"""


from pathlib import Path
from typing import Annotated

import typer

from prc3cfg.cli import ExitStatus, app, click_errors
from prc3cfg.cli.common import (
    FramesOpt,
    LockOpt,
    ModuleOpt,
    PlantArg,
    RetriesOpt,
    TraceOpt,
    VerifyChoice,
    check_output,
    line_options,
    print_lines,
    unanswered,
)

EXIT_CHANGES = 2
#: `plan`: a hard rule of the plant's policy refuses what the plan would write (docs/commands.md).
EXIT_POLICY = 3

PreviousOpt = Annotated[Path | None, typer.Option("--previous", metavar="PLANT", help=(
    "The plant file as it was (e.g. on the main branch), taken as what the modules hold: only what the "
    "change from it touches is "
    "read, and what it described and this one no longer does is said to stay on the hardware. Default: the "
    "plant file last "
    "applied in full from here."))]
FullReadOpt = Annotated[bool, typer.Option("--full-read",
                                           help="Read back every module in full, not only what the "
                                                "change touches.")]


@app.command()
def read(
    plant: PlantArg,
    json_out: Annotated[bool, typer.Option("--json", help="Print a list of module images "
                                                          "(device units).")] = False,
    module: ModuleOpt = None,
    trace: TraceOpt = None,
    retries: RetriesOpt = 5,
    lock_timeout: LockOpt = 0.0,
) -> None:
    """Read back every module of the plant (system parameters, managed programs, and the
    programs the plant's system parameters would clamp)."""
    import json

    from prc3cfg import api
    from prc3cfg.core import render

    check_output(trace, "--trace", plant=plant)
    loaded = api.load(plant)
    pairs = api.select(loaded, module)
    with line_options(trace, retries, lock_timeout) as options:
        images = api.read(loaded, module, options)
    if json_out:
        print(json.dumps([{"bus": bus.name, **images[(bus.name, m.address)].to_json()} for bus, m in pairs],
                         indent=1))
        return
    print_lines("\n".join(line for bus, m in pairs
                           for line in render.image_lines(bus.name, m.name, images[(bus.name, m.address)])))


@app.command()
def plan(
    ctx: typer.Context,
    plant: PlantArg,
    out: Annotated[Path | None,
                   typer.Option(callback=lambda v: check_output(v, "--out"), metavar="FILE", help=(
        "Write the plan file (prc3cfg-plan/1); with --refresh-only, the drift (prc3cfg-drift/1)."))] = None,
    actual: Annotated[Path | None,
                      typer.Option(metavar="FILE", help="Plan against module images saved by "
                                                        "`read --json`.")] = None,
    json_out: Annotated[bool, typer.Option("--json",
                                           help="Print the plan (or with --refresh-only the "
                                                "drift) as JSON.")] = False,
    markdown: Annotated[bool, typer.Option("--markdown",
                                           help="Print the plan (or the drift) as markdown (PR "
                                                "comments).")] = False,
    max_chars: Annotated[int, typer.Option("--max-chars", min=1000, metavar="N",
                                           help="--markdown: at most this many characters (a GitHub comment "
                                                "holds 65,536).")] = 65_000,
    detailed_exitcode: Annotated[bool, typer.Option("--detailed-exitcode",
                                                    help="Exit 0 no changes, 2 changes, 1 error.")] = False,
    refresh_only: Annotated[bool, typer.Option("--refresh-only",
                                               help="Report drift (what the modules hold other than the "
                                                    "plant file says), no plan.")] = False,
    plot: Annotated[Path | None,
                    typer.Option("--plot", metavar="FILE",
                                 help="With one --module: draw its chains before (dashed) and after the "
                                      "plan to this .svg or .png file.")] = None,
    previous: PreviousOpt = None,
    full_read: FullReadOpt = False,
    module: ModuleOpt = None,
    trace: TraceOpt = None,
    retries: RetriesOpt = 5,
    lock_timeout: LockOpt = 0.0,
    frames: FramesOpt = False,
) -> None:
    """Read back, diff against the plant file and print the cheapest plan."""
    from prc3cfg import api
    from prc3cfg.cli import output

    _plan_options(ctx, refresh_only, plot, previous, module)
    fmt = api.plot_format(plot) if plot is not None else None
    check_output(out, "--out", plant=plant)
    check_output(plot, "--plot", plant=plant)
    check_output(trace, "--trace", plant=plant)
    loaded = api.load(plant)
    if not json_out:
        output.targeting(module)
    images = None if actual is None else api.load_images(actual, loaded, module)
    if refresh_only:
        # a lock taken only where the line is read
        with line_options(trace, retries, lock_timeout) as options:
            drifted = (api.drift(loaded, module, images=images) if images is not None
                       else api.drift(loaded, module, options=options))
        output.emit_drift(drifted, loaded.name, len(api.select(loaded, module)), out=out, json_out=json_out,
                          markdown=markdown,
                          max_chars=max_chars)
        if drifted and detailed_exitcode:
            raise ExitStatus(EXIT_CHANGES)
        return
    # a bad --previous is said before the line is used
    notes = [] if module else api.left_alone(loaded, previous)
    judged = api.policy(loaded, module)  # a bad policy file is said before the line is used
    with line_options(trace, retries, lock_timeout) as options:
        result = api.plan(loaded, module, images=images, options=options, previous=previous,
                          full_read=full_read)
    output.emit_plan(result, out=out, json_out=json_out, markdown=markdown, max_chars=max_chars, notes=notes,
                     frames=frames,
                     policy=judged)
    if plot is not None and module is not None and fmt is not None:  # one module, a format: checked above
        output.write_picture(plot, api.picture(loaded, module[0], fmt=fmt, planned=result), module[0])
    if judged is not None and judged.fails_plan:
        raise ExitStatus(EXIT_POLICY)
    if detailed_exitcode and result.changes:
        raise ExitStatus(EXIT_CHANGES)


def _plan_options(ctx: typer.Context, refresh_only: bool, plot: Path | None, previous: Path | None,
                  module: list[str] | None) -> None:
    """Refused in one line: what `--refresh-only` (drift, no plan) leaves out — a plot, what a plan leaves as
    it is (`--previous`) — and a plot of other than one module."""
    for given, name in ((plot, "--plot"), (previous, "--previous")):
        if refresh_only and given is not None:
            raise click_errors.UsageError("--refresh-only reports drift and makes no plan — leave "
                                          f"out {name}", ctx=ctx)
    if plot is not None and len(module or []) != 1:
        raise click_errors.UsageError("--plot draws one module — name it with --module NAME", ctx=ctx)


ApproveOpt = Annotated[bool, typer.Option("--auto-approve", help="Do not ask for confirmation.")]
ReasonOpt = Annotated[str | None, typer.Option("--reason", metavar="TEXT", help=(
    "Why: kept in the journal's and the snapshot's header (default: $PRC3CFG_REASON); a bus with "
    "require_reason: true needs one."))]
AxesOpt = Annotated[bool, typer.Option("--allow-axis-release",
                                       help="Allow steps that release the axes (10h, 20h).")]
EventsOpt = Annotated[bool, typer.Option("--json", help=(
    "Print events, one JSON object a line as they happen (prc3cfg-event/1: plan, question, progress, "
    "module, travel, account); "
    "needs --auto-approve (or --plan FILE): no question is asked."))]
OverrideWindowOpt = Annotated[str | None, typer.Option("--override-window", metavar="REASON", help=(
    "Apply though a soft window of the plant's policy refuses now; the reason and who gave it go into "
    "the journal."))]
OverrideEnvelopeOpt = Annotated[str | None, typer.Option("--override-envelope", metavar="REASON", help=(
    "Apply though a soft envelope of the plant's policy refuses; the reason and who gave it go into "
    "the journal."))]
VerifyOpt = Annotated[VerifyChoice,
                      typer.Option(metavar="floor|full",
                                   help="floor: read back what the steps could have changed; full: the "
                                        "system and every program read before.")]


@app.command()
def apply(
    ctx: typer.Context,
    plant: Annotated[Path | None,
                     typer.Argument(metavar="PLANT", help="The plant file (YAML).",
                                    show_default=False)] = None,
    plan_file: Annotated[Path | None,
                         typer.Option("--plan", metavar="FILE",
                                      help="Apply this plan file as reviewed (refused if stale or "
                                           "edited).")] = None,
    auto_approve: ApproveOpt = False,
    allow_axis_release: AxesOpt = False,
    lock_timeout: LockOpt = 0.0,
    module: ModuleOpt = None,
    trace: TraceOpt = None,
    retries: RetriesOpt = 5,
    verify: VerifyOpt = VerifyChoice.FLOOR,
    previous: PreviousOpt = None,
    full_read: FullReadOpt = False,
    reason: ReasonOpt = None,
    frames: FramesOpt = False,
    json_out: EventsOpt = False,
    override_window: OverrideWindowOpt = None,
    override_envelope: OverrideEnvelopeOpt = None,
) -> None:
    """Plan and apply the plant file (or apply a plan file), then verify by reading back."""
    from prc3cfg import api
    from prc3cfg.cli import output

    if plan_file is not None and (previous is not None or full_read):
        raise click_errors.UsageError("--plan reads back exactly what its plan read — leave out --previous "
                                      "and --full-read", ctx=ctx)
    if plant is None and plan_file is not None:
        plant = api.plan_file_plant(plan_file)
    if plant is None:
        raise click_errors.UsageError("name the plant file, or a plan file with --plan", ctx=ctx)
    if plant.suffix.lower() == ".json":  # Terraform's `apply PLAN`
        raise click_errors.UsageError(f"{plant} is a plan file — did you mean prc3cfg apply PLANT "
                                      f"--plan {plant}?", ctx=ctx)
    _answered(ctx, json_out, auto_approve or plan_file is not None,
              "or apply a reviewed plan file with --plan FILE")
    check_output(trace, "--trace", plant=plant)
    verified = api.Verify(verify.value)
    overrides = _overrides(ctx, override_window, override_envelope)
    if json_out:
        from prc3cfg.cli import stream

        events = stream.Stream("apply")
        # a plant file refused ends the stream with its account too
        with stream.accounted(events) as finished:
            loaded = api.load(plant)
            with line_options(trace, retries, lock_timeout, stream.EventProgress(events)) as options:
                finished.append(api.apply(loaded, module, plan_file=plan_file,
                                          gates=stream.gates(events, plan_file, auto_approve,
                                                             allow_axis_release),
                                          verify=verified, options=options, previous=previous,
                                          full_read=full_read, reason=reason,
                                          overrides=overrides))
        return
    loaded = api.load(plant)
    output.targeting(module)
    with line_options(trace, retries, lock_timeout) as options, output.accounted():
        result = api.apply(loaded, module, plan_file=plan_file,
                           gates=output.gates(plan_file, auto_approve, allow_axis_release, options, frames),
                           verify=verified, options=options, previous=previous, full_read=full_read,
                           reason=reason,
                           overrides=overrides)
    output.applied(result)


def _overrides(ctx: typer.Context, window: str | None, envelope: str | None) -> dict[str, str]:
    """The policy's overrides by kind (`api.apply`'s `overrides`); refused in one line without a reason."""
    overrides = {kind: why for kind, why in (("window", window), ("envelope", envelope)) if why is not None}
    if any(not why.strip() for why in overrides.values()):
        raise click_errors.UsageError("an override needs a reason: "
                                      "--override-window/--override-envelope REASON", ctx=ctx)
    return overrides


def _answered(ctx: typer.Context, json_out: bool, auto_approve: bool, instead: str) -> None:
    """`--json` asks no question: refused in one line, before the line is used, where one would be asked."""
    if (why := unanswered(json_out, auto_approve, instead)) is not None:
        raise click_errors.UsageError(why, ctx=ctx)


@app.command()
def restore(
    ctx: typer.Context,
    snapshot: Annotated[Path, typer.Argument(metavar="SNAPSHOT", help="A snapshot under .prc3cfg/snapshots/.",
                                             show_default=False)],
    auto_approve: ApproveOpt = False,
    allow_axis_release: AxesOpt = False,
    lock_timeout: LockOpt = 0.0,
    trace: TraceOpt = None,
    retries: RetriesOpt = 5,
    verify: VerifyOpt = VerifyChoice.FLOOR,
    onto_current_lines: Annotated[bool, typer.Option("--onto-current-lines", help=(
        "Restore onto the lines the plant file names now, though they are not those the snapshot was "
        "taken on."))] = False,
    reason: ReasonOpt = None,
    frames: FramesOpt = False,
    json_out: EventsOpt = False,
    override_window: OverrideWindowOpt = None,
) -> None:
    """Plan and apply the modules back to a snapshot an apply took, with the same gates."""
    from prc3cfg import api
    from prc3cfg.cli import output

    _answered(ctx, json_out, auto_approve, "a snapshot is restored as planned now: nothing reviewed it")
    overrides = _overrides(ctx, override_window, None)
    if json_out:
        from prc3cfg.cli import stream

        events = stream.Stream("restore")
        with stream.accounted(events) as finished, line_options(trace, retries, lock_timeout,
                                                                stream.EventProgress(events)) as options:
            finished.append(api.restore(snapshot,
                                        gates=stream.gates(events, None, auto_approve, allow_axis_release),
                                        verify=api.Verify(verify.value), options=options,
                                        onto_current_lines=onto_current_lines,
                                        reason=reason, overrides=overrides))
        return
    with line_options(trace, retries, lock_timeout) as options, output.accounted():
        result = api.restore(snapshot,
                             gates=output.gates(None, auto_approve, allow_axis_release, options, frames),
                             verify=api.Verify(verify.value),
                             options=options, onto_current_lines=onto_current_lines, reason=reason,
                             overrides=overrides)
    output.applied(result, "restore")
