"""The events of `apply --json`, `restore --json` and `adopt --json`: one JSON object a line, in the order
things happen, each `{"format": "prc3cfg-event/1", "event": KIND, "command": …, …}`
(`schemas/event.schema.json`).

    plan      the plan, as the plan file holds it (`plan`: the `prc3cfg-plan/1` document), once a line's or
    the
              plant's plan is whole (`lines`: the buses it covers); adopt: the values it would write
    question  what a person would be asked, the answer the command line gave (`--auto-approve`, …) and why
    progress  a phase began (`done` 0) or a step of it was done: reading, writing, verifying
    module    one module's account: verified / failed / unchanged, what was written, sent unacknowledged, not
              sent, what its read-back says, and the account's sentence (`text`,
              `prc3cfg.core.render.applied`)
    travel    the modules that must travel to their reference point (this run's, and earlier runs' untold)
    account   the last line: `status`, the exit code, how many modules were written and verified, the
              journal and snapshot, the times, and the error lines when it ended in one

Owns the shape of each event; the words in them are `prc3cfg.core.render`'s and the plan's document is
`prc3cfg.core.plan_file`'s. Pure: returns dicts; the CLI writes them (`prc3cfg.cli.stream`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

from prc3cfg.core import render
from prc3cfg.core.axes import Release
from prc3cfg.core.outcome import ModuleOutcome, to_travel

FORMAT = "prc3cfg-event/1"
#: Every kind of event, in the order a run emits them (a kind may repeat: a plan per line, a module each).
KINDS = ("plan", "question", "progress", "module", "travel", "account")
#: How a run ended (`account`'s `status`).
STATUSES = ("verified", "failed", "interrupted", "refused", "nothing to do", "adopted", "drift", "no drift")


def event(kind: str, command: str, **fields: Any) -> dict[str, Any]:
    """One event of `command`: its kind and fields, after the format."""
    assert kind in KINDS, kind
    return {"format": FORMAT, "event": kind, "command": command, **fields}


def question(command: str, asked: str, answer: bool, by: str) -> dict[str, Any]:
    """A question the command line answered: `asked` as a person would read it, yes or no, and what said
    so."""
    return event("question", command, question=asked, answer="yes" if answer else "no", by=by)


def _summaries(steps: Iterable[Any]) -> list[str]:
    return [step.summary for step in steps]


def _read_back(run: ModuleOutcome) -> dict[str, Any]:
    """What the module's read-back says: it matches the plant file, unchanged, differs (how), or unknown."""
    if run.final is None:
        return {"read_back": "unknown", "differences": []}
    if run.verified:
        return {"read_back": "matches", "differences": []}
    if run.unchanged:
        return {"read_back": "unchanged", "differences": []}
    return {"read_back": "differs", "differences": render.differences(run.final, run.desired)}


def module(command: str, run: ModuleOutcome) -> dict[str, Any] | None:
    """One module's account as an event (None where the human account says nothing: a module not in the
    plan that was not looked at)."""
    text = render.account(run)
    if text is None:
        return None
    result = "verified" if run.verified and run.steps else "unchanged" if run.verified else "failed"
    return event("module", command, bus=run.bus, address=run.address, name=run.name, result=result,
                 written=_summaries(run.written), unacknowledged=_summaries(run.unacknowledged),
                 unsent=_summaries(run.unsent),
                 broadcasts=run.broadcasts, repairs=run.repairs, failure=run.failure,
                 released=run.released.value,
                 **_read_back(run), text=text)


def travel(command: str, runs: Sequence[ModuleOutcome],
           earlier: Iterable[render.Untold]) -> dict[str, Any] | None:
    """The modules that must travel to their reference point before production (None: none must)."""
    modules = [{"bus": r.bus, "name": r.name, "released": r.released.value} for r in to_travel(runs)]
    told = list(earlier)
    modules += [{"bus": r.bus, "name": r.name, "released": Release.POSSIBLY.value} for r in told]
    if not modules:
        return None
    lines = [*(render.travel_list(runs) or "").splitlines(), *render.earlier_releases(told)]
    return event("travel", command, modules=modules, text=lines)


def account(command: str, status: str, code: int, *, modules: int = 0, written: int = 0,
            errors: Sequence[str] = (),
            **fields: Any) -> dict[str, Any]:
    """The last event of a run: how it ended, its exit code, how many modules it wrote and verified of
    those in its account, and the error lines (as on stderr) when it ended in one."""
    assert status in STATUSES, status
    return event("account", command, status=status, exit=code, modules=modules, written=written,
                 errors=list(errors), **fields)
