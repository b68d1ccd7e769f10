"""The runs beside a plant file, as `prc3cfg records list` and `prc3cfg records prune` see them.

- `runs`: each run — a journal, or a snapshot without one — ordered by the time in its file's name
  (`prc3cfg.shell.audit.stamped`: chosen before anything is written), never by what its header
  says; what its records say, and whatever keeps them from verifying (`findings`).
- `prune`: runs removed whole, journal and snapshot together, on evidence only. While any record in
  the plant's records folder — of any plant file there — does not verify (`prc3cfg.shell.audit.check`)
  it names each and removes nothing: a record that does not verify may name what is not its run's.
  Then never the newest snapshot of a line, never the plant's newest run, never a file of another
  plant file, never the run an axis release nobody was told of names (`prc3cfg.shell.pending_records`; the
  caller says which journals those are).

Does not own checking the records (`prc3cfg.shell.audit`), nor writing them, nor what is printed.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from prc3cfg.errors import UserError
from prc3cfg.shell.audit import (
    EVIDENCE,
    Checked,
    check,
    check_journal,
    file_name,
    journal_problems,
    journals,
    of_plant,
    stamped,
)
from prc3cfg.shell.records import STAMP_LENGTH, Snapshot, records_dir

#: The most `--older-than` takes, in days: a hundred years, older than any record.
MOST_DAYS = 36525


@dataclass(frozen=True)
class RecordedRun:
    """One apply, restore or adopt as its records tell it. `time` is the one in its file's name (when
    prc3cfg chose it: "" when the name has none) — what orders runs; `findings`, whatever else keeps
    its records from verifying where the chain is intact (a header time that disagrees with the name
    among them). The other fields are what the records say, text or None."""

    time: str
    command: str | None
    user: str | None
    host: str | None
    plant: str | None
    lines: tuple[str, ...]
    result: str
    reason: str | None
    journal: Path | None
    snapshot: Path | None
    chain: str  # "intact", "broken at FILE:LINE", "unchained" (before headers)
    findings: tuple[str, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return {"time": self.time, "command": self.command, "user": self.user, "host": self.host,
                "plant": self.plant,
                "lines": list(self.lines), "result": self.result, "reason": self.reason,
                "journal": None if self.journal is None else str(self.journal),
                "snapshot": None if self.snapshot is None else str(self.snapshot), "chain": self.chain,
                "findings": list(self.findings)}


def _text(value: Any) -> str | None:
    """A field of a record as text: what a record says may be anything JSON holds."""
    return None if value is None else value if isinstance(value, str) else json.dumps(value)


def _result(records: list[dict[str, Any]]) -> str:
    """What became of a run, from its records."""
    events = [r.get("event") for r in records]
    results = [r for r in records if r.get("event") == "result"]
    if "adopt" in events:
        adopted = [r for r in records if r.get("event") == "adopted"]
        return "unfinished" if not adopted else "adopted" if adopted[-1].get("written") else "not adopted"
    if "interrupted" in events:
        return "interrupted"
    if results:
        return "verified" if all(r.get("verified") for r in results) else "failed"
    if refused := [r for r in records if r.get("event") == "refused"]:
        return f"refused, nothing written: {_text(refused[-1].get('why'))}"
    return "unfinished" if "snapshot" in events or "apply" in events else "nothing written"


def runs(plant_path: Path) -> list[RecordedRun]:
    """Every run beside the plant file, oldest first by the times in the files' names (runs whose
    name has none last): each journal, and each snapshot without one."""
    snapshots_dir = records_dir(plant_path, "snapshots")
    found = [_journal_run(path, snapshots_dir) for path in journals(plant_path)]
    named = {run.snapshot.name for run in found if run.snapshot is not None}
    found += [_snapshot_run(path) for path in of_plant(snapshots_dir, plant_path.stem, ".json")
              if path.name not in named]
    return sorted(found, key=lambda run: (not run.time, run.time))


def _named_time(path: Path) -> str:
    """The time in a record file's name, as `RecordedRun.time` says it; "" when it has none."""
    named = stamped(path)
    return "" if named is None else named.isoformat(timespec="microseconds")


def _journal_run(path: Path, snapshots_dir: Path) -> RecordedRun:
    """A run as its journal tells it (one before headers: what its records say)."""
    checked = check_journal(path)
    records, header = checked.records, checked.header or {}
    named = _snapshot_named(checked)
    snapshot = None if named is None else snapshots_dir / named
    plant = header.get("plant")
    name = plant.get("name") if isinstance(plant, dict) else next((r.get("plant") for r in records
                                                                   if r.get("event") == "apply"), None)
    chain = "intact" if checked.chained else "unchained"
    if checked.problem is not None:
        chain = f"broken at {checked.problem.where}"
    findings = tuple(problem.said() for problem in journal_problems(path, checked, [])[0]
                     if problem is not checked.problem)
    return RecordedRun(_named_time(path), _text(header.get("command")) or ("apply" if records else None),
                       _text(header.get("user")),
                       _text(header.get("host")), _text(name), _buses(records), _result(records),
                       _text(header.get("reason")), path,
                       snapshot, chain, findings)


def _snapshot_named(checked: Checked) -> str | None:
    """The file name of the snapshot a journal records last."""
    if (record := checked.snapshot_record()) is not None:
        return file_name(record[1].get("path"))
    if applied := [r for r in checked.records if r.get("event") == "apply"
                   and isinstance(r.get("snapshot"), str)]:
        # before headers: the apply record named it by its path
        return file_name(Path(applied[-1]["snapshot"]).name)
    return None


def _buses(records: list[dict[str, Any]]) -> tuple[str, ...]:
    """The buses a run spoke on, from its records: its exchanges', and an adopt's."""
    buses = {str(r["bus"]) for r in records if r.get("event") in ("request", "exchange") and "bus" in r}
    buses |= {str(bus) for r in records if r.get("event") == "adopt" and isinstance(r.get("buses"), list)
              for bus in r["buses"]}
    return tuple(sorted(buses))


def _snapshot_run(path: Path) -> RecordedRun:
    """A run of which only the snapshot is left (written before journals named it)."""
    try:
        lines: tuple[str, ...] = tuple(sorted({bus for bus, _ in Snapshot.load(path).images}))
    except UserError:
        lines = ()
    return RecordedRun(_named_time(path), None, None, None, None, lines, "unknown (no journal)", None, None,
                       path, "unchained")


@dataclass(frozen=True)
class Pruned:
    """What `prune` removed, and what it kept although asked to remove it, with why."""

    removed: tuple[RecordedRun, ...]
    kept: tuple[tuple[RecordedRun, str], ...]


def older_than(days: float) -> timedelta:
    """`--older-than DAYS` as a time: `ValueError`, saying what to give, unless a number of days from 0 to
    `MOST_DAYS`."""
    if not 0 <= days <= MOST_DAYS:  # nan too
        raise ValueError(f"{days:g} is not a number of days from 0 to {MOST_DAYS} (a hundred years)")
    return timedelta(days=days)


def prune(plant_path: Path, *, keep: int | None, older_than_days: float | None,
          protected: Iterable[Path] = (),
          dry_run: bool = False, now: datetime | None = None) -> Pruned:
    """Remove whole runs — journal and snapshot — beyond the newest `keep` and older than
    `older_than_days` (each only when given, both when both are), by the times in their files'
    names. Nothing while any record beside the plant file — of any plant file there — does not
    verify (`check`): `UserError` naming each. Then never the newest snapshot of a line, never a run
    whose journal is in `protected` (an axis release nobody was told of names it), never the plant's
    newest run (the next one follows it), never a file of another plant file. The caller holds the
    plant's lines: no run of them is being written meanwhile."""
    try:
        cut = None if older_than_days is None else (now or datetime.now(UTC)) - older_than(older_than_days)
    except ValueError as error:
        raise UserError(f"--older-than {error}") from None
    if keep is not None and keep < 0:
        raise UserError(f"--keep {keep} is not a number of runs: give 0 or more")
    every = runs(plant_path)
    if not every:
        return Pruned((), ())
    _all_verify(plant_path)
    ordered = [run for run in every if run.time]
    beyond = ordered[: max(len(ordered) - keep, 0)] if keep is not None else ordered
    candidates = [run for run in beyond if cut is None or datetime.fromisoformat(run.time) < cut]
    why = _kept(ordered, protected, plant_path.stem)
    removed, kept = [], []
    for run in candidates:
        if run in why:
            kept.append((run, why[run]))
            continue
        if not dry_run:
            for path in (run.snapshot, run.journal):
                if path is not None:
                    path.unlink(missing_ok=True)
        removed.append(run)
    return Pruned(tuple(removed), tuple(kept))


def _all_verify(plant_path: Path) -> None:
    """`UserError` naming each record in the plant's records folder — of any plant file there — that
    does not verify: it may name what is not its run's, so prune removes nothing."""
    folder = records_dir(plant_path, "journal").parent
    if problems := check([folder]).problems:
        raise UserError("\n".join([
            f"{plant_path}: nothing was removed — {len(problems)} record{'s' if len(problems) != 1 else ''} "
            f"in {folder} do"
            f"{'es' if len(problems) == 1 else ''} not verify, and prune acts only on records that do: "
            f"{EVIDENCE}; then move each "
            f"(and what it names) out of {folder} and "
            "prune again", *(problem.said() for problem in problems)]))


def _kept(every: list[RecordedRun], protected: Iterable[Path], stem: str) -> dict[RecordedRun, str]:
    """Why each run that prune must keep is kept (`every`: oldest first): the newest snapshot of a
    line — among runs whose records verify, and among all, so that a snapshot without a journal
    (before headers: its lines are its own word) may keep itself but never take that from a checked
    one —, the plant's newest run, a run an axis release nobody was told of names, a run that names
    a snapshot of another plant file (a journal before headers: nothing checked that)."""
    # by name: a record may name the journal by a path relative to another folder
    guarded = {p.name for p in protected}
    newest: dict[tuple[bool, str], tuple[RecordedRun, str]] = {}
    for run in every:
        for identity, said in _lines(run).items():
            # `every` is oldest first: the last one seen is the newest
            newest[(False, identity)] = (run, said)
            if run.chain == "intact":
                newest[(True, identity)] = (run, said)
    lines: dict[RecordedRun, list[str]] = {}
    for run, said in newest.values():
        if said not in lines.setdefault(run, []):
            lines[run].append(said)
    why = {run: "the newest snapshot of " + " and of ".join(said) for run, said in lines.items()}
    if newest_run := [run for run in every if run.journal is not None][-1:]:
        why.setdefault(newest_run[0], "the plant's newest run: the next run's journal follows it")
    for run in every:
        if run.snapshot is not None and run.snapshot.name[STAMP_LENGTH:] != f"-{stem}.json":
            why[run] = (f"its journal names {run.snapshot.name}, a snapshot of another plant file: prune "
                        "removes only this plant file's")
        if run.journal is not None and run.journal.name in guarded:
            why[run] = ("an axis release nobody was told of names this run (prc3cfg.shell.pending_records): "
                        "kept until an apply's account names it")
    return why


def _lines(run: RecordedRun) -> dict[str, str]:
    """The lines whose modules a run's snapshot holds: each of a line's identities (`LineTaken.keys`:
    a line named by another bus name since is still that line), with the line in words."""
    if run.snapshot is None or not run.snapshot.exists():
        return {}
    try:
        snapshot = Snapshot.load(run.snapshot)
    except UserError:
        return {f"unreadable {run.snapshot.name}": f"a snapshot prc3cfg cannot read ({run.snapshot.name})"}
    found: dict[str, str] = {}
    for bus in sorted({bus for bus, _ in snapshot.images}):
        line = snapshot.lines.get(bus)
        said = f"bus {bus}'s line" + (f" ({line.port})" if line is not None else "")
        found |= {key: said for key in line.keys} if line is not None and line.keys else {f"bus {bus}": said}
    return found
