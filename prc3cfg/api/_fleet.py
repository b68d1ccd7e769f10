"""Lines as a fleet: a fleet file's lines, the matrix of those a change touches, and the summary of their
status.

`fleet_lines` reads the fleet file and each plant file it names (a bus no plant file has is refused at the
fleet file's place); `fleet_matrix` selects and lays out the lines (`prc3cfg.core.fleet`); `fleet_summary`
reads the lines' `prc3cfg status --json` documents — each line in at most one, found by its bus and the plant
file the document names — and the `waiting.txt` and `refused.txt` beside each (the words of an apply a window
refused, or that ended otherwise than done), and makes the `prc3cfg-fleet-summary/1` document. Paths are
compared as normalised POSIX text, relative to the current folder (the repository's top in CI).
"""

from __future__ import annotations

import posixpath
from collections.abc import Iterable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from prc3cfg.core import fleet
from prc3cfg.core.status import FORMAT as STATUS_FORMAT
from prc3cfg.core.text import shown
from prc3cfg.errors import UserError
from prc3cfg.plant.fleet import lines
from prc3cfg.shell.files import FileProblem, Why, read_json, read_regular
from prc3cfg.shell.plant_files import load_fleet, load_plant

#: Beside a status document: the words of an apply a window refused on its lines, or that ended otherwise than
#: done.
WAITING, REFUSED = "waiting.txt", "refused.txt"
#: A status document is far smaller (a line of 30 modules: some 30 kB).
STATUS_LIMIT = 4 * 2**20


def fleet_lines(path: str | Path) -> list[fleet.FleetLine]:
    """The lines of the fleet file `path`, in its order; `PlantError` with the problems of it or of a plant
    file it names."""
    return lines(load_fleet(path), load_plant)


def fleet_matrix(path: str | Path, changed: Iterable[str] | None = None) -> dict[str, Any]:
    """The GitHub Actions matrix of the fleet's lines: every one, or (`changed` given) those the changed files
    touch."""
    touched = None if changed is None else {_normal(file) for file in changed}
    return fleet.matrix(fleet.selected(fleet_lines(path), touched))


def fleet_summary(path: str | Path, statuses: Sequence[Path]) -> dict[str, Any]:
    """The `prc3cfg-fleet-summary/1` document of the fleet's lines from their status documents `statuses`; a
    line in two of them, or a document's bus that is no line of the fleet, is refused in one line."""
    everything = fleet_lines(path)
    found: dict[fleet.FleetLine, fleet.LineStatus] = {}
    first: dict[fleet.FleetLine, Path] = {}
    for status_path in statuses:
        document = _status(status_path)
        said = fleet.LineStatus({}, _words(status_path.parent / WAITING),
                                _words(status_path.parent / REFUSED))
        for status in document["lines"]:
            line = _line_of(everything, document["plant_file"], status["bus"])
            if line is None:
                raise UserError(f"{status_path}: bus {status['bus']} of {document['plant_file']} is not a "
                                f"line of {path} — "
                                f"give the status of the fleet's lines")
            if line in found:
                raise UserError(f"{status_path}: line {line.name} is in {first[line]} too — give each "
                                "line's status once")
            found[line], first[line] = replace(said, status=status), status_path
    return fleet.summary(everything, found)


def _normal(path: str) -> str:
    return posixpath.normpath(path.replace("\\", "/"))


def _status(path: Path) -> dict[str, Any]:
    """A `prc3cfg-status/1` document, or one line saying what the file is not."""
    try:
        document = read_json(path, STATUS_LIMIT)
    except FileProblem as problem:
        raise UserError(f"{path}: {problem} — give what prc3cfg status PLANT --json printed") from None
    if (not isinstance(document, dict) or document.get("format") != STATUS_FORMAT
        or not isinstance(document.get("lines"), list)):
        raise UserError(f"{path}: not a {STATUS_FORMAT} document — give what prc3cfg status PLANT "
                        "--json printed")
    return document


def _words(path: Path) -> str | None:
    """What the fleet workflow's apply step wrote of its apply, on one line (None: nothing)."""
    try:
        text = read_regular(path, STATUS_LIMIT).decode("utf-8", "replace")
    except FileProblem as problem:
        if problem.why is Why.MISSING:
            return None
        raise UserError(f"{path}: {problem} — it holds the words of the line's apply "
                        "(docs/fleet.md)") from None
    return shown(" ".join(text.split())) or "(no words)"


def _line_of(everything: list[fleet.FleetLine], plant_file: str, bus: str) -> fleet.FleetLine | None:
    """The fleet's line of `bus` of the plant file a status document names (as the command that made it was
    given it: the line's path, relative to the repository, ends it)."""
    parts = _normal(plant_file).split("/")
    return next((line for line in everything if line.bus == bus
                 and parts[-len(line.plant.split("/")) :] == line.plant.split("/")), None)
