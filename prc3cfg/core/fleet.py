"""Lines as a fleet: which lines a change touches, the GitHub matrix of them, and the fleet summary of their
status.

A line is one bus of one plant file, on the self-hosted runner beside it (docs/fleet.md). This module owns:
- `selected`: the lines a change touches — those whose plant file changed, or the policy file their plant file
  names (a policy change touches every line of every plant file that names it);
- `matrix`: the GitHub Actions matrix of lines (`strategy.matrix: ${{ fromJSON(...) }}`), one entry per line;
- `summary`: the `prc3cfg-fleet-summary/1` document of the lines' `prc3cfg-status/1` lines, and `markdown`,
  its table for the pull request. A line an apply left waiting for a window says so, with the window's words;
  one whose apply was refused (a stale plan, no reviewed plan, a hard rule), with the refusal's.

Pure: the files are read by `prc3cfg.plant.fleet` (the fleet file) and the command
(`prc3cfg.cli.fleet_commands`); paths are compared as the normalised POSIX text the command gives.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

SUMMARY_FORMAT = "prc3cfg-fleet-summary/1"
#: What an artifact name and a job's id may hold of a line's name (GitHub refuses " : < > | * ? \\ / in an
#: artifact's).
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


@dataclass(frozen=True, slots=True)
class FleetLine:
    """One line of the fleet: its plant file and bus, the runner label beside it, the environment whose
    reviewers approve its applies, the modules on it and the policy file its plant file names (None: none)."""

    plant: str
    bus: str
    runner: str
    environment: str
    modules: tuple[str, ...]
    policy: str | None

    @property
    def name(self) -> str:
        """How people call it: plant file and bus."""
        return f"{self.plant}:{self.bus}"

    @property
    def id(self) -> str:
        """The line in an artifact's name: letters, digits, `.`, `_` and `-` of its plant file and bus."""
        plant = self.plant.removesuffix(".yaml").removesuffix(".yml")
        return _UNSAFE.sub("-", f"{plant}-{self.bus}").strip("-")

    @property
    def group(self) -> str:
        """Its concurrency group: every job that talks to the line, one at a time, in every workflow that
        names it so."""
        return f"prc3cfg-line {self.name}"


def selected(lines: Iterable[FleetLine], changed: Collection[str] | None) -> list[FleetLine]:
    """The lines a change of the files `changed` touches, in the fleet's order (`changed` None: every
    line)."""
    return [line for line in lines if changed is None or line.plant in changed
            or (line.policy is not None and line.policy in changed)]


def matrix(lines: Iterable[FleetLine]) -> dict[str, Any]:
    """The matrix of `lines` for `strategy.matrix`: one entry per line (`policy` "" for none; `modules` one a
    line, for a shell's `while read` to make `--module` options of)."""
    return {"include": [{"line": line.name, "id": line.id, "plant": line.plant, "bus": line.bus,
                         "runner": line.runner,
                         "environment": line.environment, "group": line.group, "policy": line.policy or "",
                         "modules": "\n".join(line.modules)}
                        for line in lines]}


@dataclass(frozen=True, slots=True)
class LineStatus:
    """What one line's job left: its line of a `prc3cfg-status/1` document, and the words of an apply a window
    refused (`waiting`) or that ended otherwise than done (`refused`)."""

    status: Mapping[str, Any]
    waiting: str | None = None
    refused: str | None = None


def summary(lines: Sequence[FleetLine], found: Mapping[FleetLine, LineStatus]) -> dict[str, Any]:
    """`prc3cfg fleet summary --json`: one row per line of the fleet, in its order (a line without status: not
    in this run)."""
    return {"format": SUMMARY_FORMAT, "lines": [_row(line, found.get(line)) for line in lines]}


def _row(line: FleetLine, found: LineStatus | None) -> dict[str, Any]:
    row: dict[str, Any] = {"line": line.name, "plant": line.plant, "bus": line.bus, "runner": line.runner}
    if found is None:
        return row | {"reported": False, "modules": None, "health": None, "drift": None,
                      "pending_travel": None,
                      "last_verified": None, "failed": None, "waiting": None, "refused": None}
    modules = found.status["modules"]
    verified = [m["last_verified"] for m in modules if m["last_verified"] is not None]
    last = max(verified, key=lambda v: v["time"], default=None)
    return row | {"reported": True, "modules": len(modules), "health": found.status["health"],
                  "drift": [m["name"] for m in modules if m["drift_seen"]],
                  "pending_travel": [m["name"] for m in modules if m["travel_pending"]],
                  "last_verified": None if last is None
                  else {"time": last["time"], "by": last["by"], "commit": last["commit"]},
                  "failed": any(m["last_failed"] for m in modules), "waiting": found.waiting,
                  "refused": found.refused}


def markdown(document: Mapping[str, Any]) -> str:
    """The summary as the pull request's comment and the run's step summary shows it: one table row per
    line."""
    rows = ["<!-- prc3cfg-fleet -->", "### prc3cfg fleet", "",
            "| line | modules | health | drift | pending travel | last verified | apply |",
            "|---|---|---|---|---|---|---|"]
    for row in document["lines"]:
        if not row["reported"]:
            rows.append(f"| {_cell(row['line'])} | | | | | | not in this run |")
            continue
        last = row["last_verified"]
        if last is None:
            verified = "never"
        else:
            by = last["by"] and f"by {last['by']}"
            commit = last["commit"] and f"at {last['commit'][:12]}"
            verified = " ".join(filter(None, (last["time"], by, commit)))
        apply = next((f"{said}: {row[said]}" for said in ("waiting", "refused") if row[said] is not None),
                     "failed" if row["failed"] else "done")
        cells = (row["line"], str(row["modules"]), row["health"], ", ".join(row["drift"]) or "none",
                 ", ".join(row["pending_travel"]) or "none",
                 verified, apply)
        rows.append("| " + " | ".join(_cell(cell) for cell in cells) + " |")
    return "\n".join(rows) + "\n"


def _cell(text: str) -> str:
    """Text in a table cell: a `|` would end it, a line break the row."""
    return " ".join(text.split()).replace("|", "\\|")
