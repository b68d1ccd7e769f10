"""`prc3cfg fleet matrix FLEET [--changed FILE…]` and `prc3cfg fleet summary FLEET STATUS_JSON…`
(docs/fleet.md).

- `matrix`: the GitHub Actions matrix of the fleet's lines, one compact JSON line (`$GITHUB_OUTPUT` takes it):
  every line, or with `--changed` only those the changed files touch (paths relative to the current folder, as
  `git diff --name-only` gives them from the repository's top).
- `summary`: `prc3cfg status PLANT --json` documents of the lines (each line in at most one) gathered into one
  markdown table for the pull request, or `--json` (`prc3cfg-fleet-summary/1`). A `waiting.txt` beside a
  status document holds the words of an apply a window refused on its lines (the fleet workflow writes it).

Arguments and output only: what is selected and summarised is `prc3cfg.api`'s (`fleet_matrix`,
`fleet_summary`).
"""

from pathlib import Path
from typing import Annotated

import typer

from prc3cfg.cli import app
from prc3cfg.errors import UserError

fleet_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None,
                        help="Lines as a fleet: the CI matrix and the pull request's summary.")
app.add_typer(fleet_app, name="fleet")

FleetArg = Annotated[Path, typer.Argument(metavar="FLEET", help="The fleet file (YAML, prc3cfg-fleet/1).",
                                          show_default=False)]


@fleet_app.command()
def matrix(
    fleet: FleetArg,
    files: Annotated[
        list[str] | None, typer.Argument(metavar="FILE...",
                                         help="With --changed: the files the change touches.",
                                         show_default=False)
    ] = None,
    changed: Annotated[bool, typer.Option("--changed",
                                          help="Only the lines whose plant file or policy file is "
                                               "among FILEs.")] = False,
) -> None:
    """Print the GitHub Actions matrix of the fleet's lines (one entry per line: plant, bus, runner, group,
    …)."""
    import json

    from prc3cfg import api

    if files and not changed:
        raise UserError(f"prc3cfg fleet matrix: {files[0]} — give --changed before the changed files")
    print(json.dumps(api.fleet_matrix(fleet, (files or []) if changed else None), separators=(",", ":")))


@fleet_app.command()
def summary(
    fleet: FleetArg,
    statuses: Annotated[list[Path],
                        typer.Argument(metavar="STATUS_JSON...",
                                       help="`prc3cfg status PLANT --json` documents.", show_default=False)],
    json_out: Annotated[bool, typer.Option("--json", help="Print a prc3cfg-fleet-summary/1 "
                                                          "document.")] = False,
) -> None:
    """Gather the lines' status into one table for the pull request: modules, health, drift, travel, last
    verified."""
    from prc3cfg import api
    from prc3cfg.cli.common import print_document
    from prc3cfg.core.fleet import markdown

    document = api.fleet_summary(fleet, statuses)
    if json_out:
        print_document(document)
    else:
        print(markdown(document), end="")
