"""`prc3cfg fleet matrix FLEET [--changed FILE…]` and `prc3cfg fleet summary FLEET STATUS_JSON…` (docs/fleet.md).

- `matrix`: the GitHub Actions matrix of the fleet's lines, one compact JSON line (`$GITHUB_OUTPUT` takes it): every
  line, or with `--changed` only those the changed files touch (paths relative to the current folder, as
  `git diff --name-only` gives them from the repository's top).
- `summary`: `prc3cfg status PLANT --json` documents of the lines (each line in at most one) gathered into one
  markdown table for the pull request, or `--json` (`prc3cfg-fleet-summary/1`). A `waiting.txt` beside a status
  document holds the words of an apply a window refused on its lines (the fleet workflow writes it).

Arguments, files and output only: what is selected and summarised is `prc3cfg.core.fleet`'s.
"""

from __future__ import annotations

import posixpath
from pathlib import Path
from typing import Annotated, Any

import typer

from prc3cfg.cli import app
from prc3cfg.errors import UserError

fleet_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None, help="Lines as a fleet: the CI matrix and the pull request's summary.")
app.add_typer(fleet_app, name="fleet")

FleetArg = Annotated[Path, typer.Argument(metavar="FLEET", help="The fleet file (YAML, prc3cfg-fleet/1).", show_default=False)]
#: Beside a status document: the words of an apply a window refused on its lines.
WAITING = "waiting.txt"
#: A status document is far smaller (a line of 30 modules: some 30 kB).
STATUS_LIMIT = 4 * 2**20


@fleet_app.command()
def matrix(
    fleet: FleetArg,
    files: Annotated[
        list[str] | None, typer.Argument(metavar="FILE...", help="With --changed: the files the change touches.", show_default=False)
    ] = None,
    changed: Annotated[bool, typer.Option("--changed", help="Only the lines whose plant file or policy file is among FILEs.")] = False,
) -> None:
    """Print the GitHub Actions matrix of the fleet's lines (one entry per line: plant, bus, runner, group, …)."""
    import json

    from prc3cfg.core import fleet as lines_of

    if files and not changed:
        raise UserError(f"prc3cfg fleet matrix: {files[0]} — give --changed before the changed files")
    everything = _lines(fleet)
    touched = None if not changed else {posixpath.normpath(f.replace("\\", "/")) for f in files or ()}
    print(json.dumps(lines_of.matrix(lines_of.selected(everything, touched)), separators=(",", ":")))


@fleet_app.command()
def summary(
    fleet: FleetArg,
    statuses: Annotated[list[Path], typer.Argument(metavar="STATUS_JSON...", help="`prc3cfg status PLANT --json` documents.", show_default=False)],
    json_out: Annotated[bool, typer.Option("--json", help="Print a prc3cfg-fleet-summary/1 document.")] = False,
) -> None:
    """Gather the lines' status into one table for the pull request: modules, health, drift, travel, last verified."""
    from prc3cfg.cli.common import print_document
    from prc3cfg.core import fleet as lines_of

    everything = _lines(fleet)
    found: dict[lines_of.Line, lines_of.LineStatus] = {}
    first: dict[lines_of.Line, Path] = {}
    for path in statuses:
        document = _status(path)
        waiting = _waiting(path.parent / WAITING)
        for status in document["lines"]:
            line = _line_of(everything, document["plant_file"], status["bus"])
            if line is None:
                raise UserError(f"{path}: bus {status['bus']} of {document['plant_file']} is not a line of {fleet} — "
                                f"give the status of the fleet's lines")  # fmt: skip
            if line in found:
                raise UserError(f"{path}: line {line.name} is in {first[line]} too — give each line's status once")
            found[line], first[line] = lines_of.LineStatus(status, waiting), path
    document = lines_of.summary(everything, found)
    if json_out:
        print_document(document)
    else:
        print(lines_of.markdown(document), end="")


def _lines(fleet: Path) -> list[Any]:
    from prc3cfg.plant.fleet import lines
    from prc3cfg.shell.plant_files import load_fleet, load_plant

    return lines(load_fleet(fleet), load_plant)


def _status(path: Path) -> dict[str, Any]:
    """A `prc3cfg-status/1` document, or one line saying what the file is not."""
    from prc3cfg.core.status import FORMAT
    from prc3cfg.shell.files import FileProblem, read_json

    try:
        document = read_json(path, STATUS_LIMIT)
    except FileProblem as problem:
        raise UserError(f"{path}: {problem} — give what prc3cfg status PLANT --json printed") from None
    if not isinstance(document, dict) or document.get("format") != FORMAT or not isinstance(document.get("lines"), list):
        raise UserError(f"{path}: not a {FORMAT} document — give what prc3cfg status PLANT --json printed")
    return document


def _waiting(path: Path) -> str | None:
    from prc3cfg.core.text import shown
    from prc3cfg.shell.files import FileProblem, Why, read_regular

    try:
        text = read_regular(path, STATUS_LIMIT).decode("utf-8", "replace")
    except FileProblem as problem:
        if problem.why is Why.MISSING:
            return None
        raise UserError(f"{path}: {problem} — it holds the words of an apply a window refused") from None
    return shown(" ".join(text.split())) or "a window refused the apply"


def _line_of(lines: list[Any], plant_file: str, bus: str) -> Any:
    """The fleet's line of `bus` of the plant file a status document names (as the command that made it was given it:
    the line's path, relative to the repository, ends it)."""
    parts = posixpath.normpath(plant_file.replace("\\", "/")).split("/")
    return next((line for line in lines if line.bus == bus and parts[-len(line.plant.split("/")) :] == line.plant.split("/")), None)
