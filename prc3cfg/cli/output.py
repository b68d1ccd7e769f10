"""What `read`, `plan`, `apply` and `restore` print and ask: plans, drift, gates, the account of an apply.

Imported by the commands when they run (not when `prc3cfg --help` lists them). Rendering is
`prc3cfg.core.render`'s — plans, drift, each module's account; this module arranges it for the
terminal (which stream, in what order) and asks the questions.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from prc3cfg.cli.common import TerminalProgress, ask, print_lines, to_the_terminal, write_output
from prc3cfg.core import render
from prc3cfg.core.plan_file import write as plan_file
from prc3cfg.core.plant_plan import PlantPlan
from prc3cfg.core.text import markdown as markdown_text
from prc3cfg.errors import UserError
from prc3cfg.shell.platform import command_line

if TYPE_CHECKING:  # annotations here; an apply's classes are loaded where one runs (`gates`, `accounted`)
    from prc3cfg.api import ApplyResult, Drift, Gates, LineOptions, PolicyReport


def emit_plan(plan: PlantPlan, *, out: Path | None, json_out: bool, markdown: bool, max_chars: int,
              notes: list[str],
              frames: bool = False, policy: PolicyReport | None = None) -> None:
    """The plan for people, as markdown or as JSON, and into `out`; with what the plant's `policy` found, in
    each."""
    faults = plan.faults  # a fault a write revealed, on the lines read (a plan of a file's images names none)
    document = plan_file(plan, notes, render) if out is not None or json_out else None
    if out is not None:
        write_output(out, json.dumps(document, indent=1) + "\n", "--out")
    # streamed, 10,000 pieces a write: one string of 8 × 30 × 64 is 80 MB of pieces, one write a piece 2 s
    if json_out and document is not None:
        # the fault states a write revealed, kept in the records (the plan file leaves them out: apply --plan
        # tells its own)
        extra = (({"faults": list(faults)} if faults else {})
                 | ({"policy": policy.to_json()} if policy is not None else {}))
        pieces = json.JSONEncoder(indent=1).iterencode(document | extra)
        for text in iter(lambda: "".join(itertools.islice(pieces, 10_000)), ""):
            sys.stdout.write(text)
        print()
    elif markdown:
        full_plan = f"`{out.name}`" if out else "the plan file"
        # the policy's findings first, never cut (a reviewer must see them); the comment's last line end is
        # its own, counted in the budget
        said = "" if policy is None else "\n".join(["#### Policy", "",
                                                    *(f"- {markdown_text(line.strip())}"
                                                      for line in policy.lines())]) + "\n\n"
        print(said + render.markdown(plan, max_chars=max_chars - len(said), notes=notes, full_plan=full_plan,
                                     faults=faults, frames=frames), end="")
    else:
        if policy is not None:
            print_lines("\n".join(policy.lines()))
        # the plan made now: its words are prc3cfg's, not a file's
        print_lines(render.human(plan, notes=notes, faults=faults, frames=frames))
        if out is not None:
            print(f"Plan written to {out}; apply it with: "
                  f"{command_line('prc3cfg', 'apply', '--plan', str(out))}")


def targeting(modules: list[str] | None) -> None:
    """Terraform's -target warning: a plan of some modules is not the plan of the plant."""
    if modules:
        print(f"⚠ Only {', '.join(modules)} (--module): the rest of the plant file is left out of this "
              "plan — run without --module to see everything it would change")


def emit_drift(drifted: list[Drift], plant: str, modules: int, *, out: Path | None, json_out: bool,
               markdown: bool, max_chars: int) -> None:
    """Drift (Teach In, work on the floor) as drift, not as a plan: for people (`render.drift_lines`),
    as JSON or markdown (`render.drift_json`, `drift_markdown`), and into `out` as JSON."""
    document = render.drift_json(plant, drifted, modules)
    if out is not None:
        write_output(out, json.dumps(document, indent=1) + "\n", "--out")
    if json_out:
        print(json.dumps(document, indent=1))
    elif markdown:
        full_drift = f"`{out.name}`" if out else "the drift file"
        # its line end is counted in the budget
        print(render.drift_markdown(document, max_chars=max_chars, full_drift=full_drift), end="")
    else:
        print_lines("\n".join(render.drift_lines(drifted, modules)))
        if out is not None:
            print(f"Drift written to {out}")


def gates(plan_file: Path | None, auto_approve: bool, allow_axis_release: bool, options: LineOptions,
          frames: bool = False) -> Gates:
    """Show the plan — the read-back's progress taken off the screen first — and ask about axis
    releases and the apply itself on a terminal (`ask`), unless told not to."""
    from prc3cfg.api import Gates

    shown: set[str] = set()  # the lines whose plan was shown as their writes began

    def show_line(line_plan: PlantPlan) -> None:
        shown.update(change.bus for change in line_plan.modules)
        options.progress.note(render.line_part(line_plan, frames))

    def show(the_plan: PlantPlan) -> None:
        if isinstance(options.progress, TerminalProgress):
            options.progress.stop()
        if plan_file is not None:
            print(f"Applying {plan_file}, proved against the modules as read back now:")
        text = render.human(the_plan, shown=shown, frames=frames)
        print_lines(text)
        questions = not auto_approve or (the_plan.axis_releases and not allow_axis_release)
        if the_plan.changes and questions and sys.stdin.isatty() and not sys.stdout.isatty():
            # stdout is a file (`apply > apply.log`): what is asked about goes where it is asked
            to_the_terminal(text)
        if not the_plan.changes:
            print("Nothing to do: nothing was written (the headline above says what the plan rests on).")

    def allow(names: list[str]) -> bool:
        if auto_approve or not sys.stdin.isatty():
            return False  # refused, naming the flag
        summary = "\n".join(render.release_summary(names))
        if not ask(f"{summary}\nRelease the axes of {render.plural(len(names), 'module')}?", options,
                   typed=True):
            raise UserError(f"axis release of {render.some_of(names)} not allowed (only 'yes' allows it) — "
                            "nothing was written")
        return True

    def approve(the_plan: PlantPlan) -> bool:
        question = (f"Apply {render.plural(the_plan.message_count, 'message')} to "
                    f"{render.plural(len(the_plan.changes), 'module')}?")
        if not sys.stdin.isatty():
            raise UserError(f"{question} — no terminal to ask: pass --auto-approve to apply without asking")
        return ask("Every module must be in STOP and AUTOMATIC: a running one would take the new values on "
                   f"its next move. {question}",
                   options, typed=True)

    # --auto-approve with --allow-axis-release: no question, so each line is written as soon as its plan
    # is whole (`Gates.asks`)
    return Gates(show=show, allow_axis_release=True if allow_axis_release else allow,
                 approve=None if auto_approve else approve, show_line=show_line)


def report(result: ApplyResult) -> None:
    """The account of every module, the reference-travel list (with the releases earlier applies
    left untold), where the records are — and then those releases count as told."""
    for run in result.runs:
        if (said := render.account(run)) is not None:
            print(said, file=sys.stdout if run.verified else sys.stderr)
    if (travel := render.travel_list(result.runs)) is not None:
        print(travel)
    for line in [*render.broadcasts_heard(result.plan.proofs, result.runs),
                 *render.earlier_releases(result.earlier)]:
        print(line)
    if result.runs:
        print(f"Journal: {result.journal}", flush=True)
    from prc3cfg.api import told  # the apply's: what only an apply needs is loaded when one ran

    told(result)


@contextlib.contextmanager
def accounted() -> Iterator[None]:
    """Run an apply; whatever becomes of it after its first write, say what it did."""
    from prc3cfg.api import ApplyFailed, ApplyInterrupted

    try:
        yield
    except ApplyInterrupted as stopped:
        report(stopped.result)
        for line in stopped.result.unread:  # a line Ctrl-C stopped before it was read and planned
            print(line, file=sys.stderr)
        failed = [r for r in stopped.result.runs if not r.verified]
        touched = sum(1 for r in failed if r.sent)
        restore = command_line("prc3cfg", "restore", str(stopped.result.snapshot))
        print(f"Interrupted: {len(stopped.result.runs) - len(failed)} of "
              f"{render.plural(len(stopped.result.runs), 'module')} "
              "written and verified, "
              + (f"{touched} written in part or whole but not verified — restore them with: {restore}"
                 if touched
                 else "nothing sent to the others"))
        raise
    except ApplyFailed as failed:
        report(failed.result)
        raise


def applied(result: ApplyResult, command: str = "apply") -> None:
    """The account of a finished apply (or restore) and its time — said to be far below the estimate of a
    real line where every line was the embedded emulator, which answers at once (`ApplyResult.at_once`)."""
    if result.runs or result.earlier:
        report(result)
    if result.runs:
        written = render.plural(sum(bool(run.steps) for run in result.runs), "module")
        print_lines(f"{command.capitalize()} complete: {written} written and verified.\n"
                    + render.timing(result.plan.phases(), result.took)
                    + (" — the embedded emulator answers at once: the estimate is what a line at the plant "
                       "file's baud takes" if result.at_once else ""))


def write_picture(path: Path, data: bytes, module: str) -> None:
    """A drawing of a module's chains (`--plot`) written where it was asked for."""
    try:
        path.write_bytes(data)
    except OSError as error:
        raise UserError(f"--plot {path}: cannot write it ({error.strerror}) — nothing was "
                        "saved there") from None
    print(f"{path}: the chains of module {module}")
