"""`records prune` acts on evidence, and `records list/verify/prune` of a path that is no plant file
with records say so (issue 39, items 4 and 7).

Real runs: applies of two plant files in one folder, on the same emulated lines, through the CLI.
Then their journals are edited as someone who can write the records folder would — a header's time
moved, a journal of one plant made to name the other plant's snapshot, a chain broken, a journal
renamed — with the chain made whole again where the forgery can do that. Prune must then remove
nothing, and name what does not verify and why; the newest snapshot of every plant's lines stays.
A seeded family of such edits runs in the soak tier.
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import json
import os
import random
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml
from emulated import Result, emulated_plant, run_cli
from test_records import chained, journals, records_of, snapshots

APPLY = ("--auto-approve", "--allow-axis-release")


@pytest.fixture(autouse=True)
def no_reason_no_git_above(monkeypatch, tmp_path):
    monkeypatch.delenv("PRC3CFG_REASON", raising=False)
    monkeypatch.setenv("GIT_CEILING_DIRECTORIES", str(tmp_path.parent))


@dataclass
class Line:
    """Two plant files in one folder, on the same emulated lines: `p` (demo-line) and `q` (other-line)."""

    folder: Path
    p: Path
    q: Path

    def runs(self, plant: Path) -> list[Path]:
        return [j for j in journals(self.folder) if j.name.endswith(f"-{plant.stem}.jsonl")]

    def snapshot_of(self, journal: Path) -> Path:
        (record,) = [r for r in records_of(journal) if r["event"] == "snapshot"][-1:]
        return self.folder / ".prc3cfg" / "snapshots" / record["path"]

    def files(self) -> set[Path]:
        return set(journals(self.folder)) | set(snapshots(self.folder))


def with_position(plant: Path, position: float) -> None:
    """Program 7 of booth-a-left at `position`: each apply after such a change writes (a snapshot)."""
    document = yaml.safe_load(plant.read_text())
    document["buses"][0]["modules"][0].setdefault("programs", {})[7] = {"position": position, "speed": 0.3}
    plant.write_text(yaml.safe_dump(document, sort_keys=False))


@contextlib.contextmanager
def two_plants(tmp_path: Path, capsys: pytest.CaptureFixture, order: str = "ppqp") -> Iterator[Line]:
    """Runs of `p` and `q` in `order`, each writing booth-a-left; then one run of `p` writing booth-b-left."""
    with emulated_plant(tmp_path) as plant:
        q = tmp_path / "other.yaml"
        q.write_text(plant.path.read_text().replace("plant: demo-line", "plant: other-line"))
        for n, which in enumerate(order):
            path = plant.path if which == "p" else q
            with_position(path, 1.0 + n / 10)
            result = run_cli(capsys, "apply", path, "--module", "booth-a-left", *APPLY)
            assert result.code == 0, result.err
        assert run_cli(capsys, "apply", plant.path, "--module", "booth-b-left", *APPLY).code == 0
        yield Line(tmp_path, plant.path, q)


def rechained(journal: Path, change: Callable[[list[dict]], None]) -> None:
    """The journal's records changed by `change` and chained again: a forgery the chain alone cannot tell."""
    records = [{k: v for k, v in r.items() if k != "prev"} for r in parsed(journal)]
    change(records)
    journal.write_bytes(chained(*records))


def relinked(after: Path, before: Path) -> None:
    """The header of `after` made to follow `before` as it is now (and its chain made whole): the link forged
    too."""
    last = before.read_bytes().splitlines()[-1]
    link = {"journal": before.name, "lines": len(before.read_bytes().splitlines()),
            "sha256": hashlib.sha256(last).hexdigest()}
    rechained(after, lambda records: records[0].update(previous=link))


def header_time(value: object) -> Callable[[list[dict]], None]:
    def change(records: list[dict]) -> None:
        if value is None:
            del records[0]["time"]
        else:
            records[0]["time"] = value

    return change


def refused(result, *names: Path) -> None:
    """Prune stopped: non-zero, no traceback, and each of `names` said."""
    assert result.code == 1, (result.out, result.err)
    assert "Traceback" not in result.err and "nothing was removed" in result.err, result.err
    for name in names:
        assert str(name) in result.err, result.err


# -- ordered by the file name and the chain, never by a header's word ------------------------------


@pytest.mark.parametrize("forged", ["edited", "rechained"])
def test_a_header_time_moved_back_does_not_make_the_newest_run_the_oldest(tmp_path, capsys, forged):
    """The newest run's header says 2001: prune ordered by it took that run for the oldest and removed the
    line's newest snapshot. Now the file name orders, and the header that disagrees with it stops prune."""
    with two_plants(tmp_path, capsys, "ppp") as line:
        *_, newest_a, newest = line.runs(line.p)
        change = header_time("2001-01-01T00:00:00+00:00")
        if forged == "rechained":
            rechained(newest, change)
        else:
            records = newest.read_text().splitlines()
            records[0] = json.dumps(json.loads(records[0]) | {"time": "2001-01-01T00:00:00+00:00"})
            newest.write_text("\n".join(records) + "\n")
        kept = line.files()
        for args in (("--keep", "1"), ("--keep", "1", "--dry-run"), ("--older-than", "0", "--json")):
            result = run_cli(capsys, "records", "prune", line.p, *args)
            refused(result, newest)
            assert line.files() == kept
        assert line.snapshot_of(newest_a).exists()
        said = run_cli(capsys, "records", "verify", line.p)
        assert said.code == 1 and str(newest) in said.err
        if forged == "rechained":
            assert "its file name" in said.err, said.err  # the header's time against the file name's
        listed = json.loads(run_cli(capsys, "records", "list", line.p, "--json").out)
        run = next(r for r in listed if r["journal"] == str(newest))
        assert run["time"].startswith(newest.name[:4]), run
        assert (run["findings"] if forged == "rechained"
                else run["chain"].startswith(f"broken at {newest}:")), run


def test_a_header_time_moved_forward_on_an_older_run_stops_prune(tmp_path, capsys):
    """An older run's header moved past the newest (the chain made whole, the next run's link forged): the
    header's time is later than the records after it — said, and prune removes nothing."""
    with two_plants(tmp_path, capsys, "ppp") as line:
        first, second, third, fourth = line.runs(line.p)
        rechained(first, header_time("2099-01-01T00:00:00+00:00"))
        relinked(second, first)
        for after, before in ((third, second), (fourth, third)):
            relinked(after, before)
        kept = line.files()
        refused(run_cli(capsys, "records", "prune", line.p, "--keep", "1"), first)
        assert line.files() == kept


@pytest.mark.parametrize("forged", ["edited", "rechained"])
def test_a_journal_of_one_plant_naming_the_other_plants_snapshot_removes_nothing(tmp_path, capsys, forged):
    """p's first journal made to name q's newest snapshot (its SHA-256 too): prune of p removed q's
    snapshot."""
    with two_plants(tmp_path, capsys, "ppqp") as line:
        (q_run,) = line.runs(line.q)
        theirs = line.snapshot_of(q_run)
        first, second, *_ = line.runs(line.p)

        def name_theirs(records: list[dict]) -> None:
            for record in records:
                if record["event"] == "snapshot":
                    record.update(path=theirs.name, sha256=hashlib.sha256(theirs.read_bytes()).hexdigest())

        if forged == "rechained":
            rechained(first, name_theirs)
            relinked(second, first)
            for before, after in itertools.pairwise(line.runs(line.p)[1:]):
                relinked(after, before)
        else:
            records = records_of(first)
            name_theirs(records)
            first.write_text("".join(json.dumps(r) + "\n" for r in records))
        kept = line.files()
        for args in (("--keep", "1"), ("--keep", "1", "--json")):  # the console script, as its own process
            done = subprocess.run([sys.executable, "-m", "prc3cfg", "records", "prune", str(line.p), *args],
                                  capture_output=True, text=True, timeout=60)
            refused(Result(done.returncode, done.stdout, done.stderr), first)
            assert done.stdout == ""
        assert theirs.exists() and line.files() == kept


def test_a_broken_chain_anywhere_in_the_folder_stops_prune_and_names_it(tmp_path, capsys):
    """A journal of the other plant that does not verify stops prune of this one too: it may name this one's
    files."""
    with two_plants(tmp_path, capsys, "ppqp") as line:
        (q_run,) = line.runs(line.q)
        text = q_run.read_bytes()
        q_run.write_bytes(text.replace(b'"event": "exchange"', b'"event": "exchange", "x": 1', 1))
        kept = line.files()
        for dry in ((), ("--dry-run",)):
            result = run_cli(capsys, "records", "prune", line.p, "--keep", "0", *dry)
            refused(result, q_run)
            assert "not the record the next one" in result.err
        assert line.files() == kept


def test_a_renamed_journal_is_not_ordered_by_its_new_name(tmp_path, capsys):
    """The newest journal renamed to an old time (its snapshot left): the header's journal name disagrees."""
    with two_plants(tmp_path, capsys, "ppp") as line:
        *_, newest = line.runs(line.p)
        renamed = newest.with_name("20000101T000000.000000Z-plant.jsonl")
        newest.rename(renamed)
        kept = line.files()
        refused(run_cli(capsys, "records", "prune", line.p, "--keep", "1"), renamed)
        assert line.files() == kept


def test_prune_of_records_that_verify_keeps_each_lines_newest_by_the_file_names(tmp_path, capsys):
    """Nothing edited: the runs beyond the newest go, the newest snapshot of each line and the newest run stay
    — and the other plant's records are not touched."""
    with two_plants(tmp_path, capsys, "ppqp") as line:
        first, second, third, fourth = line.runs(line.p)
        theirs = set(line.runs(line.q)) | {line.snapshot_of(j) for j in line.runs(line.q)}
        pruned = run_cli(capsys, "records", "prune", line.p, "--keep", "0", "--json")
        assert pruned.code == 0, pruned.err
        done = json.loads(pruned.out)
        assert [r["journal"] for r in done["removed"]] == [str(first), str(second)]
        assert {k["journal"]: k["why"] for k in done["kept"]}.keys() == {str(third), str(fourth)}
        assert all(p.exists() for p in theirs) and third.exists() and line.snapshot_of(third).exists()
        assert run_cli(capsys, "records", "verify", tmp_path / ".prc3cfg").code == 0


# -- bad times and bounds: one line, never a traceback -----------------------------------------


@pytest.mark.parametrize("value", ["yesterday", "2026-01-01T00:00", 1700000000, None,
                                   "9999-12-31T23:59:59+00:00"])
def test_a_header_time_prc3cfg_did_not_write_is_one_line(tmp_path, capsys, value):
    with two_plants(tmp_path, capsys, "pp") as line:
        first, *_ = line.runs(line.p)
        rechained(first, header_time(value))
        relinked(line.runs(line.p)[1], first)
        relinked(line.runs(line.p)[2], line.runs(line.p)[1])
        kept = line.files()
        for bound in (("--keep", "0"), ("--older-than", "0")):
            refused(run_cli(capsys, "records", "prune", line.p, *bound), first)
        assert line.files() == kept
        said = run_cli(capsys, "records", "verify", line.p)
        assert said.code == 1 and f"{first}:1: " in said.err and "Traceback" not in said.err, said.err
        listed = run_cli(capsys, "records", "list", line.p)
        assert listed.code == 0 and "header" in listed.out


@pytest.mark.parametrize("bound", [("--older-than", "1e9"), ("--older-than", "inf"), ("--older-than", "nan"),
                                   ("--older-than", "-1"), ("--older-than", "1e400"), ("--keep", "-1")])
def test_a_bad_bound_is_one_line(plant, capsys, bound):
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-a-left", *APPLY).code == 0
    result = run_cli(capsys, "records", "prune", plant.path, *bound)
    assert (result.code != 0 and len(result.err.strip().splitlines()) == 1
            and bound[0] in result.err), result.err
    assert len(journals(plant.path.parent)) == 1


def test_keep_more_than_there_are_removes_nothing(plant, capsys):
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-a-left", *APPLY).code == 0
    result = run_cli(capsys, "records", "prune", plant.path, "--keep", str(10**30), "--older-than", "36500")
    assert result.code == 0 and "Removed 0 runs" in result.out, result.err
    assert len(journals(plant.path.parent)) == 1


# -- a path that is no plant file with records -------------------------------------------------


def test_records_of_a_path_that_is_no_plant_file_say_so_in_one_line(tmp_path, capsys):
    (tmp_path / "notes.yaml").write_text("a: 1\n")
    (tmp_path / "notes.txt").write_text("hello\n")
    (tmp_path / "folder").mkdir()
    for path in (tmp_path / "no-such-plant.yaml", tmp_path / "folder", tmp_path / "notes.yaml",
                 tmp_path / "notes.txt"):
        for args in (("list", path), ("list", path, "--json"), ("verify", path),
                     ("prune", path, "--keep", "1"),
                     ("prune", path, "--keep", "1", "--json")):
            done = run_cli(capsys, "records", *args)
            said = done.err.strip().splitlines()
            assert done.code == 1 and done.out == "" and len(said) == 1, (args, done.out, done.err)
            assert str(path) in said[0] and "check the path" in said[0] and ".prc3cfg" in said[0], said


def test_a_typo_listed_as_json_by_the_console_script_is_an_error_not_an_empty_list(tmp_path):
    done = subprocess.run([sys.executable, "-m", "prc3cfg", "records", "list", str(tmp_path / "plnat.yaml"),
                           "--json"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and done.stdout == "", (done.stdout, done.stderr)
    assert (done.stderr.startswith(f"error: {tmp_path / 'plnat.yaml'}: no such file")
            and "check the path" in done.stderr)


def test_a_plant_file_never_applied_has_no_runs_yet(tmp_path, capsys):
    """A real plant file with no records: list and prune say so and succeed; verify fails — it vouches for
    nothing."""
    with emulated_plant(tmp_path) as plant:
        listed = run_cli(capsys, "records", "list", plant.path)
        assert listed.code == 0 and "no runs recorded yet" in listed.out
        as_json = run_cli(capsys, "records", "list", plant.path, "--json")
        assert as_json.code == 0 and json.loads(as_json.out) == []
        pruned = run_cli(capsys, "records", "prune", plant.path, "--keep", "0")
        assert pruned.code == 0 and "Removed 0 runs" in pruned.out
        verified = run_cli(capsys, "records", "verify", plant.path)
        assert verified.code == 1 and "no runs of it recorded" in verified.err


def test_verify_of_several_paths_names_the_one_without_records(plant, capsys, tmp_path):
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-a-left", *APPLY).code == 0
    typo = tmp_path / "plnat.yaml"
    result = run_cli(capsys, "records", "verify", plant.path, typo)
    assert result.code == 1 and str(typo) in result.err and "check the path" in result.err


# -- the seeded family -------------------------------------------------------------------------

#: Header times prc3cfg never writes.
GARBAGE_TIMES = ["yesterday", "2026-01-01T00:00", 1700000000, None, "", "9999-12-31T23:59:59+00:00",
                 "2000-01-01T00:00:00+00:00",
                 [], {"t": 1}, "2026-13-45T99:99:99Z", "1e400", -1]


def edit(line: Line, rng: random.Random) -> str:
    """One edit as an attacker with write access to the folder would make it; what it was, in words."""
    journal = rng.choice(regular(journals(line.folder)))
    kind = rng.choice(["none", "time", "snapshot", "drop", "duplicate", "swap", "rename", "plant",
                       "truncate"])
    if kind == "none":
        return "nothing"
    records = parsed(journal) or [{"event": "header"}]
    if kind == "time":
        records[0]["time"] = rng.choice(GARBAGE_TIMES)
    elif kind == "snapshot":
        other = rng.choice(regular(snapshots(line.folder)))
        for record in records:
            if record["event"] == "snapshot":
                record.update(path=other.name, sha256=hashlib.sha256(other.read_bytes()).hexdigest())
    elif kind == "drop" and len(records) > 2:
        del records[rng.randrange(1, len(records))]
    elif kind == "duplicate":
        at = rng.randrange(len(records))
        records.insert(at, records[at])
    elif kind == "swap" and len(records) > 2:
        a, b = rng.sample(range(len(records)), 2)
        records[a], records[b] = records[b], records[a]
    elif kind == "rename":
        renamed = f"{rng.randrange(2000, 2100)}0101T000000.000000Z-{journal.name[24:]}"
        journal.rename(journal.with_name(renamed))
        return f"renamed {journal.name}"
    elif kind == "plant":
        name = (line.folder / ".prc3cfg" / rng.choice(["journal", "snapshots"])
                / f"29990101T000000.000000Z-plant.json{rng.choice(['', 'l'])}")
        what = rng.choice(["fifo", "folder", "link", "garbage"])
        if os.path.lexists(name):
            return "nothing"
        if what == "fifo" and hasattr(os, "mkfifo"):
            os.mkfifo(name)
        elif what == "folder":
            name.mkdir()
        elif what == "link":
            name.symlink_to("/dev/zero")
        else:
            name.write_bytes(rng.randbytes(rng.randrange(1, 200)))
        return f"planted a {what} at {name.name}"
    elif kind == "truncate":
        data = journal.read_bytes()
        journal.write_bytes(data[: rng.randrange(len(data))])
        return f"cut {journal.name}"
    if rng.random() < 0.6:
        journal.write_bytes(chained(*({k: v for k, v in r.items() if k != "prev"} for r in records)))
        if rng.random() < 0.5:  # the next run's link forged too
            mine = [j for j in regular(journals(line.folder)) if j.name[24:] == journal.name[24:]]
            if journal in mine and mine.index(journal) + 1 < len(mine):
                relinked(mine[mine.index(journal) + 1], journal)
        return f"{kind} in {journal.name}, rechained"
    journal.write_text("".join(json.dumps(r) + "\n" for r in records))
    return f"{kind} in {journal.name}"


def regular(paths: list[Path]) -> list[Path]:
    """Files of the records folder, not one planted before (a FIFO, a folder, a link): what an edit opens."""
    return [p for p in paths if p.is_file() and not p.is_symlink()]


def parsed(journal: Path) -> list[dict]:
    """The records of a journal that parse (an edit before may have cut one)."""
    found = []
    for line in journal.read_bytes().splitlines():
        with contextlib.suppress(ValueError):
            found.append(json.loads(line))
    return [record for record in found if isinstance(record, dict)]


def newest_by_line(line: Line) -> set[Path]:
    """Before any edit: the newest snapshot of each line of each plant — what no prune may remove."""
    newest: dict[tuple[str, str], Path] = {}
    for snapshot in snapshots(line.folder):
        document = json.loads(snapshot.read_text())
        for bus in {m["bus"] for m in document["modules"]}:
            newest[(snapshot.name[24:], bus)] = snapshot  # names sort by time
    return set(newest.values())


def run_family(tmp_path: Path, capsys: pytest.CaptureFixture, seeds: range) -> dict[str, int]:
    """Each seed: the base's records copied, edited, pruned. How many prunes stopped, removed something,
    removed nothing."""
    outcomes = {"stopped": 0, "removed": 0, "none removed": 0}
    (tmp_path / "base").mkdir()
    with two_plants(tmp_path / "base", capsys, "ppqpq") as base:
        guarded = {p.relative_to(base.folder) for p in newest_by_line(base)}
        for seed in seeds:
            rng = random.Random(seed)
            folder = tmp_path / f"seed-{seed}"
            shutil.copytree(base.folder, folder, symlinks=True)
            line = Line(folder, folder / base.p.name, folder / base.q.name)
            # none: prune must still act
            said = [edit(line, rng) for _ in range(rng.choice([0, 0, 1, 1, 2, 3]))]
            before = set(folder.rglob("*"))
            whole = run_cli(capsys, "records", "verify", folder / ".prc3cfg").code == 0
            plant = rng.choice([line.p, line.q])
            bound = rng.choice([("--keep", str(rng.randrange(0, 4))),
                                ("--older-than", rng.choice(["0", "0.5", "1e9", "nan"]))])
            result = run_cli(capsys, "records", "prune", plant, *bound,
                             *rng.choice([(), ("--dry-run",), ("--json",)]))
            assert result.code in (0, 1, 64), (seed, said, result.err)
            assert "Traceback" not in result.err, (seed, said)
            after = set(folder.rglob("*"))
            if not whole or result.code != 0:
                # nothing acted on what does not verify
                assert after == before, (seed, said, result.out, result.err)
            assert all((folder / p).exists() for p in guarded if folder / p in before), (seed, said,
                                                                                         result.out)
            if result.code == 0:
                assert run_cli(capsys, "records", "verify", folder / ".prc3cfg").code == 0, (seed, said)
            outcomes["stopped" if result.code else "removed" if after != before else "none removed"] += 1
            shutil.rmtree(folder)
    return outcomes


def test_seeded_edits_before_prune_a_few(tmp_path, capsys):
    outcomes = run_family(tmp_path, capsys, range(12))
    assert outcomes["stopped"] and outcomes["removed"], outcomes


@pytest.mark.soak
def test_seeded_edits_before_prune(tmp_path, capsys):
    outcomes = run_family(tmp_path, capsys, range(12, 412))
    assert min(outcomes.values()) >= 10, outcomes
