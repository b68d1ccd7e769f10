"""`prc3cfg adopt`: the plant file rewritten in place to describe what the modules hold (Teach In).

Reads the modules and works out the new text (`prc3cfg.api.adopt`), shows each value adopted and the unified
diff of the file, then writes it (`prc3cfg.api.write_adoption`: atomically) — after asking on a terminal, or
with `--auto-approve`; without a terminal it refuses in one line. `--check` shows the same and writes nothing:
exit 2 when there is drift to adopt, 0 when there is none. The file is written only if it is still the one
that was read; its permissions are kept.

Arguments, prompts and output only: the work is `prc3cfg.api`'s.
"""


import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from prc3cfg.cli import ExitStatus, app, click_errors
from prc3cfg.cli.common import (
    LockOpt,
    ModuleOpt,
    PlantArg,
    RetriesOpt,
    TraceOpt,
    ask,
    check_output,
    line_options,
    print_lines,
    unanswered,
)
from prc3cfg.cli.plan_commands import EXIT_CHANGES, ApproveOpt, ReasonOpt
from prc3cfg.errors import UserError

if TYPE_CHECKING:
    from prc3cfg.api import Adoption

ProgramOpt = Annotated[
    list[int] | None,
    typer.Option("--program", min=1, max=64, metavar="N",
                 help="Only this program (number); repeatable. System parameters are then left alone."),
]
CheckOpt = Annotated[bool, typer.Option("--check",
                                        help="Show the diff; exit 2 if there is drift to adopt, 0 if none; "
                                             "write nothing.")]


@app.command()
def adopt(
    ctx: typer.Context,
    plant: PlantArg,
    module: ModuleOpt = None,
    program: ProgramOpt = None,
    check: CheckOpt = False,
    auto_approve: ApproveOpt = False,
    trace: TraceOpt = None,
    retries: RetriesOpt = 5,
    lock_timeout: LockOpt = 0.0,
    reason: ReasonOpt = None,
    json_out: Annotated[bool, typer.Option("--json", help=(
        "Print events, one JSON object a line (prc3cfg-event/1: plan, question, account); needs "
        "--auto-approve or --check."))] = False,
) -> None:
    """Rewrite the plant file in place to describe what the modules hold (positions taught on the
    floor): only the values that drifted, in the layer they came from; comments and layout kept."""
    from prc3cfg import api

    if (why := unanswered(json_out, auto_approve or check, "or --check to see the diff only")) is not None:
        raise click_errors.UsageError(why, ctx=ctx)
    check_output(trace, "--trace", plant=plant)
    if json_out:
        _adopt_events(plant, module, program, check=check, trace=trace, retries=retries,
                      lock_timeout=lock_timeout, reason=reason)
        return
    loaded = api.load(plant)
    with line_options(trace, retries, lock_timeout) as options:
        adoption = api.adopt(loaded, module, program, options, reason=reason, check=check)
    if not adoption.adopted:
        print("No drift to adopt: the modules hold what the plant file says.")
        return
    print_lines("\n".join(value.text for value in adoption.adopted))
    print(_diff(adoption, plant))
    if check:
        raise ExitStatus(EXIT_CHANGES)
    question = f"Write {_count(len(adoption.adopted))} into {plant}?"
    if not auto_approve:
        if not sys.stdin.isatty():
            raise UserError(f"{question} — no terminal to ask: pass --auto-approve to write it "
                            "without asking, "
                            "or --check to see the diff only")
        if not ask(question):
            raise UserError("not adopted — the plant file was not changed")
    api.write_adoption(adoption)
    print(f"Adopted {_count(len(adoption.adopted))} into {plant}: it describes what the modules hold now "
          "— review the diff and commit it.")


def _diff(adoption: "Adoption", plant: Path) -> str:
    """The unified diff of the plant file, as adopted."""
    import difflib

    return "\n".join(difflib.unified_diff(adoption.before.splitlines(), adoption.after.splitlines(),
                                          str(plant), f"{plant} (adopted)",
                                          lineterm=""))


def _adopt_events(plant: Path, module: list[str] | None, program: list[int] | None, *, check: bool,
                  trace: Path | None, retries: int,
                  lock_timeout: float, reason: str | None) -> None:
    """`adopt --json`: what it would write and the diff (`plan`), the write approved by `--auto-approve`
    (`question`), and the `account` — `adopted`, `drift` (`--check`, exit 2) or `no drift` — also when it ends
    in an error."""
    from prc3cfg import api
    from prc3cfg.cli.stream import EventProgress, Stream
    from prc3cfg.core import events

    said = Stream("adopt")
    try:
        loaded = api.load(plant)
        with line_options(trace, retries, lock_timeout, EventProgress(said)) as options:
            adoption = api.adopt(loaded, module, program, options, reason=reason, check=check)
        adopted = [{"modules": list(value.modules), "what": value.what, "layer": value.layer}
                   for value in adoption.adopted]
        said.event("plan", adopted=adopted, diff=_diff(adoption, plant))
        values = len(adoption.adopted)
        if adoption.adopted and not check:
            said.emit(events.question("adopt", f"Write {_count(values)} "
                                               f"into {plant}?", True, "--auto-approve"))
            api.write_adoption(adoption)
    except UserError as error:
        said.emit(events.account("adopt", "refused", error.exit_code, errors=str(error).split("\n"),
                                 plant=str(plant)))
        raise
    status, code = ("no drift", 0) if not values else ("drift", EXIT_CHANGES) if check else ("adopted", 0)
    said.emit(events.account("adopt", status, code,
                             modules=len({name for value in adoption.adopted for name in value.modules}),
                             written=0 if check else values, plant=str(plant)))
    if code:
        raise ExitStatus(code)


def _count(values: int) -> str:
    return f"{values} value{'s' if values != 1 else ''}"
