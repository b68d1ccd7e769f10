"""The records beside a plant file as an auditor reads them: checked, and what keeps each from being evidence.

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
- `journal_problems`: whatever keeps a journal from being evidence — its chain, its header against
  its file name (`stamped`) and the record after it, its link to the run before (of the same plant
  file, earlier), the snapshot it names as its own (of the same plant file, the bytes recorded,
  its header naming this journal). `prc3cfg.shell.recorded_runs` lists and prunes runs on it.

Journals written before records had headers (prc3cfg 0.1.0) are "unchained": listed, never
refused, and said as not checked. Does not own writing the records, nor what is printed.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from prc3cfg.errors import UserError
from prc3cfg.shell.files import FileProblem, Why, read_regular
from prc3cfg.shell.platform import resolved
from prc3cfg.shell.records import STAMP_LENGTH, Snapshot, line_hash, records_dir

#: The largest journal read: 30 modules × 8 buses, every program written and verified, is a few MB.
JOURNAL_LIMIT = 1024 * 2**20
#: What to do about a record that does not verify.
EVIDENCE = ("keep the file as it is for whoever investigates, and compare it with your backup copy "
            "(docs/security.md)")
#: What to do about a path that names no records.
WHERE = "check the path; records are kept beside the plant file, in .prc3cfg/"
NAME_ONE = f"{WHERE} — name a plant file, a .prc3cfg folder, a journal (.jsonl) or a snapshot (.json)"
#: The time that begins every record file's name (`prc3cfg.shell.records`, `STAMP_LENGTH` long).
STAMP_FORMAT = "%Y%m%dT%H%M%S.%fZ"
#: How far the clock may be stepped (NTP) between two moments a run takes one after the other — its
#: journal's name, then its header's time, then its next record's: beyond it, they disagree.
CLOCK_SLACK = timedelta(minutes=1)


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
        found = [(n, r) for n, r in enumerate(self.records, 1) if r.get("event") == "snapshot"
                 and (name is None or r.get("path") == name)]
        return found[-1] if found else None


def file_name(value: Any) -> str | None:
    """`value` when a record names a file beside it by it — a bare name, no folder, not `..` — else
    None: a record is data anyone may have edited, and prune removes what records name."""
    if (not isinstance(value, str) or value in ("", ".", "..") or "/" in value or "\\" in value
        or "\0" in value):
        return None
    return value


def stamped(path: Path) -> datetime | None:
    """The time a record file's name begins with (`TIME-PLANT.jsonl`, `TIME-PLANT.json`): when prc3cfg
    chose the name. None when the name does not begin so."""
    try:
        return (datetime.strptime(path.name[:STAMP_LENGTH], STAMP_FORMAT).replace(tzinfo=UTC)
                if path.name[STAMP_LENGTH:][:1] == "-" else None)
    except ValueError:
        return None


def _time(value: Any) -> datetime | None:
    """A record's `time` as prc3cfg writes it — ISO 8601 with its UTC offset — else None."""
    try:
        said = datetime.fromisoformat(value) if isinstance(value, str) else None
    except ValueError:
        return None
    return said if said is not None and said.utcoffset() is not None else None


def check_journal(path: Path) -> Checked:
    """The chain of the journal at `path`. A last line without its end of line is left out and said
    (`cut`): a run the disk refused midway (full), or killed as it wrote, leaves one — and so does
    another run still writing it — and the records before it are whole."""
    try:
        data = read_regular(path, JOURNAL_LIMIT)
    except FileProblem as problem:
        told = NAME_ONE if problem.why is Why.MISSING else EVIDENCE
        return Checked(path, [], False, Mismatch(str(path), str(problem), told))
    lines = data.split(b"\n")
    cut = bool(lines.pop())  # what follows the last newline: nothing, in a whole journal
    if not lines:
        said = "cut short before its header was whole" if cut else "empty: a journal begins with its header"
        return Checked(path, [], False, Mismatch(str(path), said))
    records: list[dict[str, Any]] = []
    for number, line in enumerate(lines, 1):
        try:
            record = json.loads(line)
        except (ValueError, RecursionError):  # RecursionError: nested deeper than json's parser goes
            record = None
        if not isinstance(record, dict):
            return Checked(path, records, True,
                           Mismatch(f"{path}:{number}", "not a JSON record as prc3cfg writes it"))
        records.append(record)
    if records[0].get("event") != "header":
        if not any("prev" in record for record in records):
            return Checked(path, records, False, None, line_hash(lines[-1]), cut)  # before headers
        return Checked(path, records, True,
                       Mismatch(f"{path}:1", "no header: a journal begins with who, where, what and why"))
    if records[0].get("prev") is not None:
        return Checked(path, records, True, Mismatch(f"{path}:1", "a header that follows another record"))
    for number in range(1, len(lines)):
        if records[number].get("prev") != line_hash(lines[number - 1]):
            return Checked(path, records, True, Mismatch(
                f"{path}:{number}", f"not the record the next one (line {number + 1}) was written after — "
                                    "this one edited, "
                "or records removed or inserted here"))
    return Checked(path, records, True, None, line_hash(lines[-1]), cut)


def journals(plant_path: Path) -> list[Path]:
    """The plant file's journals, oldest first (by the time in their names)."""
    return of_plant(records_dir(plant_path, "journal"), plant_path.stem, ".jsonl")


def of_plant(folder: Path, stem: str, suffix: str) -> list[Path]:
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
        raise UserError(f"{checked.problem.said()} — the plant's newest journal does not verify, and this "
                        "run's journal "
                        f"would follow it: nothing was written; {EVIDENCE}, then move it (and its "
                        "snapshot) out of "
                        f"{found[-1].parent} and run again")
    return {"journal": found[-1].name, "lines": len(checked.records), "sha256": checked.last}


def snapshot_checked(path: Path, snapshot: Snapshot) -> str | None:
    """A snapshot about to be restored, checked against its journal: `UserError` when either does
    not verify; a note when it was written before records had headers (it cannot be checked)."""
    if snapshot.header is None:
        for beside in of_plant(resolved(path).parent.parent / "journal", snapshot.plant_path.stem, ".jsonl"):
            with contextlib.suppress(FileProblem):
                if ('"event": "snapshot", "path": '
                    f'{json.dumps(path.name)}').encode() in read_regular(beside, JOURNAL_LIMIT):
                    raise UserError(f"{path}: has no header, but {beside} records it as written with one — "
                                    "edited since; "
                                    f"nothing was written; {EVIDENCE}")
        return f"{path}: written before records had headers — its integrity cannot be checked"
    name = file_name(snapshot.header.get("journal"))
    if name is None:
        raise UserError(f"{path}: its header names no journal file — the snapshot cannot be checked, "
                        f"nothing was written; {EVIDENCE}")
    candidates = [resolved(path).parent.parent / "journal" / name,
                  records_dir(snapshot.plant_path, "journal") / name]
    journal = next((c for c in candidates if c.is_file()), None)
    if journal is None:
        raise UserError(f"{path}: its journal {name} is in neither {candidates[0].parent} nor "
                        f"{candidates[1].parent} — the "
                        "snapshot cannot be checked, nothing was written: put the journal back from "
                        "your backup")
    problem = _snapshot_problem(check_journal(journal), path)
    if problem is not None:
        raise UserError(f"{problem.said()} — nothing was written; {EVIDENCE}")
    return None


def _snapshot_problem(checked: Checked, snapshot: Path) -> Mismatch | None:
    """Whatever keeps `snapshot` from being the one its journal recorded last: not recorded there, of
    another plant file, not the bytes recorded, or a snapshot whose header names another journal."""
    if checked.problem is not None:
        return checked.problem
    found = checked.snapshot_record(snapshot.name)
    if found is None:
        return Mismatch(str(snapshot), f"not recorded in its journal {checked.path}")
    line, record = found
    if snapshot.name[STAMP_LENGTH:] != checked.path.name[STAMP_LENGTH:].removesuffix(".jsonl") + ".json":
        return Mismatch(f"{checked.path}:{line}",
                        f"names {snapshot.name}, a snapshot of another plant file, as its own")
    try:
        data = read_regular(snapshot, JOURNAL_LIMIT)
    except FileProblem as problem:
        return Mismatch(str(snapshot), str(problem))
    if line_hash(data) != record.get("sha256"):
        return Mismatch(str(snapshot),
                        f"does not match its SHA-256 in {checked.path}:{line} — edited or replaced since it "
                        "was written")
    try:
        header = json.loads(data).get("header")
    except (ValueError, RecursionError, AttributeError):
        return Mismatch(str(snapshot), "not a JSON document as prc3cfg writes a snapshot")
    if isinstance(header, dict) and header.get("journal") != checked.path.name:
        return Mismatch(f"{checked.path}:{line}",
                        f"names {snapshot.name} as its own, whose header names the journal "
                                                  f"{header.get('journal')!r} — the snapshot of another run")
    return None


def _header_problem(path: Path, journal: Checked) -> Mismatch | None:
    """Whatever in a chained journal's header disagrees with what prc3cfg can check: the journal's
    own name (`journal`), the time the name begins with, and the time of the record after the header
    — the name is chosen first, the header written at the first record, the next record after it."""
    header, where = journal.header or {}, f"{path}:1"
    if header.get("journal") != path.name:
        return Mismatch(where, f"its header names the journal {header.get('journal')!r}, not this file — "
                               "renamed, or copied from another")
    if (named := stamped(path)) is None:
        return Mismatch(str(path),
                        f"its name does not begin with the time prc3cfg writes ({STAMP_FORMAT}-PLANT.jsonl) "
                        "— renamed")
    if (said := _time(header.get("time"))) is None:
        return Mismatch(where, f"its header's time {header.get('time')!r} is not an ISO 8601 time with its "
                               "UTC offset, as prc3cfg "
                               "writes it — edited")
    if said < named - CLOCK_SLACK:
        return Mismatch(where, f"its header's time {said.isoformat()} is before the time in its file name "
                               f"({named.isoformat()}), which was chosen first — edited, or the file renamed")
    after = _time(journal.records[1].get("time")) if len(journal.records) > 1 else None
    if after is not None and said > after + CLOCK_SLACK:
        return Mismatch(where, f"its header's time {said.isoformat()} is after the time of the record "
                               "after it "
                               f"({after.isoformat()}) — edited")
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
        unchained = (f"; {self.unchained} written before records had headers: not checked"
                     if self.unchained else "")
        journals = f"{self.journals} journal{'s' if self.journals != 1 else ''}"
        return (f"{journals} and {self.snapshots} snapshot{'s' if self.snapshots != 1 else ''} "
                f"checked{unchained}")


def check(paths: Iterable[Path]) -> Verified:
    """Every record under `paths` checked: a plant file (its records), a records folder, journals,
    snapshots — and a problem for each path that names none."""
    result = Verified()
    wanted_journals, wanted_snapshots = _wanted(paths, result)
    checked: dict[Path, Checked] = {}
    done: set[Path] = set()  # snapshots checked with their journal
    for path in wanted_journals:
        checked[resolved(path)] = _check_chained(path, result, done)
    for path in wanted_snapshots:
        if resolved(path) not in done:
            _check_alone(path, result, checked)
    return result


def _wanted(paths: Iterable[Path], result: Verified) -> tuple[dict[Path, None], dict[Path, None]]:
    """The journals and the snapshots `paths` name, each once, in order; a problem for a path that names no
    records."""
    wanted_journals: dict[Path, None] = {}
    wanted_snapshots: dict[Path, None] = {}
    for path in paths:
        folder = _records_folder(path)
        found: list[Path] = []
        if path.suffix.lower() in (".yaml", ".yml") and not path.is_dir():  # a plant file: its own records
            found = journals(path)
            wanted_journals.update(dict.fromkeys(found))
            found += (snapshots := of_plant(records_dir(path, "snapshots"), path.stem, ".json"))
            wanted_snapshots.update(dict.fromkeys(snapshots))
            none = ("no such file" if not path.exists()
                    else "no runs of it recorded in the .prc3cfg/ folder beside it")
        elif folder is not None:
            for kind, into, suffix in (("journal", wanted_journals, ".jsonl"),
                                       ("snapshots", wanted_snapshots, ".json")):
                with contextlib.suppress(OSError):
                    found += (these := sorted(p for p in (folder / kind).iterdir() if p.suffix == suffix))
                    into.update(dict.fromkeys(these))
            none = "a folder with no records in it (no journal/ or snapshots/ with any)"
        elif path.suffix in (".jsonl", ".json"):
            found = [path]
            (wanted_journals if path.suffix == ".jsonl" else wanted_snapshots)[path] = None
        else:
            found = []
            none = ("no such file" if not os.path.lexists(path)
                    else "not a plant file, records folder, journal (.jsonl) or snapshot (.json)")
        if not found:
            result.problems.append(Mismatch(str(path), none, NAME_ONE))
    return wanted_journals, wanted_snapshots


def _check_chained(path: Path, result: Verified, done: set[Path]) -> Checked:
    """A journal checked into `result` (`journal_problems`); the snapshot it records last added to
    `done`, so that it is not checked again on its own."""
    journal = check_journal(path)
    result.journals += 1
    if journal.cut and journal.problem is None:
        result.notes.append(f"{path}:{len(journal.records) + 1}: its last record was cut short — the disk "
                            "refused it, or the "
                            "run was killed as it wrote it — and is left out")
    if not journal.chained and journal.problem is None:
        result.unchained += 1
    problems, snapshot = journal_problems(path, journal, result.notes)
    result.problems.extend(problems)
    if snapshot is not None:
        done.add(snapshot)
        result.snapshots += 1
    return journal


def journal_problems(path: Path, journal: Checked, notes: list[str]) -> tuple[list[Mismatch], Path | None]:
    """Whatever keeps a journal from being evidence: its chain; then its header against its name and
    records, its link to the run before, and the snapshot it records last (given back, once named)."""
    if journal.problem is not None:
        return [journal.problem], None
    if not journal.chained:
        return [], None
    found_problems = (_header_problem(path, journal), _link_problem(path, journal, notes))
    problems = [problem for problem in found_problems if problem is not None]
    if (found := journal.snapshot_record()) is None:
        return problems, None
    if (name := file_name(found[1].get("path"))) is None:
        return [*problems,
                Mismatch(f"{path}:{found[0]}", "names no snapshot file (a path, not a name in "
                                               "snapshots/)")], None
    snapshot = resolved(path).parent.parent / "snapshots" / name
    if not os.path.lexists(snapshot):
        problems.append(Mismatch(f"{path}:{found[0]}", f"names the snapshot {snapshot}, which is not there — "
                                                       "removed by hand (prune removes a run's journal and "
                                                       "snapshot together)"))
    elif (problem := _snapshot_problem(journal, snapshot)) is not None:
        problems.append(problem)
    return problems, snapshot


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
    journal_path = resolved(path).parent.parent / "journal" / name
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


def _link_problem(path: Path, journal: Checked, notes: list[str]) -> Mismatch | None:
    """A journal's link to the plant's journal before it: one of the same plant file, begun earlier
    (by the names' times), and that one's line as it was when this run began."""
    previous = (journal.header or {}).get("previous")
    if not isinstance(previous, dict):
        return None
    if (name := file_name(previous.get("journal"))) is None:
        return Mismatch(f"{path}:1", "its link to the run before names no journal file")
    before = resolved(path).parent / name
    began, then = stamped(path), stamped(before)
    if (name == path.name or name[STAMP_LENGTH:] != path.name[STAMP_LENGTH:] or began is None
        or then is None or then > began + CLOCK_SLACK):
        return Mismatch(f"{path}:1",
                        f"its link to the run before names {name}, not an earlier journal of the same plant "
                        "file — edited")
    try:
        lines = read_regular(before, JOURNAL_LIMIT).split(b"\n")
    except FileProblem as problem:
        if problem.why is not Why.MISSING:
            return Mismatch(str(before), str(problem))
        notes.append(f"{path}:1: follows {before.name}, which is not there (pruned, or removed)")
        return None
    count = previous.get("lines")
    if (not isinstance(count, int) or not 0 < count <= len(lines)
        or line_hash(lines[count - 1]) != previous.get("sha256")):
        return Mismatch(f"{before}:{count}", f"not the record {path}:1 follows — edited since that run began")
    return None
