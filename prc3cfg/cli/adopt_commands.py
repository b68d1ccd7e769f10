"""`prc3cfg adopt`: the plant file rewritten in place to describe what the modules hold (Teach In).

Reads the modules and works out the new text (`prc3cfg.api.adopt`), shows each value adopted
and the unified diff of the file, then writes it (`prc3cfg.api.write_adoption`: atomically) — after asking on a
terminal, or with `--auto-approve`; without a terminal it refuses in one line. `--check` shows
the same and writes nothing: exit 2 when there is drift to adopt, 0 when there is none. The
file is written only if it is still the one that was read; its permissions are kept.

Arguments, prompts and output only: the work is `prc3cfg.api`'s.
"""


import sys
from typing import Annotated

import typer

from prc3cfg.cli import ExitStatus, app
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
)
from prc3cfg.cli.plan_commands import EXIT_CHANGES, ApproveOpt, ReasonOpt
from prc3cfg.errors import UserError

ProgramOpt = Annotated[
    list[int] | None,
    typer.Option("--program", min=1, max=64, metavar="N", help="Only this program (number); repeatable. System parameters are then left alone."),
]
CheckOpt = Annotated[bool, typer.Option("--check", help="Show the diff; exit 2 if there is drift to adopt, 0 if none; write nothing.")]


@app.command()
def adopt(
    plant: PlantArg,
    module: ModuleOpt = None,
    program: ProgramOpt = None,
    check: CheckOpt = False,
    auto_approve: ApproveOpt = False,
    trace: TraceOpt = None,
    retries: RetriesOpt = 5,
    lock_timeout: LockOpt = 0.0,
    reason: ReasonOpt = None,
) -> None:
    """Rewrite the plant file in place to describe what the modules hold (positions taught on the
    floor): only the values that drifted, in the layer they came from; comments and layout kept."""
    import difflib

    from prc3cfg import api

    check_output(trace, "--trace", plant=plant)
    loaded = api.load(plant)
    with line_options(trace, retries, lock_timeout) as options:
        adoption = api.adopt(loaded, module, program, options, reason=reason, check=check)
    if not adoption.adopted:
        print("No drift to adopt: the modules hold what the plant file says.")
        return
    print_lines("\n".join(value.text for value in adoption.adopted))
    diff = difflib.unified_diff(adoption.before.splitlines(), adoption.after.splitlines(), str(plant), f"{plant} (adopted)", lineterm="")
    print("\n".join(diff))
    if check:
        raise ExitStatus(EXIT_CHANGES)
    question = f"Write {_count(len(adoption.adopted))} into {plant}?"
    if not auto_approve:
        if not sys.stdin.isatty():
            raise UserError(f"{question} — no terminal to ask: pass --auto-approve to write it without asking, "
                            "or --check to see the diff only")  # fmt: skip
        if not ask(question):
            raise UserError("not adopted — the plant file was not changed")
    api.write_adoption(adoption)
    print(f"Adopted {_count(len(adoption.adopted))} into {plant}: it describes what the modules hold now "
          "— review the diff and commit it.")  # fmt: skip


def _count(values: int) -> str:
    return f"{values} value{'s' if values != 1 else ''}"
