"""`--json` on every command (issue 42, item 4): one family of documents, `prc3cfg-KIND/1`, each checked
against `schemas/KIND.schema.json` — the events of `apply`, `restore` and `adopt` line by line, drift as field
/ before / after, and the documents of `plan`, `scan`, `doctor`, `import`, `records verify` and `validate`.

Against real emulators (tests/emulated.py); the stream a CI step follows is read from a real process.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import jsonschema
import pytest
from emulated import emulated_plant, run_cli, signal_once_every_line_writes

ROOT = Path(__file__).resolve().parents[1]
SCHEMAS = ROOT / "schemas"
#: The environment of a CI step: Python buffers a pipe's writes (what PYTHONUNBUFFERED would hide).
BUFFERED = {name: value for name, value in os.environ.items() if name != "PYTHONUNBUFFERED"}


def schema(kind: str) -> jsonschema.Draft7Validator:
    text = (SCHEMAS / f"{kind}.schema.json").read_text(encoding="utf-8")
    return jsonschema.Draft7Validator(json.loads(text))


def valid(kind: str, document: object) -> object:
    """`document`, checked against its schema (and a `prc3cfg-KIND/1` document's format against the schema's
    kind; the lists and the one object printed before the family carry none)."""
    checker = schema(kind)
    checker.validate(document)
    if checker.schema["title"].startswith("prc3cfg-"):
        assert (isinstance(document, dict)
                and document["format"] == checker.schema["title"] == f"prc3cfg-{kind}/1")
    return document


def events(out: str) -> list[dict]:
    """The events of a stream: every line of stdout one JSON object, each valid, the plans in them too."""
    found = [json.loads(line) for line in out.splitlines()]
    # nothing on stdout but whole event lines
    assert found and "".join(f"{line}\n" for line in out.splitlines()) == out
    for event in found:
        valid("event", event)
        if event["event"] == "plan" and "plan" in event:
            valid("plan", event["plan"])
    return found


def kinds(found: list[dict]) -> list[str]:
    """The kinds of events in order, a run of progress events as one."""
    said = [event["event"] for event in found]
    return [kind for at, kind in enumerate(said) if kind != "progress" or at == 0
            or said[at - 1] != "progress"]


@pytest.fixture
def plant(tmp_path):
    with emulated_plant(tmp_path) as emulated:
        yield emulated


def test_every_schema_is_draft_7_and_named_for_its_format():
    files = sorted(SCHEMAS.glob("*.schema.json"))
    assert {path.name for path in files} >= {f"{k}.schema.json"
                                             for k in ("event", "plan", "drift", "scan", "doctor", "import",
                                                       "records-verify")}
    for path in files:
        document = json.loads(path.read_text(encoding="utf-8"))
        jsonschema.Draft7Validator.check_schema(document)
        kind = path.name.removesuffix(".schema.json")
        assert document["$id"] == (f"urn:prc3cfg:{kind}" if kind != "plant" else "urn:prc3cfg:plant-file")
    with pytest.raises(jsonschema.ValidationError):  # the check can fail
        valid("event", {"format": "prc3cfg-event/1", "event": "module", "command": "apply"})


def test_apply_json_is_a_stream_of_events_a_ci_step_reads_line_by_line(plant):
    """A real process, as a CI step runs it: stdout holds events only, in the order things happen, each
    valid."""
    done = subprocess.run([sys.executable, "-m", "prc3cfg", "apply", str(plant.path), "--json",
                           "--auto-approve", "--allow-axis-release"],
                          capture_output=True, text=True, encoding="utf-8",
                          env=os.environ | {"PYTHONPATH": str(ROOT)}, check=False)
    assert done.returncode == 0, done.stderr
    found = events(done.stdout)
    assert "Traceback" not in done.stderr
    order = kinds(found)
    assert order[0] == "progress" and order[-2:] == ["travel", "account"]
    assert order.index("plan") < order.index("question") < order.index("module")
    whole = [event for event in found if event["event"] == "plan" and event["whole"]]
    assert len(whole) == 1 and whole[0]["plan"]["message_count"] > 0
    questions = [(e["answer"], e["by"]) for e in found if e["event"] == "question"]
    assert questions == [("yes", "--allow-axis-release"), ("yes", "--auto-approve")]
    modules = [event for event in found if event["event"] == "module"]
    assert len(modules) == 6 and all(m["result"] == "verified" and m["read_back"] == "matches"
                                     and m["written"] for m in modules)
    assert {(t["bus"], t["name"]) for t in found[-2]["modules"]} == {(m["bus"], m["name"]) for m in modules}
    account = found[-1]
    assert (account["status"], account["exit"], account["modules"], account["written"]) == ("verified", 0, 6,
                                                                                            6)
    assert Path(account["snapshot"]).is_file() and plant.matches_plant()
    phases = [e["phase"] for e in found if e["event"] == "progress" and e["done"] == 0]
    assert phases == ["reading modules", "writing", "verifying"]

    again = run_in_process_events(plant.path, "--auto-approve")
    assert again[-1]["status"] == "nothing to do" and not [e for e in again
                                                           if e["event"] in ("module", "question")]


def test_each_event_is_on_the_pipe_as_it_happens(tmp_path, capsys):
    """The first frame on each line is held until the test has read the first event (the reading's progress,
    a short line) from the process's stdout: an event kept in a buffer until more come would never be read,
    and the frames would go out late."""
    seen, held, armed = threading.Event(), [], threading.Event()

    def hold_first_frame(frame, _):
        if armed.is_set() and len(held) < 2:
            held.append(seen.wait(timeout=60))
        return set()

    # a reply may be waited for 5 s, 6 times: the test reads the event while the frame is held, however busy
    # the machine
    with emulated_plant(tmp_path, timeout=5.0,
                        lossy={"booth-a": hold_first_frame, "booth-b": hold_first_frame}) as plant:
        armed.set()
        process = subprocess.Popen([sys.executable, "-m", "prc3cfg", "apply", str(plant.path), "--json",
                                    "--auto-approve", "--allow-axis-release"],
                                   stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                   text=True, encoding="utf-8",
                                   env=BUFFERED | {"PYTHONPATH": str(ROOT)})
        assert process.stdout is not None
        first = process.stdout.readline()
        seen.set()
        out, err = process.communicate(timeout=120)
    assert process.returncode == 0, err
    # the frames waited for the test, which had read the event while the process ran
    assert held == [True, True]
    assert json.loads(first)["event"] == "progress" and events(first + out)[-1]["status"] == "verified"


def test_an_interrupted_apply_ends_its_stream_with_every_module_and_its_account(tmp_path):
    """SIGINT once every line has begun to write (seen on the frame trace, a FIFO): the accounts of the
    modules, then `interrupted`, exit 130 — what the human account says, as events."""
    fifo = tmp_path / "trace.fifo"
    os.mkfifo(fifo)
    with emulated_plant(tmp_path, line_speed=True, timeout=0.5) as plant:
        process = subprocess.Popen([sys.executable, "-m", "prc3cfg", "apply", str(plant.path), "--json",
                                    "--auto-approve", "--allow-axis-release",
                                    "--trace", str(fifo)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                   text=True, encoding="utf-8",
                                   env=BUFFERED | {"PYTHONPATH": str(ROOT),
                                                   "PRC3CFG_LOCK_DIR": str(tmp_path / "locks")})
        with fifo.open() as trace:
            signal_once_every_line_writes(trace, process, plant.emulators, signal.SIGINT)
            out, err = process.communicate(timeout=60)
    found = events(out)
    assert process.returncode == 130 and err.splitlines()[-1] == "error: interrupted"
    account = found[-1]
    assert (account["status"], account["exit"], account["errors"]) == ("interrupted", 130, ["interrupted"])
    ran = [e for e in found if e["event"] == "module"]
    assert len(ran) == 6 and any(e["result"] == "failed" for e in ran) and all(e["text"] for e in ran)
    assert account["snapshot"] and account["written"] == sum(e["result"] == "verified" for e in ran)


def run_in_process_events(path: Path, *args: str) -> list[dict]:
    result = subprocess.run([sys.executable, "-m", "prc3cfg", "apply", str(path), "--json", *args],
                            capture_output=True, text=True,
                            encoding="utf-8", env=os.environ | {"PYTHONPATH": str(ROOT)},
                            check=False)
    return events(result.stdout)


@pytest.mark.parametrize("command", [["apply", "{plant}"], ["restore", "{snapshot}"], ["adopt", "{plant}"]])
def test_json_without_auto_approve_is_refused_in_one_line_before_the_line_is_used(plant, capsys, tmp_path,
                                                                                  command):
    args = [word.format(plant=plant.path, snapshot=tmp_path / "snapshot.json") for word in command]
    result = run_cli(capsys, *args, "--json", "--trace", tmp_path / "trace.txt")
    assert result.code == 64 and result.out == ""
    assert len(result.err.splitlines()) == 1 and "--json asks no question — pass --auto-approve" in result.err
    assert not (tmp_path / "trace.txt").exists()  # not a frame sent


def test_a_release_not_allowed_is_answered_no_and_the_account_says_refused(plant, capsys):
    result = run_cli(capsys, "apply", plant.path, "--json", "--auto-approve")
    found = events(result.out)
    assert result.code == 1 and len(result.problems) == 1 and "axis" in result.err
    refusal = [e for e in found if e["event"] == "question"]
    assert [(e["answer"], e["by"]) for e in refusal] == [("no", "no --allow-axis-release")]
    assert (found[-1]["status"] == "refused" and found[-1]["exit"] == 1
            and found[-1]["errors"] == [result.err.removeprefix("error: ").strip()])
    assert not [e for e in found if e["event"] == "module"] and not plant.matches_plant()


def test_a_plant_file_refused_ends_the_stream_with_its_account(plant, capsys):
    plant.path.write_text(plant.path.read_text(encoding="utf-8").replace("max_speed: 0.5\n",
                                                                         "max_speed: 9.5\n"),
                          encoding="utf-8")
    result = run_cli(capsys, "apply", plant.path, "--json", "--auto-approve")
    (account,) = events(result.out)
    assert result.code == 1 and account["status"] == "refused" and account["exit"] == 1
    assert ([f"error: {line}" for line in account["errors"]] == result.problems
            and "max_speed 9.5 m/s is out of range" in result.err)


def test_a_reviewed_plan_file_is_applied_with_json_without_auto_approve(plant, capsys, tmp_path):
    assert run_cli(capsys, "plan", plant.path, "--out", tmp_path / "plan.json").code == 0
    result = run_cli(capsys, "apply", "--plan", tmp_path / "plan.json", "--json", "--allow-axis-release")
    found = events(result.out)
    assert result.code == 0, result.err
    assert ("yes", f"--plan {tmp_path / 'plan.json'}") in [(e["answer"], e["by"]) for e in found
                                                           if e["event"] == "question"]
    assert found[-1]["status"] == "verified" and plant.matches_plant()


def test_restore_json_streams_its_events_and_ends_in_its_account(plant, capsys):
    applied = run_cli(capsys, "apply", plant.path, "--json", "--auto-approve", "--allow-axis-release")
    snapshot = events(applied.out)[-1]["snapshot"]
    result = run_cli(capsys, "restore", snapshot, "--json", "--auto-approve", "--allow-axis-release")
    found = events(result.out)
    assert result.code == 0, result.err
    assert ({e["command"] for e in found} == {"restore"} and found[-1]["status"] == "verified"
            and found[-1]["written"] == 6)
    assert not plant.matches_plant()  # back to the factory's


def test_drift_json_gives_each_difference_as_field_before_after(plant, capsys):
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    bus = plant.plant.buses[0]
    module = bus.modules[0]
    before = module.desired_image().known(1).P
    plant.emulators[bus.name].teach_in(module.address, 1, before + 25)
    result = run_cli(capsys, "plan", plant.path, "--refresh-only", "--json")
    document = valid("drift", json.loads(result.out))
    assert result.code == 0, result.err
    (drifted,) = document["drifted"]
    (change,) = drifted["changes"]
    assert (change["program"], change["field"], change["before"], change["after"]) == (1, "P", before,
                                                                                       before + 25)
    assert drifted["differences"] == [change["text"]] and change["text"].startswith("program 1 position")


def test_adopt_json_says_what_it_adopts_and_writes_it(plant, capsys):
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    bus, module = plant.plant.buses[0], plant.plant.buses[0].modules[0]
    plant.emulators[bus.name].teach_in(module.address, 1, module.desired_image().known(1).P + 25)
    checked = run_cli(capsys, "adopt", plant.path, "--json", "--check")
    found = events(checked.out)
    assert checked.code == 2 and kinds(found)[-2:] == ["plan", "account"] and found[-1]["status"] == "drift"
    (value,) = found[-2]["adopted"]
    assert value["modules"] == [f"{bus.name}/{module.name}"] and found[-2]["diff"].startswith("---")
    adopted = run_cli(capsys, "adopt", plant.path, "--json", "--auto-approve")
    found = events(adopted.out)
    assert adopted.code == 0, adopted.err
    assert [e["event"] for e in found if e["event"] != "progress"] == ["plan", "question", "account"]
    assert found[-1]["status"] == "adopted" and found[-1]["written"] == 1
    assert events(run_cli(capsys, "adopt", plant.path, "--json", "--check").out)[-1]["status"] == "no drift"


def test_every_other_command_prints_a_document_its_schema_takes(plant, capsys, tmp_path):
    port = plant.plant.buses[0].port
    plan = run_cli(capsys, "plan", plant.path, "--json", "--out", tmp_path / "plan.json")
    saved = json.loads((tmp_path / "plan.json").read_text(encoding="utf-8"))
    assert plan.code == 0 and valid("plan", json.loads(plan.out)) == valid("plan", saved)
    shown = run_cli(capsys, "show", tmp_path / "plan.json", "--json")
    assert shown.code == 0, shown.err
    buses = valid("plan", json.loads(shown.out))["buses"]
    # show's verdict
    reviews = [m.pop("review") for bus in buses for m in bus["modules"]]
    assert reviews == ["as written"] * len(plant.plant.modules())
    assert buses == json.loads(plan.out)["buses"]

    # import and doctor: no scan of 1..30
    addresses = ",".join(str(m.address) for m in plant.plant.buses[0].modules)
    # the silent addresses: 50 ms each, twice
    scan = run_cli(capsys, "scan", "--port", port, "--timeout", "50ms", "--json")
    assert scan.code == 0, scan.err
    scanned = valid("scan", json.loads(scan.out))["modules"]
    assert [m["address"] for m in scanned] == [m.address for m in plant.plant.buses[0].modules]

    doctor = run_cli(capsys, "doctor", "--port", port, "--modules", addresses, "--exchanges", "2", "--json")
    assert doctor.code == 0, doctor.err
    found = valid("doctor", json.loads(doctor.out))
    assert found["plant_keys"]["framing"] == "crc16" and all(m["exchanges"] == 2 for m in found["modules"])

    imported = run_cli(capsys, "import", "--port", port, "--modules", addresses, "--json")
    document = valid("import", json.loads(imported.out))
    assert (imported.code == 0 and document["modules"] == len(plant.plant.buses[0].modules)
            and "plant: imported" in document["plant_file"])
    written = run_cli(capsys, "import", "--port", port, "--modules", addresses, "--json", "--out",
                      tmp_path / "imported.yaml")
    document = valid("import", json.loads(written.out))
    assert (document["plant_file"] is None
            and "\nplant: imported\n" in (tmp_path / "imported.yaml").read_text(encoding="utf-8"))

    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    verified = run_cli(capsys, "records", "verify", plant.path, "--json")
    assert verified.code == 0 and valid("records-verify", json.loads(verified.out))["verified"]

    listed = run_cli(capsys, "records", "list", plant.path, "--json")
    assert (listed.code == 0
            and [run["command"] for run in valid("records-list", json.loads(listed.out))] == ["apply"])
    pruned = run_cli(capsys, "records", "prune", plant.path, "--keep", "1", "--dry-run", "--json")
    assert pruned.code == 0 and valid("records-prune", json.loads(pruned.out)) == {"removed": [], "kept": []}
    read = run_cli(capsys, "read", plant.path, "--json")
    assert read.code == 0 and len(valid("read", json.loads(read.out))) == 6
    ports = run_cli(capsys, "ports", "--json")
    # a machine without ports says so on stderr
    assert ports.code in (0, 1) and valid("ports", json.loads(ports.out or "[]")) is not None

    assert run_cli(capsys, "validate", plant.path, "--json").out == run_cli(capsys, "validate", plant.path,
                                                                            "--format", "json").out
    broken = tmp_path / "broken.yaml"
    broken.write_text(plant.path.read_text(encoding="utf-8").replace("plant: demo-line", "plant: [demo"),
                      encoding="utf-8")
    refused = run_cli(capsys, "validate", broken, "--json")
    assert refused.code == 1 and valid("validate", json.loads(refused.out))
    assert run_cli(capsys, "validate", broken, "--json", "--format", "github").code == 64


def test_a_broken_record_is_a_problem_in_the_document_and_exit_1(plant, capsys):
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    (journal,) = (plant.path.parent / ".prc3cfg" / "journal").glob("*.jsonl")
    journal.write_text(journal.read_text(encoding="utf-8").replace('"apply"', '"apply "', 1),
                       encoding="utf-8")
    result = run_cli(capsys, "records", "verify", plant.path, "--json")
    document = valid("records-verify", json.loads(result.out))
    assert result.code == 1 and not document["verified"] and document["problems"]
    assert [f"error: {line}" for line in document["problems"]] == result.problems


def test_an_event_or_a_document_is_printed_in_ascii_with_every_other_character_escaped(capsys):
    """A C1 control, a line separator or a letter in what a stream or a document carries (another user's
    record in a travel event, a journal's text in records verify) is a JSON escape on stdout: the same value
    to a reader, no control to a terminal that shows the stream, and any pipe's encoding carries it."""
    from prc3cfg.cli.common import print_document
    from prc3cfg.cli.stream import Stream

    said = "bob\u009b2J\u2028Jürgen"
    Stream("apply").event("travel", modules=[{"bus": said, "name": said, "released": "possibly"}],
                          text=[said])
    print_document({"format": "prc3cfg-scan/1", "port": said})
    out = capsys.readouterr().out
    assert out.isascii() and "\\u009b" in out and "\\u2028" in out
    event, document = json.loads(out.splitlines()[0]), json.loads("\n".join(out.splitlines()[1:]))
    assert event["modules"][0]["name"] == said and document["port"] == said
