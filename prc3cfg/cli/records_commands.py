"""`prc3cfg records verify`, `list` and `prune`: the journals and snapshots beside a plant file.

- `verify PATH…`: plant files (their records), records folders, journals, snapshots — each file's
  first record that does not match, one `error: file:line: …` line each, exit 1; else what was
  checked, exit 0 (`prc3cfg.api.verify_records`).
- `list PLANT [--json]`: every apply, restore and adopt — time, command, who, plant, lines,
  result, snapshot, reason, findings — oldest first; a plant file without any: so said, exit 0.
- `prune PLANT --keep N | --older-than DAYS [--dry-run] [--json]`: whole runs removed, and those
  kept although asked for, with why.

`list` and `prune` of a path that is no plant file and has no records beside it: one line saying
so, exit 1 — a typo lists nothing silently nowhere.

Arguments and output only: the work is `prc3cfg.api`'s.
"""

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from prc3cfg.cli import records_app
from prc3cfg.cli.common import PlantArg, print_document
from prc3cfg.errors import UserError

if TYPE_CHECKING:
    from prc3cfg.api import RecordedRun
    from prc3cfg.plant import Plant

JsonOpt = Annotated[bool, typer.Option("--json", help="Print it as JSON.")]
#: `records verify --json`'s document (`schemas/records-verify.schema.json`).
VERIFY_FORMAT = "prc3cfg-records-verify/1"


@records_app.command()
def verify(
    paths: Annotated[list[Path], typer.Argument(metavar="PATH...", help=(
        "Plant files (their records), .prc3cfg folders, journals (.jsonl) or snapshots (.json).", ),
                                                show_default=False)],
    json_out: Annotated[bool, typer.Option("--json", help=(
        f"Print a {VERIFY_FORMAT} document: what was checked, and each problem (exit 1 as "
        "without it)."))] = False,
) -> None:
    """Check the hash chain of journals and each snapshot against its journal: name the first record that does
    not match."""
    import sys

    from prc3cfg import api
    from prc3cfg.core.text import shown

    result = api.verify_records(paths)
    for note in result.notes:
        print(f"note: {shown(note)}", file=sys.stderr)
    if json_out:
        print_document({"format": VERIFY_FORMAT, "verified": not result.problems, "journals": result.journals,
                        "snapshots": result.snapshots,
                        "unchained": result.unchained, "problems": result.said(), "notes": result.notes,
                        "summary": result.summary()})
    if result.problems:
        raise UserError("\n".join(result.said()))
    if not json_out:
        print(f"Records verified: {result.summary()}.")


@records_app.command("list")
def list_(plant: PlantArg, json_out: JsonOpt = False) -> None:
    """Each apply, restore and adopt beside the plant file: time, who, plant, lines, result, snapshot."""
    from prc3cfg import api

    found = api.list_records(plant)
    if json_out:
        print_document([run.to_json() for run in found])
        return
    if not found:
        print(f"{plant}: no runs recorded yet (an apply, restore or adopt keeps them in "
              f"{plant.parent / '.prc3cfg'}).")
    for run in found:
        print(_line(run))


@records_app.command()
def prune(
    plant: PlantArg,
    keep: Annotated[int | None,
                    typer.Option("--keep", min=0, metavar="N", help="Keep the newest N runs.")] = None,
    older_than: Annotated[float | None,
                          typer.Option("--older-than", metavar="DAYS",
                                       help="Remove only runs older than this (by the times in their files' "
                                            "names).")] = None,
    dry_run: Annotated[bool, typer.Option("--dry-run", help="Say what would go; remove nothing.")] = False,
    json_out: JsonOpt = False,
) -> None:
    """Remove old runs, journal and snapshot together — nothing while a record beside the plant file does not
    verify; never the newest snapshot of a line, never a run an axis release nobody was told of names."""
    from prc3cfg import api

    done = api.prune_records(_plant_file(plant), keep=keep, older_than_days=older_than, dry_run=dry_run)
    if json_out:
        print_document({"removed": [run.to_json() for run in done.removed],
                        "kept": [run.to_json() | {"why": why} for run, why in done.kept]})
        return
    verb = "Would remove" if dry_run else "Removed"
    for run in done.removed:
        print(f"{verb}: {_line(run)}")
    for run, why in done.kept:
        print(f"Kept: {_line(run)} — {why}")
    print(f"{verb} {len(done.removed)} run{'s' if len(done.removed) != 1 else ''}; kept {len(done.kept)} of "
          "those old enough.")


def _plant_file(path: Path) -> "Plant":
    """The plant file at `path`; where it is none and no records are beside it (a typo, a folder,
    another file), `list_records`' one line saying so — records that outlive their plant file get
    the plant file's own error."""
    from prc3cfg import api

    try:
        return api.load(path)
    except UserError:
        api.list_records(path)
        raise


def _line(run: "RecordedRun") -> str:
    """A run in one line, everything from the files `shown`."""
    from prc3cfg.core.text import shown

    who = f"{run.user}@{run.host}" if run.user else "(who: not recorded)"
    parts = [run.time or "(no time)", run.command or "?", who, run.plant or "?", ", ".join(run.lines) or "-",
             run.result,
             f"snapshot {run.snapshot.name}" if run.snapshot is not None else "no snapshot"]
    if run.reason:
        parts.append(f"reason: {run.reason}")
    if run.chain != "intact":
        parts.append(f"chain {run.chain}")
    parts += [f"finding: {finding}" for finding in run.findings]
    return shown("  ".join(parts))
