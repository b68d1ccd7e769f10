"""Policy: the policy file a plant file names, judged on the modules a plan or an apply takes, at a moment.

`policy(plant, modules, now)` evaluates it (`prc3cfg.core.policy.findings`) and places each finding in its
files; `PolicyReport.gate` refuses (`PolicyRefused`; `WindowShut`, exit 75, where only windows refuse) what
refuses unless overridden, and says what was overridden, by whom and why, for the journal. "Now" is the
clock's, or `PRC3CFG_POLICY_NOW` (an ISO 8601 instant with its offset) for tests and rehearsals — said on
screen and in the journal whenever it is used (`policy_now`).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any

from prc3cfg.api._plan import select
from prc3cfg.core.text import shown
from prc3cfg.errors import UserError
from prc3cfg.plant import Plant
from prc3cfg.plant.problems import Finding
from prc3cfg.shell import platform
from prc3cfg.shell.plant_files import load_policy, plant_document

if TYPE_CHECKING:
    from prc3cfg.core import policy as rules

#: The environment variable that sets the moment windows are judged at (tests, rehearsing a freeze).
NOW_VARIABLE = "PRC3CFG_POLICY_NOW"
#: What each override option overrides.
OVERRIDES = {"window": "--override-window", "envelope": "--override-envelope"}


class PolicyRefused(UserError):
    """The policy refuses: one line per refusing finding, and what to do."""


class WindowShut(PolicyRefused):
    """Only windows refuse: the change waits for one to open (or shut), it is not wrong — a CI job tells it
    from a failure by the exit code, sysexits' EX_TEMPFAIL ("try again later"; docs/fleet.md reports the line
    as waiting)."""

    exit_code = 75


@dataclass(frozen=True)
class PolicyReport:
    """What a policy found for one plan or apply: the file and its SHA-256, the moment, each finding and its
    line."""

    file: str
    sha256: str
    now: datetime
    clock: str  # "system", or NOW_VARIABLE when that set it
    placed: tuple[tuple[rules.RuleFinding, Finding], ...]  # each finding and where it is said

    @property
    def findings(self) -> tuple[tuple[rules.RuleFinding, str], ...]:
        """Each finding and its line, "file:line:column: level: what"."""
        return tuple((f, shown(f"{at.file}:{at.line}:{at.column}: {at.message}")) for f, at in self.placed)

    @property
    def fails_plan(self) -> bool:
        """Whether these findings fail a plan and a plant file (`core.policy.fails_plan`)."""
        # loaded with the policy itself (`policy`): a report is made of it
        from prc3cfg.core import policy as rules

        return rules.fails_plan(f for f, _ in self.placed)

    def lines(self) -> list[str]:
        head = f"Policy {self.file} (sha256 {self.sha256[:12]}), judged at {self.now.isoformat()}"
        head += f" — set by {NOW_VARIABLE}, not the clock" if self.clock != "system" else ""
        return ([head, *(f"  {line}" for _, line in self.findings)] if self.findings
                else [head + ": no findings"])

    def only(self, kind: str) -> PolicyReport:
        """What the rules of one kind found: a restore is judged by windows only (no envelope judges a
        snapshot), `validate` by envelopes only (it judges no moment)."""
        return replace(self, placed=tuple((f, at) for f, at in self.placed if f.kind == kind))

    def gate(self, overrides: Mapping[str, str]) -> dict[str, Any]:
        """`PolicyRefused` when something refuses despite `overrides`; else what goes into the journal's
        header."""
        # loaded with the policy itself (`policy`): a report is made of it
        from prc3cfg.core import policy as rules

        refusing = rules.refusing([f for f, _ in self.findings], overrides)
        if refused := [line for f, line in self.findings if f in refusing]:
            unused = sorted({f.kind for f in refusing if f.level == "soft"})
            fix = ("change the plant file or the policy (a hard rule is never overridden)"
                   if any(f.level == "hard" for f in refusing)
                   else " or ".join(f"{OVERRIDES[k]} REASON" for k in unused)
                   + " (an override is recorded in the journal)")
            refusal = WindowShut if all(f.kind == "window" for f in refusing) else PolicyRefused
            raise refusal("\n".join([*refused, "the policy refuses this apply; nothing was "
                                               f"written — {fix}"]))
        overridden = [{"kind": f.kind, "rule": f.rule, "finding": line, "reason": overrides[f.kind],
                       "user": platform.user_name()}
                      for f, line in self.findings if f.level == "soft" and f.kind in overrides]
        return self.to_json() | {"overridden": overridden}

    def to_json(self) -> dict[str, Any]:
        return {"file": self.file, "sha256": self.sha256, "now": self.now.isoformat(), "clock": self.clock,
                "findings": [{"kind": f.kind, "rule": f.rule, "level": f.level, "text": line}
                             for f, line in self.findings]}


def policy_now() -> tuple[datetime, str]:
    """The moment windows are judged at, and what set it: `PRC3CFG_POLICY_NOW`, else the system clock."""
    given = os.environ.get(NOW_VARIABLE)
    if not given:
        return datetime.now(UTC), "system"
    try:
        moment = datetime.fromisoformat(given)
    except ValueError:
        moment = None
    if moment is None or moment.tzinfo is None:
        raise UserError(f"{NOW_VARIABLE}={given!r} is not an ISO 8601 instant with its offset "
                        "(2026-03-30T09:00:00+02:00) — "
                        f"set it so, or unset it to use the clock")
    return moment.astimezone(UTC), NOW_VARIABLE


def policy(plant: Plant, modules: Iterable[str] | None = None,
           now: datetime | None = None) -> PolicyReport | None:
    """The policy `plant` names judged on its (named) modules and their buses at `now` (default `policy_now`);
    None when it names none. A finding about a value is placed at the plant file's value, naming the rule's
    place. The rules and the policy's models are loaded here, for a plant file that names a policy: 9 ms of
    CPU that every plan and apply of one that names none paid at import."""
    loaded = load_policy(plant)
    if loaded is None:
        return None
    from prc3cfg.core import policy as rules
    from prc3cfg.plant.policy import placed, plant_values

    moment, clock = (now, "given") if now is not None else policy_now()
    pairs = select(plant, modules)
    found = rules.findings(plant_values(pairs, loaded.rules.limited), [bus.name for bus, _ in pairs],
                           loaded.rules, moment)
    document = plant_document(plant) if any(f.value_at is not None for f in found) else None
    return PolicyReport(str(loaded.path), loaded.sha256, moment, clock,
                        tuple((f, placed(f, document, loaded)) for f in found))
