"""The account of an apply: what was and was not written to each module and what its read-back says
(`account`), the modules that must travel to their reference point (`travel_list`, and `earlier_releases` an
earlier apply left untold), and the lines whose broadcasts only the plan's modules heard (`broadcasts_heard`).
It reads each module's outcome as the apply left it (`prc3cfg.core.outcome.ModuleOutcome`). Pure: returns
strings.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Protocol

from prc3cfg.core import text as escape
from prc3cfg.core.axes import Release
from prc3cfg.core.outcome import ModuleOutcome, to_travel
from prc3cfg.core.plant_plan import LineProof
from prc3cfg.core.render.words import differences, listed
from prc3cfg.core.text import address_ranges


def account(run: ModuleOutcome) -> str | None:
    """What was and was not written to one module, and what a read-back says it holds now (None: a
    module not in the plan that was not looked at — nothing to say)."""
    head = f"bus {run.bus}, module {run.address} ({run.name})"
    if run.verified and not run.steps:
        if not run.watched:
            return None
        return (f"✓ {head}: not in the plan; its system parameters read back as they were (a release went "
                "out on a line without error detection)")
    if run.verified:
        repaired = (f", after {run.repairs} repair round{'s' if run.repairs != 1 else ''}" if run.repairs
                    else "")
        received = (f" and {run.broadcasts} broadcast{'s' if run.broadcasts != 1 else ''} received"
                    if run.broadcasts else "")
        return (f"✓ {head}: {len(run.written)} message{'s' if len(run.written) != 1 else ''} "
                f"written{received}, verified{repaired}")
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
        lines.append("    read back, it differs from the plant file: "
                     + "; ".join(differences(run.final, run.desired)))
    return "\n".join(lines)


#: What the account says of modules whose axes were, or may have been, released.
TRAVEL = "⚠ Travel to reference point required before production on:"


def travel_list(runs: Sequence[ModuleOutcome]) -> str | None:
    """The modules whose axes were — or may have been — released: they must travel to their reference point.
    The heading, then each bus's modules on lines of their own (`listed`)."""
    released = to_travel(runs)
    if not released:
        return None
    return "\n".join(listed(TRAVEL, ([f"{r.bus}/{r.name}"
                                      + (" (possibly: its 10h/20h went out unacknowledged)"
                                         if r.released is Release.POSSIBLY else "")
                                      for r in released if r.bus == bus]
                                     for bus in dict.fromkeys(r.bus for r in released))))


class Untold(Protocol):
    """What the account reads of an axis release an earlier apply sent and never told of — it was
    killed after its 10h/20h (`prc3cfg.shell.pending_records.Pending`)."""

    @property
    def bus(self) -> str: ...
    @property
    def name(self) -> str: ...
    @property
    def command(self) -> str: ...
    @property
    def pid(self) -> int: ...
    @property
    def time(self) -> str: ...
    @property
    def journal(self) -> str | None: ...
    @property
    def owner(self) -> str | None: ...


def earlier_releases(records: Iterable[Untold]) -> list[str]:
    """The modules whose axes an earlier apply may have released and ended before saying so: they must travel
    too — another user's record told as their claim; every field escaped, as the file says it
    (`escape.shown`)."""
    shown = escape.shown
    return [f"{TRAVEL} {shown(r.bus)}/{shown(r.name)} (possibly: "
            + ("" if r.owner is None else f"{r.owner}'s record says ")
            + f"an earlier prc3cfg {shown(r.command)}, pid {r.pid} at {shown(r.time)}, sent a 10h/20h and "
              "ended before its account"
            + (f"; journal {shown(r.journal)})" if r.journal else ")") for r in records]


def broadcasts_heard(proofs: Iterable[LineProof], runs: Sequence[ModuleOutcome]) -> list[str]:
    """After an apply, each line that took a broadcast where the probes had found every address the
    plant file does not list silent: only the plan's modules heard it."""
    return [f"Bus {proof.bus}: broadcast after {address_ranges(proof.silent)} answered no probe — only the "
            "plan's modules heard it"
            for proof in proofs if proof.silent
            and any(run.bus == proof.bus and run.broadcasts for run in runs)]
