"""The records an apply leaves, as an auditor reads them: each journal and snapshot says who, where,
what and why (a header); the journal is a hash chain `records verify` checks; `records list` and
`records prune` manage them; `require_reason` refuses a write without a reason before the line opens.
Real emulators, the CLI in-process, real `git`."""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import socket
import subprocess
from pathlib import Path

import pytest
import yaml
from emulated import emulated_plant, run_cli

from prc3cfg import __version__
from prc3cfg.shell import pending_records
from prc3cfg.shell.locks import line_keys

APPLY = ("--auto-approve", "--allow-axis-release")


@pytest.fixture(autouse=True)
def no_reason_no_git_above(monkeypatch, tmp_path):
    """No reason from the environment, and no git work tree above the test's folder."""
    monkeypatch.delenv("PRC3CFG_REASON", raising=False)
    monkeypatch.setenv("GIT_CEILING_DIRECTORIES", str(tmp_path.parent))


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def journals(folder: Path) -> list[Path]:
    return sorted((folder / ".prc3cfg" / "journal").glob("*.jsonl"))


def snapshots(folder: Path) -> list[Path]:
    return sorted((folder / ".prc3cfg" / "snapshots").glob("*.json"))


def records_of(journal: Path) -> list[dict]:
    return [json.loads(line) for line in journal.read_text().splitlines()]


def git(folder: Path, *args: str) -> str:
    done = subprocess.run(["git", "-C", str(folder), *args], capture_output=True, text=True, check=True)
    return done.stdout.strip()


def committed(folder: Path) -> str:
    git(folder, "init", "-q")
    git(folder, "-c", "user.name=t", "-c", "user.email=t@example.com", "add", "plant.yaml")
    git(folder, "-c", "user.name=t", "-c", "user.email=t@example.com", "commit", "-q", "-m", "plant")
    return git(folder, "rev-parse", "HEAD")


def edit_plant(path: Path, change) -> None:
    document = yaml.safe_load(path.read_text())
    change(document)
    path.write_text(yaml.safe_dump(document, sort_keys=False))


def test_header_outside_a_git_work_tree_without_a_reason(plant, capsys, tmp_path):
    result = run_cli(capsys, "apply", plant.path, *APPLY)
    assert result.code == 0, result.err
    (journal,) = journals(tmp_path)
    (snapshot,) = snapshots(tmp_path)
    header = records_of(journal)[0]
    assert header["event"] == "header" and header["prev"] is None
    assert header["command"] == "apply"
    assert header["user"] and header["host"] == socket.gethostname()
    assert header["prc3cfg"] == __version__
    assert "apply" in header["argv"] and str(plant.path) in header["argv"]
    assert header["plant"]["path"] == str(plant.path.resolve())
    assert header["plant"]["sha256"] == sha256(plant.path)
    git_said = header["plant"]["git"]
    assert (git_said["commit"] is None and git_said["clean"] is None
            and "not in a git work tree" in git_said["said"])
    assert header["plan_file"] is None and header["reason"] is None
    assert header["journal"] == journal.name
    kept = json.loads(snapshot.read_text())["header"]
    assert kept == {k: v for k, v in header.items() if k not in ("time", "event", "prev")}


def test_header_in_a_git_work_tree_with_a_reason_and_a_plan_file(plant, capsys, tmp_path, monkeypatch):
    commit = committed(tmp_path)
    plan = tmp_path / "plan.json"
    assert run_cli(capsys, "plan", plant.path, "--out", plan).code == 0
    result = run_cli(capsys, "apply", plant.path, "--plan", plan, *APPLY, "--reason",
                     "PR #12: new stroke, run 345")
    assert result.code == 0, result.err
    header = records_of(journals(tmp_path)[-1])[0]
    assert header["plant"]["git"] == {"commit": commit, "clean": True, "plant_file": "committed",
                                      "said": None}
    assert header["plan_file"] == {"path": str(plan.resolve()), "sha256": sha256(plan)}
    assert header["reason"] == "PR #12: new stroke, run 345"
    assert json.loads(snapshots(tmp_path)[-1].read_text())["header"]["reason"] == ("PR #12: new "
                                                                                   "stroke, run 345")

    # the plant file changed and not committed; the reason from the environment; a restore says so too
    edit_plant(plant.path,
               lambda d: d["buses"][0]["modules"][0].setdefault("programs", {}).update({7: {"position": 1.0,
                                                                                            "speed": 0.3}}))
    monkeypatch.setenv("PRC3CFG_REASON", "ticket 77")
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-a-left", *APPLY).code == 0
    header = records_of(journals(tmp_path)[-1])[0]
    assert header["plant"]["git"] == {"commit": commit, "clean": False, "plant_file": "changed", "said": None}
    assert header["reason"] == "ticket 77" and header["plan_file"] is None
    restored = run_cli(capsys, "restore", snapshots(tmp_path)[-1], *APPLY, "--reason", "undo ticket 77")
    assert restored.code == 0, restored.err
    header = records_of(journals(tmp_path)[-1])[0]
    assert header["command"] == "restore" and header["reason"] == "undo ticket 77"


def test_require_reason_refuses_before_any_frame(tmp_path, capsys, monkeypatch):
    with emulated_plant(tmp_path, require_reason=True) as plant:
        before = plant.images()
        trace = tmp_path / "trace.txt"
        result = run_cli(capsys, "apply", plant.path, *APPLY, "--trace", trace)
        assert result.code == 1
        (line,) = result.problems
        assert ("require_reason" in line and "--reason" in line and "PRC3CFG_REASON" in line
                and "nothing was written" in line)
        assert plant.images() == before
        assert not trace.exists() or trace.read_text() == ""
        assert not (tmp_path / ".prc3cfg" / "journal").exists()
        adopted = run_cli(capsys, "adopt", plant.path, "--auto-approve")
        assert adopted.code == 1 and "require_reason" in adopted.err
        monkeypatch.setenv("PRC3CFG_REASON", "commissioning")
        assert run_cli(capsys, "apply", plant.path, *APPLY).code == 0
        assert records_of(journals(tmp_path)[-1])[0]["reason"] == "commissioning"


def test_every_record_is_chained_and_one_edited_byte_is_found_at_its_record(plant, capsys, tmp_path):
    assert run_cli(capsys, "apply", plant.path, *APPLY).code == 0
    (journal,) = journals(tmp_path)
    lines = journal.read_bytes().splitlines()
    for before, line in itertools.pairwise(lines):
        assert json.loads(line)["prev"] == hashlib.sha256(before).hexdigest()
    snapshot_record = [r for r in records_of(journal) if r["event"] == "snapshot"][-1]
    assert snapshot_record["sha256"] == sha256(snapshots(tmp_path)[0])
    good = run_cli(capsys, "records", "verify", plant.path)
    assert good.code == 0, good.err

    text = journal.read_bytes()
    at = text.index(b'"duration_s": 0.') + len(b'"duration_s": 0.')  # a digit of the third record or later
    edited = text[:at] + (b"9" if text[at:at + 1] != b"9" else b"8") + text[at + 1:]
    journal.write_bytes(edited)
    line = edited[:at].count(b"\n") + 1
    for target in (plant.path, journal, tmp_path / ".prc3cfg"):
        found = run_cli(capsys, "records", "verify", target)
        assert found.code == 1
        assert f"{journal}:{line}:" in found.err, found.err
    refused = run_cli(capsys, "apply", plant.path, *APPLY)
    assert refused.code == 1 and f"{journal}:{line}:" in refused.err and "nothing was written" in refused.err
    assert len(journals(tmp_path)) == 1
    restore = run_cli(capsys, "restore", snapshots(tmp_path)[0], *APPLY)
    assert restore.code == 1 and f"{journal}:{line}:" in restore.err


def test_an_edited_snapshot_is_found_and_not_restored(plant, capsys, tmp_path):
    assert run_cli(capsys, "apply", plant.path, *APPLY).code == 0
    (snapshot,) = snapshots(tmp_path)
    snapshot.write_text(snapshot.read_text().replace('"S1": ', '"S1": 1', 1))
    found = run_cli(capsys, "records", "verify", plant.path)
    assert found.code == 1 and str(snapshot) in found.err
    restore = run_cli(capsys, "restore", snapshot, *APPLY)
    assert restore.code == 1 and str(snapshot) in restore.err and "nothing was written" in restore.err


def test_a_snapshot_stripped_of_its_header_is_not_restored_as_one_from_before_headers(plant, capsys,
                                                                                      tmp_path):
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-a-left", *APPLY).code == 0
    (snapshot,) = snapshots(tmp_path)
    document = json.loads(snapshot.read_text())
    del document["header"]
    snapshot.write_text(json.dumps(document))
    refused = run_cli(capsys, "restore", snapshot, *APPLY)
    assert refused.code == 1 and "has no header, but" in refused.err and "nothing was written" in refused.err
    # with its journal gone too, it is one from before headers: restored, and said
    journals(tmp_path)[0].unlink()
    restored = run_cli(capsys, "restore", snapshot, *APPLY)
    assert restored.code == 0, restored.err
    assert "written before records had headers — its integrity cannot be checked" in restored.err


def test_records_list_says_who_what_where_and_the_result(plant, capsys, tmp_path):
    assert run_cli(capsys, "apply", plant.path, *APPLY, "--reason", "first").code == 0
    assert run_cli(capsys, "apply", plant.path, *APPLY).code == 0  # nothing to do
    listed = run_cli(capsys, "records", "list", plant.path, "--json")
    assert listed.code == 0, listed.err
    first, second = json.loads(listed.out)
    assert first["command"] == "apply" and first["reason"] == "first" and first["result"] == "verified"
    assert first["user"] and first["host"] == socket.gethostname() and first["plant"] == "demo-line"
    assert first["lines"] == ["booth-a", "booth-b"]
    assert first["snapshot"] == str(snapshots(tmp_path)[0]) and first["journal"] == str(journals(tmp_path)[0])
    assert first["time"] < second["time"] and first["chain"] == "intact"
    assert second["result"] == "nothing written" and second["snapshot"] is None
    human = run_cli(capsys, "records", "list", plant.path)
    assert human.code == 0 and "verified" in human.out and "first" in human.out


def test_a_refused_run_says_why_in_its_journal_and_in_the_list(plant, capsys, tmp_path):
    """An apply refused at a gate after its read-back keeps the journal of what it read, ending in why it was
    refused — `records list` says it, `records verify` still verifies the chain."""
    refused = run_cli(capsys, "apply", plant.path, "--auto-approve")
    assert refused.code == 1 and "apply again with --allow-axis-release" in refused.err
    (journal,) = journals(tmp_path)
    last = json.loads(journal.read_text().splitlines()[-1])
    assert last["event"] == "refused" and last["why"] == refused.err.removeprefix("error: ").strip()
    (run,) = json.loads(run_cli(capsys, "records", "list", plant.path, "--json").out)
    assert run["result"] == f"refused, nothing written: {last['why']}"
    assert "refused, nothing written: the plan releases the axes of" in run_cli(capsys, "records", "list",
                                                                                plant.path).out
    assert run_cli(capsys, "records", "verify", plant.path).code == 0


def test_prune_keeps_the_newest_snapshot_of_each_line_and_what_a_pending_release_needs(plant, capsys,
                                                                                       tmp_path):
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-a-left", *APPLY).code == 0
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-b-left", *APPLY).code == 0
    edit_plant(plant.path,
               lambda d: d["buses"][0]["modules"][0].setdefault("programs", {}).update({7: {"position": 1.0,
                                                                                            "speed": 0.3}}))
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-a-left", *APPLY).code == 0
    for _ in range(2):
        # no changes: no snapshot
        assert run_cli(capsys, "apply", plant.path, "--module", "booth-a-left", *APPLY).code == 0
    runs = journals(tmp_path)
    taken = snapshots(tmp_path)
    assert len(runs) == 5 and len(taken) == 3

    pruned = run_cli(capsys, "records", "prune", plant.path, "--older-than", "1", "--json")
    assert json.loads(pruned.out)["removed"] == []
    # an untold axis release recorded by the first run (as an apply killed after its 10h leaves it)
    bus = plant.plant.buses[0]
    pending_records.Releases("apply", runs[0]).record(line_keys(bus.port), bus.name, 1, "booth-a-left")
    kept_back = json.loads(run_cli(capsys, "records", "prune", plant.path, "--keep", "0", "--json").out)
    assert [r["journal"] for r in kept_back["removed"]] == [str(runs[3])]
    assert not runs[3].exists() and runs[0].exists() and taken[0].exists()
    why = {k["journal"]: k["why"] for k in kept_back["kept"]}
    assert "axis release" in why[str(runs[0])] and "newest run" in why[str(runs[4])]
    assert "newest snapshot" in why[str(runs[1])] and "newest snapshot" in why[str(runs[2])]

    pending_records.cleared(pending_records.of_line(line_keys(bus.port)))
    pruned = run_cli(capsys, "records", "prune", plant.path, "--keep", "0", "--json")
    assert pruned.code == 0, pruned.err
    assert [r["journal"] for r in json.loads(pruned.out)["removed"]] == [str(runs[0])]
    assert not runs[0].exists() and not taken[0].exists()
    # newest of booth-b, of booth-a
    assert runs[1].exists() and taken[1].exists() and runs[2].exists() and taken[2].exists()
    assert runs[4].exists()
    assert run_cli(capsys, "records", "verify", plant.path).code == 0  # what prune leaves verifies


def test_refresh_only_writes_json_markdown_and_a_file(plant, capsys, tmp_path):
    out = tmp_path / "drift.json"
    as_json = run_cli(capsys, "plan", plant.path, "--refresh-only", "--json", "--out", out)
    assert as_json.code == 0, as_json.err
    document = json.loads(as_json.out)
    assert document == json.loads(out.read_text())
    assert (document["format"] == "prc3cfg-drift/1" and document["plant"] == "demo-line"
            and document["modules"] == 6)
    assert {(d["bus"], d["name"]) for d in document["drifted"]} >= {("booth-a", "booth-a-left")}
    assert all(d["differences"] for d in document["drifted"])
    markdown = run_cli(capsys, "plan", plant.path, "--refresh-only", "--markdown")
    assert (markdown.code == 0 and markdown.out.startswith("<!-- prc3cfg-drift -->")
            and "booth-a-left" in markdown.out)
    plain = run_cli(capsys, "plan", plant.path, "--refresh-only", "--out", out, "--detailed-exitcode")
    assert (plain.code == 2 and "drifted from the plant file" in plain.out
            and f"Drift written to {out}" in plain.out)
    assert json.loads(out.read_text()) == document


def test_git_absent_is_said(plant, capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path / "no-bin"))
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-a-left", *APPLY).code == 0
    said = records_of(journals(tmp_path)[-1])[0]["plant"]["git"]
    assert (said["commit"] is None and said["clean"] is None and "git" in said["said"]
            and "not found" in said["said"])


def test_records_verify_of_nothing_says_so(tmp_path, capsys):
    (tmp_path / "plant.yaml").write_text("plant: x\n")
    result = run_cli(capsys, "records", "verify", tmp_path / "nothing.jsonl")
    assert result.code == 1 and "nothing.jsonl" in result.err
    assert os.path.exists(tmp_path / "plant.yaml")


def test_adopt_leaves_a_journal_saying_who_adopted_what_and_why(plant, capsys, tmp_path):
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-a-left", *APPLY).code == 0
    plant.emulators["booth-a"].teach_in(1, 2, 160)
    before = sha256(plant.path)
    result = run_cli(capsys, "adopt", plant.path, "--module", "booth-a-left", "--auto-approve", "--reason",
                     "taught on the floor")
    assert result.code == 0, result.err
    applied, journal = journals(tmp_path)
    header, *rest = records_of(journal)
    assert header["command"] == "adopt" and header["reason"] == "taught on the floor"
    assert header["plant"]["sha256"] == before and "adopt" in header["argv"]
    adopt, adopted = (r for r in rest if r["event"] in ("adopt", "adopted"))
    assert adopt["buses"] == ["booth-a"] and adopt["values"]
    assert adopted == adopted | {"written": True, "sha256": sha256(plant.path)}
    last = hashlib.sha256(applied.read_bytes().splitlines()[-1]).hexdigest()
    assert header["previous"] == {"journal": applied.name, "lines": len(records_of(applied)),
                                  "sha256": last}  # it follows the apply's journal
    _, run = json.loads(run_cli(capsys, "records", "list", plant.path, "--json").out)
    assert (run["command"] == "adopt" and run["result"] == "adopted" and run["lines"] == ["booth-a"]
            and run["snapshot"] is None)
    assert run_cli(capsys, "records", "verify", plant.path).code == 0


def test_a_run_follows_the_last_line_of_the_journal_before_it(plant, capsys, tmp_path):
    """The last record of a journal has no record after it: the next run's header covers it."""
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-a-left", *APPLY).code == 0
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-a-left", *APPLY).code == 0
    first, _ = journals(tmp_path)
    lines = first.read_bytes().splitlines(keepends=True)
    lines[-1] = lines[-1].replace(b"{", b"{ ", 1)
    first.write_bytes(b"".join(lines))
    found = run_cli(capsys, "records", "verify", plant.path)
    assert found.code == 1 and f"{first}:{len(lines)}:" in found.err, found.err


def test_drift_in_markdown_is_inert_and_fits():
    """A hostile module name in the drift comment: no mention, link or HTML is live; a long drift is cut with
    a count."""
    from prc3cfg.core.render import Drift, drift_json, drift_markdown

    hostile = Drift("bus-<b>", 1, "@someone [x](https://evil.example) <img src=x>",
                    ("program 1 position 1.000 m → 1.100 m",))
    text = drift_markdown(drift_json("p`lant", [hostile], 1))
    assert "@someone" not in text and "](https" not in text and "<img" not in text and "<b>" not in text
    many = [Drift("b", n % 30 + 1, f"m{n}",
                  tuple(f"program {p} position 1.000 m → 1.100 m" for p in range(1, 65))) for n in range(60)]
    cut = drift_markdown(drift_json("plant", many, 60), max_chars=5000)
    assert len(cut) <= 5000 and cut.rstrip().endswith("that drifted: see the drift file.")


def chained(*records: dict) -> bytes:
    """Records as a journal writes them: each line's `prev` the SHA-256 of the line before."""
    lines, prev = [], None
    for record in records:
        line = json.dumps({**record, "prev": prev}).encode()
        lines.append(line)
        prev = hashlib.sha256(line).hexdigest()
    return b"".join(line + b"\n" for line in lines)


GOOD = chained({"event": "header"}, {"event": "request", "n": 1}, {"event": "exchange", "n": 2},
               {"event": "result", "n": 3})
LINES = GOOD.splitlines(keepends=True)


@pytest.mark.parametrize(("data", "problem"), [
    (GOOD, None),
    (LINES[0] + LINES[1] + LINES[2].replace(b'"n": 2', b'"n": 5') + LINES[3], 3),  # an edited record
    (LINES[0] + LINES[1] + LINES[3], 2),  # a record removed
    (LINES[0] + LINES[1] + LINES[1] + LINES[2] + LINES[3], 2),  # a record inserted (a copy)
    (LINES[0] + LINES[1] + b"not json\n" + LINES[3], 3),
    (GOOD[:-1], None),  # cut short (a full disk, a kill): the last record left out, the rest whole
    (LINES[1] + LINES[2], 1),  # no header
    (b"", None),  # empty: no line, the file itself
    (b'{"event": "apply"}\n{"event": "request"}\n', None),  # before headers: unchained, not refused
], ids=["good", "edited", "removed", "inserted", "not-json", "cut-short", "no-header", "empty",
        "before-headers"])
def test_the_chain_names_the_first_record_that_does_not_match(tmp_path, data, problem):
    from prc3cfg.shell.audit import check_journal

    journal = tmp_path / "j.jsonl"
    journal.write_bytes(data)
    checked = check_journal(journal)
    if data == b"":
        assert checked.problem is not None and checked.problem.where == str(journal)
    elif problem is None:
        assert checked.problem is None and checked.chained == data.startswith(b'{"event": "header"')
        assert checked.cut == (not data.endswith(b"\n")) and len(checked.records) == data.count(b"\n")
    else:
        assert (checked.problem is not None
                and checked.problem.where == f"{journal}:{problem}"), checked.problem


@pytest.mark.parametrize("name", ["../plant.yaml", "/etc/passwd", "a/b.json", "..", "", None, 7, "a\\b.json"])
def test_a_record_that_names_a_path_is_not_followed_by_prune(plant, capsys, tmp_path, name):
    """prune removes what records name: a journal edited to name a file outside snapshots/ (and
    its chain made whole again) does not verify — prune removes nothing, and names it."""
    from prc3cfg.shell.audit import file_name

    assert file_name(name) is None
    victim = tmp_path / "plant.yaml"
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-a-left", *APPLY).code == 0
    journal, = journals(tmp_path)
    records = [{k: v for k, v in r.items() if k != "prev"} for r in records_of(journal)]
    for record in records:
        if record["event"] == "snapshot":
            record["path"] = name
    journal.write_bytes(chained(*records))
    # the newest run: not this one
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-a-left", *APPLY).code == 0
    refused = run_cli(capsys, "records", "prune", plant.path, "--keep", "0")
    assert refused.code == 1 and f"{journal}:" in refused.err and "nothing was removed" in refused.err
    assert victim.exists() and journal.exists()


def test_a_journal_the_disk_cut_short_still_verifies_and_restores(plant, capsys, tmp_path):
    """A full disk (or a kill) leaves a journal whose last record has no end of line: the records
    before it stand — verify says so in a note, and its snapshot restores (what the error of such an
    apply tells the operator to do)."""
    assert run_cli(capsys, "apply", plant.path, "--module", "booth-a-left", *APPLY).code == 0
    (journal,) = journals(tmp_path)
    journal.write_bytes(journal.read_bytes() + b'{"time": "2026-')
    checked = run_cli(capsys, "records", "verify", plant.path)
    assert checked.code == 0 and f"note: {journal}:" in checked.err and "cut short" in checked.err
    restored = run_cli(capsys, "restore", snapshots(tmp_path)[0], *APPLY)
    assert restored.code == 0, restored.err


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="needs root to give the folder to another user")
def test_git_refusing_a_repository_of_another_owner_is_said(tmp_path):
    """git's safe.directory: a work tree another user owns is not read — the header says git's reason."""
    from prc3cfg.shell.records import git_state

    repo = tmp_path / "theirs"
    repo.mkdir()
    (repo / "plant.yaml").write_text("plant: x\n")
    git(repo, "init", "-q")
    subprocess.run(["chown", "-R", "1001:1001", str(repo)], check=True)
    said = git_state(repo / "plant.yaml")
    assert said["commit"] is None and said["clean"] is None and "dubious ownership" in said["said"], said
