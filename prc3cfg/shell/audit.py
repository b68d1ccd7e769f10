"""The records beside a plant file as an auditor reads them: checked, listed, pruned.

A run — an apply, a restore, an adopt — leaves a journal (`.prc3cfg/journal/`) and, once it
writes a module, a snapshot (`.prc3cfg/snapshots/`): `prc3cfg.shell.records` writes them. This
module reads them back:

- `check_journal`: the hash chain of one journal — a header first, each later record's `prev` the
  SHA-256 of the line before — and the first record that does not match, as `file:line`. The last
  line of a journal has no record after it: it is covered by the next run's link to it
  (`previous` in that run's header), by nothing before that.
- `check` (`prc3cfg records verify`): journals, their snapshots (each as the last `snapshot`
  record of its journal says it was written), and each journal's link to the one before it.
- `follow`: before a run writes, the plant's newest journal checked — a run does not begin a
  record that follows one that does not verify — and the link to it, for the new header.
- `snapshot_checked`: before a restore writes, its snapshot and its journal checked.
- `runs` (`prc3cfg records list`) and `prune` (`prc3cfg records prune`): each run in a line, and
  runs removed whole, journal and snapshot together — never the newest snapshot of a line, never
  the run an axis release nobody was told of names (`prc3cfg.shell.releases`; the caller says
  which journals those are).

Journals written before records had headers (prc3cfg 0.1.0) are "unchained": listed, never
refused, and said as not checked. Does not own writing the records, nor what is printed.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from prc3cfg.errors import UserError
from prc3cfg.shell.files import FileProblem, Why, read_regular
from prc3cfg.shell.records import STAMP_LENGTH, Snapshot, line_hash, records_dir

#: The largest journal read: 30 modules × 8 buses, every program written and verified, is a few MB.
JOURNAL_LIMIT = 1024 * 2**20
#: What to do about a record that does not verify.
EVIDENCE = "keep the file as it is for whoever investigates, and compare it with your backup copy (docs/security.md)"
#: What to do about a path that names no records.
NAME_ONE = "name a plant file, a .prc3cfg folder, a journal (.jsonl) or a snapshot (.json)"


@dataclass(frozen=True)
class Mismatch:
    """A record that does not verify: where (`file:line`, or the file) and what is wrong."""

    where: str
    what: str
    remedy: str = EVIDENCE

    def said(self) -> str:
        return f"{self.where}: {self.what}"


@dataclass(frozen=True)
class Checked:
    """One journal read and its chain checked: its records, the first `problem`, whether it is
    chained at all (journals before headers are not), and the hash of its last complete line."""

    path: Path
    records: list[dict[str, Any]]
    chained: bool
    problem: Mismatch | None
    last: str | None = None
    cut: bool = False  # a last line without its end of line, left out

    @property
    def header(self) -> dict[str, Any] | None:
        return self.records[0] if self.chained and self.records else None

    def snapshot_record(self, name: str | None = None) -> tuple[int, dict[str, Any]] | None:
        """The last `snapshot` record (naming `name`), with its line number."""
        found = [(n, r) for n, r in enumerate(self.records, 1) if r.get("event") == "snapshot" and (name is None or r.get("path") == name)]
        return found[-1] if found else None


def file_name(value: Any) -> str | None:
    """`value` when a record names a file beside it by it — a bare name, no folder, not `..` — else
    None: a record is data anyone may have edited, and prune removes what records name."""
    if not isinstance(value, str) or value in ("", ".", "..") or "/" in value or "\\" in value or "\0" in value:
        return None
    return value


def check_journal(path: Path) -> Checked:
    """The chain of the journal at `path`. A last line without its end of line is left out and said
    (`cut`): a run the disk refused midway (full), or killed as it wrote, leaves one — and so does
    another run still writing it — and the records before it are whole."""
    try:
        data = read_regular(path, JOURNAL_LIMIT)
    except FileProblem as problem:
        return Checked(path, [], False, Mismatch(str(path), str(problem), NAME_ONE if problem.why is Why.MISSING else EVIDENCE))
    lines = data.split(b"\n")
    cut = bool(lines.pop())  # what follows the last newline: nothing, in a whole journal
    if not lines:
        said = "cut short before its header was whole" if cut else "empty: a journal begins with its header"
        return Checked(path, [], False, Mismatch(str(path), said))
    records: list[dict[str, Any]] = []
    for number, line in enumerate(lines, 1):
        try:
            record = json.loads(line)
        except ValueError:
            record = None
        if not isinstance(record, dict):
            return Checked(path, records, True, Mismatch(f"{path}:{number}", "not a JSON record as prc3cfg writes it"))
        records.append(record)
    if records[0].get("event") != "header":
        if not any("prev" in record for record in records):
            return Checked(path, records, False, None, line_hash(lines[-1]), cut)  # before headers
        return Checked(path, records, True, Mismatch(f"{path}:1", "no header: a journal begins with who, where, what and why"))
    if records[0].get("prev") is not None:
        return Checked(path, records, True, Mismatch(f"{path}:1", "a header that follows another record"))
    for number in range(1, len(lines)):
        if records[number].get("prev") != line_hash(lines[number - 1]):
            return Checked(path, records, True, Mismatch(
                f"{path}:{number}", f"not the record the next one (line {number + 1}) was written after — this one edited, "
                "or records removed or inserted here"))  # fmt: skip
    return Checked(path, records, True, None, line_hash(lines[-1]), cut)


def journals(plant_path: Path) -> list[Path]:
    """The plant file's journals, oldest first (by the time in their names)."""
    return _of_plant(records_dir(plant_path, "journal"), plant_path.stem, ".jsonl")


def _of_plant(folder: Path, stem: str, suffix: str) -> list[Path]:
    try:
        found = [p for p in folder.iterdir() if p.suffix == suffix]
    except OSError:
        return []
    return sorted(p for p in found if p.name[STAMP_LENGTH:] == f"-{stem}{suffix}")


def follow(plant_path: Path) -> dict[str, Any] | None:
    """What a new run's header links to — the plant's newest journal: its name, lines and last
    line's hash — once it verifies; `UserError` (nothing written yet) when it does not."""
    found = journals(plant_path)
    if not found:
        return None
    checked = check_journal(found[-1])
    if checked.problem is not None:
        raise UserError(f"{checked.problem.said()} — the plant's newest journal does not verify, and this run's journal "
                        f"would follow it: nothing was written; {EVIDENCE}, then move it (and its snapshot) out of "
                        f"{found[-1].parent} and run again")  # fmt: skip
    return {"journal": found[-1].name, "lines": len(checked.records), "sha256": checked.last}


def snapshot_checked(path: Path, snapshot: Snapshot) -> str | None:
    """A snapshot about to be restored, checked against its journal: `UserError` when either does
    not verify; a note when it was written before records had headers (it cannot be checked)."""
    if snapshot.header is None:
        for beside in _of_plant(path.resolve().parent.parent / "journal", snapshot.plant_path.stem, ".jsonl"):
            with contextlib.suppress(FileProblem):
                if f'"event": "snapshot", "path": {json.dumps(path.name)}'.encode() in read_regular(beside, JOURNAL_LIMIT):
                    raise UserError(f"{path}: has no header, but {beside} records it as written with one — edited since; "
                                    f"nothing was written; {EVIDENCE}")  # fmt: skip
        return f"{path}: written before records had headers — its integrity cannot be checked"
    name = file_name(snapshot.header.get("journal"))
    if name is None:
        raise UserError(f"{path}: its header names no journal file — the snapshot cannot be checked, nothing was written; {EVIDENCE}")
    candidates = [path.resolve().parent.parent / "journal" / name, records_dir(snapshot.plant_path, "journal") / name]
    journal = next((c for c in candidates if c.is_file()), None)
    if journal is None:
        raise UserError(f"{path}: its journal {name} is in neither {candidates[0].parent} nor {candidates[1].parent} — the "
                        "snapshot cannot be checked, nothing was written: put the journal back from your backup")  # fmt: skip
    problem = _snapshot_problem(check_journal(journal), path)
    if problem is not None:
        raise UserError(f"{problem.said()} — nothing was written; {EVIDENCE}")
    return None


def _snapshot_problem(checked: Checked, snapshot: Path) -> Mismatch | None:
    """Whatever keeps `snapshot` from being the one its journal recorded last."""
    if checked.problem is not None:
        return checked.problem
    found = checked.snapshot_record(snapshot.name)
    if found is None:
        return Mismatch(str(snapshot), f"not recorded in its journal {checked.path}")
    line, record = found
    try:
        written = line_hash(read_regular(snapshot, JOURNAL_LIMIT))
    except FileProblem as problem:
        return Mismatch(str(snapshot), str(problem))
    if written != record.get("sha256"):
        return Mismatch(str(snapshot), f"does not match its SHA-256 in {checked.path}:{line} — edited or replaced since it was written")
    return None


@dataclass
class Verified:
    """What `check` found: problems, one line each (the first of each file), and how many files it checked."""

    problems: list[Mismatch] = field(default_factory=list)
    journals: int = 0
    snapshots: int = 0
    unchained: int = 0
    notes: list[str] = field(default_factory=list)

    def said(self) -> list[str]:
        """Each problem in one line, with what to do."""
        return [f"{problem.said()} — {problem.remedy}" for problem in self.problems]

    def summary(self) -> str:
        """What was checked, in one line."""
        unchained = f"; {self.unchained} written before records had headers: not checked" if self.unchained else ""
        journals = f"{self.journals} journal{'s' if self.journals != 1 else ''}"
        return f"{journals} and {self.snapshots} snapshot{'s' if self.snapshots != 1 else ''} checked{unchained}"


def check(paths: Iterable[Path]) -> Verified:
    """Every record under `paths` checked: a plant file (its records), a records folder, journals, snapshots."""
    result = Verified()
    wanted_journals, wanted_snapshots = _wanted(paths, result)
    checked: dict[Path, Checked] = {}
    done: set[Path] = set()  # snapshots checked with their journal
    for path in wanted_journals:
        checked[path.resolve()] = _check_chained(path, result, done)
    for path in wanted_snapshots:
        if path.resolve() not in done:
            _check_alone(path, result, checked)
    if not wanted_journals and not wanted_snapshots and not result.problems:
        result.problems.extend(Mismatch(str(p), "no records there", "an apply, restore or adopt keeps them in .prc3cfg/ beside the plant file")
                               for p in paths)  # fmt: skip
    return result


def _wanted(paths: Iterable[Path], result: Verified) -> tuple[dict[Path, None], dict[Path, None]]:
    """The journals and the snapshots `paths` name, each once, in order; a problem for a path that names no records."""
    wanted_journals: dict[Path, None] = {}
    wanted_snapshots: dict[Path, None] = {}
    for path in paths:
        folder = _records_folder(path)
        if path.suffix.lower() in (".yaml", ".yml") and not path.is_dir():  # a plant file: its own records
            wanted_journals.update(dict.fromkeys(journals(path)))
            wanted_snapshots.update(dict.fromkeys(_of_plant(records_dir(path, "snapshots"), path.stem, ".json")))
        elif folder is not None:
            for kind, into, suffix in (("journal", wanted_journals, ".jsonl"), ("snapshots", wanted_snapshots, ".json")):
                with contextlib.suppress(OSError):
                    into.update(dict.fromkeys(sorted(p for p in (folder / kind).iterdir() if p.suffix == suffix)))
        elif path.suffix == ".jsonl":
            wanted_journals[path] = None
        elif path.suffix == ".json":
            wanted_snapshots[path] = None
        else:
            result.problems.append(Mismatch(str(path), "not a plant file, records folder, journal (.jsonl) or snapshot (.json)", NAME_ONE))
    return wanted_journals, wanted_snapshots


def _check_chained(path: Path, result: Verified, done: set[Path]) -> Checked:
    """A journal checked into `result`: its chain, its link to the run before and the snapshot it
    records last (added to `done`, so that it is not checked again on its own)."""
    journal = check_journal(path)
    result.journals += 1
    if journal.problem is not None:
        result.problems.append(journal.problem)
        return journal
    if journal.cut:
        result.notes.append(f"{path}:{len(journal.records) + 1}: its last record was cut short — the disk refused it, or the "
                            "run was killed as it wrote it — and is left out")  # fmt: skip
    if not journal.chained:
        result.unchained += 1
        return journal
    header = journal.header or {}
    if (problem := _link_problem(path, header.get("previous"), result.notes)) is not None:
        result.problems.append(problem)
    if (found := journal.snapshot_record()) is None:
        return journal
    if (name := file_name(found[1].get("path"))) is None:
        result.problems.append(Mismatch(f"{path}:{found[0]}", "names no snapshot file (a path, not a name in snapshots/)"))
        return journal
    snapshot = path.resolve().parent.parent / "snapshots" / name
    done.add(snapshot)
    result.snapshots += 1
    if not snapshot.exists():
        result.problems.append(Mismatch(f"{path}:{found[0]}", f"names the snapshot {snapshot}, which is not there — "
                                       "removed by hand (prune removes a run's journal and snapshot together)"))  # fmt: skip
    elif (problem := _snapshot_problem(journal, snapshot)) is not None:
        result.problems.append(problem)
    return journal


def _check_alone(path: Path, result: Verified, checked: dict[Path, Checked]) -> None:
    """A snapshot no journal given recorded, checked into `result` against the journal its header
    names (from `checked`, when that journal was given too: its problem is said there already)."""
    result.snapshots += 1
    try:
        taken = Snapshot.load(path)
    except UserError as error:
        result.problems.append(Mismatch(str(path), str(error).partition(": ")[2] or str(error)))
        return
    if taken.header is None:
        result.unchained += 1
        return
    if (name := file_name(taken.header.get("journal"))) is None:
        result.problems.append(Mismatch(str(path), "its header names no journal file"))
        return
    journal_path = path.resolve().parent.parent / "journal" / name
    if not journal_path.is_file():
        result.problems.append(Mismatch(str(path), f"its journal {journal_path} is not there"))
        return
    journal = checked.get(journal_path) or check_journal(journal_path)
    if journal.problem is None and (problem := _snapshot_problem(journal, path)) is not None:
        result.problems.append(problem)
    elif journal.problem is not None and journal_path not in checked:
        result.problems.append(journal.problem)


def _records_folder(path: Path) -> Path | None:
    """The `.prc3cfg` folder `path` names: itself, its journal/ or snapshots/, or the one in it."""
    if not path.is_dir():
        return None
    if path.name in ("journal", "snapshots"):
        return path.parent
    return path / ".prc3cfg" if (path / ".prc3cfg").is_dir() and not (path / "journal").is_dir() else path


def _link_problem(path: Path, previous: Any, notes: list[str]) -> Mismatch | None:
    """A journal's link to the plant's journal before it: that one's line as it was when this run began."""
    if not isinstance(previous, dict):
        return None
    if (name := file_name(previous.get("journal"))) is None:
        return Mismatch(f"{path}:1", "its link to the run before names no journal file")
    before = path.resolve().parent / name
    if not before.is_file():
        notes.append(f"{path}:1: follows {before.name}, which is not there (pruned, or removed)")
        return None
    lines = before.read_bytes().split(b"\n")
    count = previous.get("lines")
    if not isinstance(count, int) or not 0 < count <= len(lines) or line_hash(lines[count - 1]) != previous.get("sha256"):
        return Mismatch(f"{before}:{count}", f"not the record {path}:1 follows — edited since that run began")
    return None


# -- listing and pruning ------------------------------------------------------------------------


@dataclass(frozen=True)
class RecordedRun:
    """One apply, restore or adopt as its records tell it."""

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

    def to_json(self) -> dict[str, Any]:
        return {"time": self.time, "command": self.command, "user": self.user, "host": self.host, "plant": self.plant,
                "lines": list(self.lines), "result": self.result, "reason": self.reason,
                "journal": None if self.journal is None else str(self.journal),
                "snapshot": None if self.snapshot is None else str(self.snapshot), "chain": self.chain}  # fmt: skip


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
    return "unfinished" if "snapshot" in events or "apply" in events else "nothing written"


def runs(plant_path: Path) -> list[RecordedRun]:
    """Every run beside the plant file, oldest first: each journal, and each snapshot without one."""
    snapshots_dir = records_dir(plant_path, "snapshots")
    found = [_journal_run(path, snapshots_dir) for path in journals(plant_path)]
    named = {run.snapshot.name for run in found if run.snapshot is not None}
    found += [_snapshot_run(path) for path in _of_plant(snapshots_dir, plant_path.stem, ".json") if path.name not in named]
    return sorted(found, key=lambda run: run.time)


def _journal_run(path: Path, snapshots_dir: Path) -> RecordedRun:
    """A run as its journal tells it (one before headers: what its records say)."""
    checked = check_journal(path)
    records, header = checked.records, checked.header or {}
    named = _snapshot_named(checked)
    snapshot = None if named is None else snapshots_dir / named
    plant = header.get("plant")
    name = plant.get("name") if isinstance(plant, dict) else next((r.get("plant") for r in records if r.get("event") == "apply"), None)
    chain = "intact" if checked.chained else "unchained"
    if checked.problem is not None:
        chain = f"broken at {checked.problem.where}"
    return RecordedRun(str(records[0].get("time", "")) if records else "", header.get("command") or ("apply" if records else None),
               header.get("user"), header.get("host"), name, _buses(records), _result(records), header.get("reason"), path,
               snapshot, chain)  # fmt: skip


def _snapshot_named(checked: Checked) -> str | None:
    """The file name of the snapshot a journal records last."""
    if (record := checked.snapshot_record()) is not None:
        return file_name(record[1].get("path"))
    if applied := [r for r in checked.records if r.get("event") == "apply" and isinstance(r.get("snapshot"), str)]:
        return file_name(Path(applied[-1]["snapshot"]).name)  # before headers: the apply record named it by its path
    return None


def _buses(records: list[dict[str, Any]]) -> tuple[str, ...]:
    """The buses a run spoke on, from its records: its exchanges', and an adopt's."""
    buses = {str(r["bus"]) for r in records if r.get("event") in ("request", "exchange") and "bus" in r}
    buses |= {str(bus) for r in records if r.get("event") == "adopt" for bus in r.get("buses") or ()}
    return tuple(sorted(buses))


def _snapshot_run(path: Path) -> RecordedRun:
    """A run of which only the snapshot is left (written before journals named it)."""
    try:
        snapshot = Snapshot.load(path)
        taken = datetime.strptime(snapshot.taken, "%Y%m%dT%H%M%S.%fZ").replace(tzinfo=UTC).isoformat()
        lines: tuple[str, ...] = tuple(sorted({bus for bus, _ in snapshot.images}))
    except (UserError, ValueError):
        taken, lines = "", ()
    return RecordedRun(taken, None, None, None, None, lines, "unknown (no journal)", None, None, path, "unchained")


@dataclass(frozen=True)
class Pruned:
    """What `prune` removed, and what it kept although asked to remove it, with why."""

    removed: tuple[RecordedRun, ...]
    kept: tuple[tuple[RecordedRun, str], ...]


def prune(plant_path: Path, *, keep: int | None, older_than_days: float | None, protected: Iterable[Path] = (),
          dry_run: bool = False, now: datetime | None = None) -> Pruned:  # fmt: skip
    """Remove whole runs — journal and snapshot — beyond the newest `keep` and older than
    `older_than_days` (each only when given, both when both are): never the newest snapshot of a
    line, never a run whose journal is in `protected` (an axis release nobody was told of names it),
    never the plant's newest run (the next one follows it). The caller holds the plant's lines: no
    run of them is being written meanwhile."""
    every = runs(plant_path)
    now = now or datetime.now(UTC)
    cut = None if older_than_days is None else now - timedelta(days=older_than_days)
    beyond = set(range(len(every) - keep)) if keep is not None else set(range(len(every)))
    candidates = [i for i in sorted(beyond) if cut is None or (every[i].time and datetime.fromisoformat(every[i].time) < cut)]
    why = _kept(every, protected)
    removed, kept = [], []
    for index in candidates:
        run = every[index]
        if index in why:
            kept.append((run, why[index]))
            continue
        if not dry_run:
            for path in (run.snapshot, run.journal):
                if path is not None:
                    path.unlink(missing_ok=True)
        removed.append(run)
    return Pruned(tuple(removed), tuple(kept))


def _kept(every: list[RecordedRun], protected: Iterable[Path]) -> dict[int, str]:
    """Why each run that prune must keep is kept, by its index in `every` (oldest first): the newest
    snapshot of a line, the plant's newest run, a run an axis release nobody was told of names."""
    guarded = {p.name for p in protected}  # by name: a record may name the journal by a path relative to another folder
    newest: dict[str, tuple[int, str]] = {}
    for index, run in enumerate(every):
        for identity, said in _lines(run).items():
            newest[identity] = (index, said)  # `every` is oldest first: the last one seen is the newest
    lines: dict[int, list[str]] = {}
    for index, said in newest.values():
        if said not in lines.setdefault(index, []):
            lines[index].append(said)
    why = {index: "the newest snapshot of " + " and of ".join(said) for index, said in lines.items()}
    if every and every[-1].journal is not None:
        why.setdefault(len(every) - 1, "the plant's newest run: the next run's journal follows it")
    for index, run in enumerate(every):
        if run.journal is not None and run.journal.name in guarded:
            why[index] = "an axis release nobody was told of names this run (prc3cfg.shell.releases): kept until an apply's account names it"
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
