"""`--json` of `apply`, `restore` and `adopt`: their events (`prc3cfg.core.events`) on stdout, one JSON object
a line, each written and flushed as it happens — a CI step or a dashboard follows them with `while read`.

Nothing else goes to stdout then: errors and warnings stay one line each on stderr, and the run's last
event is its `account`, also when it ends in an error. No question can be asked on a stream, so the
command line answers each one: `--auto-approve` (or a reviewed plan file, `--plan`) approves, and
`--allow-axis-release` allows releases; a question not answered so is refused before anything is read.
"""

from __future__ import annotations

import contextlib
import json
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from prc3cfg.api import ApplyFailed, ApplyInterrupted, ApplyResult, Gates
from prc3cfg.core import events, render
from prc3cfg.core.plan_file import write as plan_file
from prc3cfg.core.plant_plan import PlantPlan
from prc3cfg.errors import Interrupted, UserError


class Stream:
    """Events written to stdout one a line, whole and flushed: the lines' threads emit at once."""

    def __init__(self, command: str) -> None:
        self.command = command
        self._lock = threading.Lock()

    def emit(self, document: dict[str, Any] | None) -> None:
        if document is None:
            return
        text = json.dumps(document) + "\n"  # ASCII: any pipe carries it, and no C1 control or line separator
        # another user's record brought (a travel event names their claims) reaches a terminal that
        # shows the stream
        with self._lock:
            sys.stdout.write(text)
            sys.stdout.flush()

    def event(self, kind: str, **fields: Any) -> None:
        self.emit(events.event(kind, self.command, **fields))


class EventProgress:
    """`api.Progress` as `progress` events: a phase's start (`done` 0) and each step of it."""

    def __init__(self, stream: Stream) -> None:
        self._stream, self._phase, self._done, self._total = stream, "", 0, 0
        self._lock = threading.Lock()

    def start(self, what: str, total: int) -> None:
        with self._lock:
            self._phase, self._done, self._total = what, 0, total
            self._stream.event("progress", phase=what, done=0, total=total)

    def advance(self) -> None:
        with self._lock:
            self._done += 1
            self._stream.event("progress", phase=self._phase, done=self._done, total=self._total)

    def note(self, text: str) -> None:
        """Nothing: what a note says (the snapshot's path, a line's plan) comes in the events themselves."""


def gates(stream: Stream, plan_given: Path | None, auto_approve: bool, allow_axis_release: bool) -> Gates:
    """The gates of an apply whose questions the command line answers (`unanswered` checked before): each
    line's plan and then the plant's as `plan` events, and each question with its answer."""
    approved_by = "--auto-approve" if auto_approve else f"--plan {plan_given}"

    def document(the_plan: PlantPlan) -> dict[str, Any]:
        return plan_file(the_plan, [], render)

    def show_line(line_plan: PlantPlan) -> None:
        stream.event("plan", lines=sorted(line_plan.buses()), whole=False, plan=document(line_plan))

    def show(the_plan: PlantPlan) -> None:
        stream.event("plan", lines=sorted(the_plan.buses()), whole=True, plan=document(the_plan))
        if the_plan.axis_releases and allow_axis_release:
            names = [change.name for change in the_plan.axis_releases]
            stream.emit(events.question(stream.command,
                                        f"Release the axes of {render.plural(len(names), 'module')}?", True,
                                        "--allow-axis-release"))
        # else refused before it is asked
        if the_plan.changes and (allow_axis_release or not the_plan.axis_releases):
            stream.emit(events.question(stream.command, _approval(the_plan), True, approved_by))

    def refuse_release(names: list[str]) -> bool:
        stream.emit(events.question(stream.command,
                                    f"Release the axes of {render.plural(len(names), 'module')}?", False,
                                    "no --allow-axis-release"))
        return False

    return Gates(show=show, show_line=show_line,
                 allow_axis_release=True if allow_axis_release else refuse_release)


def _approval(the_plan: PlantPlan) -> str:
    """The question a terminal would ask before the writes (`prc3cfg.cli.output.gates`)."""
    return (f"Apply {render.plural(the_plan.message_count, 'message')} to "
            f"{render.plural(len(the_plan.changes), 'module')}?")


def accounts(stream: Stream, result: ApplyResult) -> None:
    """Each module's account, and the modules that must travel; the releases they name count as told then."""
    for run in result.runs:
        stream.emit(events.module(stream.command, run))
    stream.emit(events.travel(stream.command, result.runs, result.earlier))
    from prc3cfg.api import told

    told(result)


def _ended(result: ApplyResult) -> dict[str, Any]:
    return {"modules": len(result.runs),
            "written": sum(bool(run.steps) and run.verified for run in result.runs),
            "journal": str(result.journal) if result.runs else None,
            "snapshot": None if result.snapshot is None else str(result.snapshot),
            "took": {phase: round(seconds, 3) for phase, seconds in result.took.items()},
            "estimated": {phase: round(seconds, 3) for phase, seconds in result.plan.phases().items()}}


@contextlib.contextmanager
def accounted(stream: Stream) -> Iterator[list[ApplyResult]]:
    """Run an apply (or restore): the list it yields takes its result; whatever becomes of it, the last event
    is its `account` — then the error goes on to stderr as without `--json`."""
    finished: list[ApplyResult] = []
    try:
        yield finished
    except (ApplyInterrupted, ApplyFailed) as stopped:
        accounts(stream, stopped.result)
        interrupted = isinstance(stopped, ApplyInterrupted)
        status, code = ("interrupted", 130) if interrupted else ("failed", stopped.exit_code)
        stream.emit(events.account(stream.command, status, code, errors=str(stopped).split("\n"),
                                   **_ended(stopped.result)))
        raise
    except UserError as error:  # refused (or interrupted) before any write: the plan, a gate, the line
        status = "interrupted" if isinstance(error, Interrupted) else "refused"
        stream.emit(events.account(stream.command, status, error.exit_code, errors=str(error).split("\n")))
        raise
    except KeyboardInterrupt:
        stream.emit(events.account(stream.command, "interrupted", 130, errors=["interrupted"]))
        raise
    result = finished[0]
    accounts(stream, result)
    stream.emit(events.account(stream.command, "verified" if result.runs else "nothing to do", 0,
                               **_ended(result)))
