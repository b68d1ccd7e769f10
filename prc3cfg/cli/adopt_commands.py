"""`prc3cfg adopt`: the plant file rewritten in place to describe what the modules hold (Teach In).

Reads the modules (`prc3cfg.api.read`), works out the new text (`prc3cfg.plant.adopt`), shows each
value adopted and the unified diff of the file, then writes it atomically — after asking on a
terminal, or with `--auto-approve`; without a terminal it refuses in one line. `--check` shows
the same and writes nothing: exit 2 when there is drift to adopt, 0 when there is none. The
file is written only if it is still the one that was read; its permissions are kept.

Arguments, prompts and output only: the work is `prc3cfg.plant.adopt`'s.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from prc3cfg.cli import Outcome, app
from prc3cfg.cli.common import (
    LockOpt,
    ModuleOpt,
    PlantArg,
    RetriesOpt,
    TraceOpt,
    check_output,
    line_options,
    print_lines,
)
from prc3cfg.cli.plan_commands import EXIT_CHANGES, ApproveOpt
from prc3cfg.errors import UserError

ProgramOpt = Annotated[
    Optional[list[int]],
    typer.Option("--program", min=1, max=64, help="Only this program (number); repeatable. System parameters are then left alone."),
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
) -> None:
    """Rewrite the plant file in place to describe what the modules hold (positions taught on the
    floor): only the values that drifted, in the layer they came from; comments and layout kept."""
    import difflib
    import os
    import stat

    from prc3cfg import api
    from prc3cfg.plant import adopt as adopting
    from prc3cfg.shell.files import write_atomically

    check_output(trace, "--trace", plant=plant)
    loaded = api.load(plant)
    text = _text(plant)
    with line_options(trace, retries, lock_timeout) as options:
        images = api.read(loaded, module, options)
    adoption = adopting.adopt(loaded, images, text, program)
    if not adoption.adopted:
        print("No drift to adopt: the modules hold what the plant file says.")
        return
    print_lines("\n".join(value.text for value in adoption.adopted))
    diff = difflib.unified_diff(text.splitlines(), adoption.text.splitlines(), str(plant), f"{plant} (adopted)", lineterm="")
    print("\n".join(diff))
    if check:
        raise Outcome(EXIT_CHANGES)
    question = f"Write {_count(len(adoption.adopted))} into {plant}?"
    if not auto_approve:
        if not sys.stdin.isatty():
            raise UserError(f"{question} — no terminal to ask: pass --auto-approve to write it without asking, "
                            "or --check to see the diff only")  # fmt: skip
        if not typer.confirm(question, default=False):
            raise UserError("not adopted — the plant file was not changed")
    if _text(plant) != text:
        raise UserError(f"{plant}: the plant file changed while adopting — it was not written: adopt again")
    target = plant.resolve()  # a link to the plant file stays a link
    mode = stat.S_IMODE(os.stat(target).st_mode)
    try:
        write_atomically(target, adoption.text)
        os.chmod(target, mode)
    except OSError as error:
        raise UserError(f"{plant}: cannot write it ({error.strerror}) — it was not changed") from None
    print(f"Adopted {_count(len(adoption.adopted))} into {plant}: it describes what the modules hold now "
          "— review the diff and commit it.")  # fmt: skip


def _text(plant: Path) -> str:
    """The plant file's text as it is now (`prc3cfg.plant.adopt` checks it is the one loaded)."""
    try:
        return plant.read_bytes().decode("utf-8", "replace")
    except OSError as error:
        raise UserError(f"{plant}: cannot read it ({error.strerror}) — nothing was adopted") from None


def _count(values: int) -> str:
    return f"{values} value{'s' if values != 1 else ''}"
