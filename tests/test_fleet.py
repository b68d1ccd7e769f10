"""Lines as a fleet (issue 44, item 3): the fleet file, `prc3cfg fleet matrix` and `fleet summary`, and
docs/fleet.md's workflow — linted by actionlint and zizmor as tests/test_ci_recipe.py lints docs/ci.md's, and
run job by job with that file's runner (`Plant`, the `gh` stand-in, real git, emulators behind socket://) over
three lines, one of them in a deny window of the plant's policy (`PRC3CFG_POLICY_NOW`): two are applied and
verified on their emulators, the third is reported as waiting in the fleet summary the merged pull request
gets.

What GitHub alone does is not here: the matrix is taken from the `lines` job's output and each entry run in
turn; an environment's required reviewers are GitHub's (the job runs as approved); `gh run download RUN_ID`
takes the artifacts of every run the test made (the stand-in keeps no runs apart).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import jsonschema
import pytest
import yaml
from emulated import DEMO, run_cli
from hypothesis import given, settings
from hypothesis import strategies as st
from test_ci_recipe import Plant, actionlint, token_only_where_github_is_called, zizmor_findings
from test_policy import MONDAY_MORNING
from test_policy import SHIFT_ON_BOOTH_B as SHIFT  # the paint shop's production shift, on booth-b alone
from tools import needs

from prc3cfg.core import fleet as lines_of
from prc3cfg.plant.fleet import fleet_schema_text
from prc3cfg.shell.testing import emulate

ROOT = Path(__file__).resolve().parents[1]
PAGE = (ROOT / "docs" / "fleet.md").read_text()
BLOCKS = re.findall(r"```yaml\n(.*?)```", PAGE, re.S)
WORKFLOW_TEXT = next(block for block in BLOCKS if block.startswith("name: fleet"))
WORKFLOW = yaml.safe_load(WORKFLOW_TEXT)
EXAMPLE = next(block for block in BLOCKS if block.startswith("format: prc3cfg-fleet/1"))
SUMMARY = json.loads((ROOT / "schemas" / "fleet-summary.schema.json").read_text())
# checked once: jsonschema.validate checks the schema on every call
SUMMARY_CHECK = jsonschema.Draft7Validator(SUMMARY)

FLEET = """format: prc3cfg-fleet/1
plants:
  - plant: plants/paint-shop.yaml
    lines:
      - {bus: booth-a, runner: line-booth-a, environment: booth-a}
      - {bus: booth-b, runner: line-booth-b}
  - plant: plants/washer.yaml
    lines:
      - {bus: washer, runner: line-washer}
"""


def washer(source: Path) -> Path:
    """A second plant file: the demo's booth-a alone, as the bus `washer` with modules of its own names."""
    document = yaml.safe_load(DEMO.read_text())
    bus = document["buses"][0]
    bus["name"] = "washer"
    for module in bus["modules"]:
        module["name"] = module["name"].replace("booth-a", "washer")
    document["buses"] = [bus]
    document["plant"] = "washer"
    source.write_text(yaml.safe_dump(document, sort_keys=False))
    return source


def repository(folder: Path) -> Path:
    """A fleet's files in `folder` (its ports emulator://, for what needs no bus): the fleet file, two plant
    files naming one policy."""
    (folder / "plants").mkdir(parents=True)
    (folder / "plants" / "paint-shop.yaml").write_text(DEMO.read_text() + "\npolicy: rules.yaml\n")
    (folder / "plants" / "washer.yaml").write_text(washer(folder / "w.yaml").read_text()
                                                   + "\npolicy: rules.yaml\n")
    (folder / "plants" / "rules.yaml").write_text(SHIFT)
    (folder / "fleet.yaml").write_text(FLEET)
    return folder / "fleet.yaml"


@pytest.fixture
def fleet(tmp_path, monkeypatch):
    path = repository(tmp_path)
    monkeypatch.chdir(tmp_path)  # the repository's top, where `git diff --name-only`'s paths start
    return path.name


def matrix(capsys, *args: str) -> list[dict[str, str]]:
    result = run_cli(capsys, "fleet", "matrix", *args)
    assert result.code == 0, result.err
    assert result.out.count("\n") == 1  # one line: $GITHUB_OUTPUT takes it
    return json.loads(result.out)["include"]


# -- the fleet file and the matrix
# -------------------------------------------------------------------------------------


def test_the_matrix_has_one_entry_per_line_with_its_runner_environment_group_and_modules(fleet, capsys):
    entries = matrix(capsys, fleet)
    assert [(e["line"], e["runner"], e["environment"]) for e in entries] == [
        ("plants/paint-shop.yaml:booth-a", "line-booth-a", "booth-a"), ("plants/paint-shop.yaml:booth-b",
                                                                        "line-booth-b", "booth-b"),
        ("plants/washer.yaml:washer", "line-washer", "washer")]
    assert ([e["group"] for e in entries] == [f"prc3cfg-line {e['line']}" for e in entries]
            and len({e["id"] for e in entries}) == 3)
    assert entries[0]["modules"].split("\n") == ["booth-a-left", "booth-a-right", "booth-a-top"]
    assert {e["policy"] for e in entries} == {"plants/rules.yaml"}


@pytest.mark.parametrize(("changed", "lines"), [
    (["plants/washer.yaml"], ["plants/washer.yaml:washer"]),
    (["plants/paint-shop.yaml", "README.md"],
     ["plants/paint-shop.yaml:booth-a", "plants/paint-shop.yaml:booth-b"]),
    (["plants/rules.yaml"],
     ["plants/paint-shop.yaml:booth-a", "plants/paint-shop.yaml:booth-b", "plants/washer.yaml:washer"]),
    (["./plants/../plants/washer.yaml"], ["plants/washer.yaml:washer"]),
    (["README.md"], []),
    ([], []),
])
def test_a_change_selects_the_lines_of_its_plant_files_and_every_line_its_policy_rules(fleet, capsys, changed,
                                                                                       lines):
    assert [e["line"] for e in matrix(capsys, fleet, "--changed", "--", *changed)] == lines


def test_changed_files_without_changed_are_refused_in_one_line(fleet, capsys):
    result = run_cli(capsys, "fleet", "matrix", fleet, "plants/washer.yaml")
    assert (result.code == 1
            and result.err == "error: prc3cfg fleet matrix: plants/washer.yaml — give --changed before the "
                              "changed files\n")


@pytest.mark.parametrize(("edit", "expected"), [
    (lambda t: t.replace("bus: booth-b", "bus: booth-c"),
     "fleet.yaml:6:15: bus 'booth-c' is not in plants/paint-shop.yaml — it has booth-a, booth-b"),
    (lambda t: t.replace(", runner: line-washer", ""),
     "fleet.yaml:9:9: 'runner' is missing — see docs/fleet.md"),
    (lambda t: t.replace("{bus: booth-b, runner: line-booth-b}",
                         "{bus: booth-b, runner: line-booth-b, label: x}"),
     "fleet.yaml:6:46: unknown key 'label' — see schemas/fleet.schema.json"),
    (lambda t: t.replace("prc3cfg-fleet/1", "prc3cfg-fleet/2"),
     "fleet.yaml:1:9: 'format' is 'prc3cfg-fleet/2' — it is 'prc3cfg-fleet/1'"),
    (lambda t: t.replace("bus: booth-b", "bus: booth-a"),
     "fleet.yaml:6:15: line plants/paint-shop.yaml:booth-a is named twice"),
    (lambda t: t + "  - plant: plants/none.yaml\n    lines: [{bus: x, runner: r}]\n", "plants/none.yaml: "),
    (lambda t: t.replace("lines:\n      - {bus: washer, runner: line-washer}", "lines: []"),
     "fleet.yaml:8:12: 'lines' is not valid"),
])
def test_a_mistake_in_the_fleet_file_is_one_line_at_its_file_line_and_column(fleet, capsys, edit, expected):
    Path(fleet).write_text(edit(FLEET))
    for command in (("matrix", fleet), ("summary", fleet, "none.json")):
        result = run_cli(capsys, "fleet", *command)
        assert result.code == 1 and len(result.problems) == 1, result.err
        assert result.problems[0].startswith(f"error: {expected}"), result.err


def test_the_fleet_schema_in_schemas_is_the_one_the_models_make_and_the_docs_example_is_valid(tmp_path):
    assert (ROOT / "schemas" / "fleet.schema.json").read_text(encoding="utf-8") == fleet_schema_text()
    schema = json.loads(fleet_schema_text())
    jsonschema.validate(yaml.safe_load(EXAMPLE), schema)
    jsonschema.validate(yaml.safe_load(FLEET), schema)
    with pytest.raises(jsonschema.ValidationError):  # the check can fail
        jsonschema.validate(yaml.safe_load(FLEET.replace("runner:", "label:")), schema)


# -- the summary
# -------------------------------------------------------------------------------------------------------


def status_of(capsys, plant: str, folder: Path, bus: str | None = None, waiting: str | None = None) -> Path:
    """`prc3cfg status PLANT --json` (records only: no bus is opened), kept as FOLDER/status.json (only
    `bus`'s line, as the workflow's jq keeps it), and a waiting.txt beside it."""
    result = run_cli(capsys, "status", plant, "--json")
    assert result.code == 0, result.err
    document = json.loads(result.out)
    if bus is not None:
        document["lines"] = [line for line in document["lines"] if line["bus"] == bus]
    folder.mkdir(parents=True)
    (folder / "status.json").write_text(json.dumps(document))
    if waiting is not None:
        (folder / "waiting.txt").write_text(waiting)
    return folder / "status.json"


def test_the_summary_has_a_row_per_line_and_says_which_waits_for_a_window(fleet, capsys, tmp_path):
    statuses = [status_of(capsys, "plants/paint-shop.yaml", tmp_path / "a", "booth-a"),
                status_of(capsys, "plants/paint-shop.yaml", tmp_path / "b", "booth-b",
                          "rules.yaml:3:5: soft: bus booth-b: deny window "
                          "'production' is open until 2026-11-30 16:00 CET\n")]
    result = run_cli(capsys, "fleet", "summary", fleet, *statuses)
    assert result.code == 0, result.err
    rows = [line for line in result.out.splitlines() if line.startswith("| plants/")]
    assert rows == [
        "| plants/paint-shop.yaml:booth-a | 3 | MAINTENANCE_REQUIRED | none | none | never | done |",
        "| plants/paint-shop.yaml:booth-b | 3 | MAINTENANCE_REQUIRED | none | none | never | waiting: "
        "rules.yaml:3:5: soft: bus booth-b: "
        "deny window 'production' is open until 2026-11-30 16:00 CET |",
        "| plants/washer.yaml:washer | | | | | | not in this run |"]
    document = json.loads(run_cli(capsys, "fleet", "summary", fleet, *statuses, "--json").out)
    SUMMARY_CHECK.validate(document)
    assert (document["format"] == SUMMARY["title"]
            and [row["reported"] for row in document["lines"]] == [True, True, False])


def test_a_status_of_no_line_or_of_a_line_twice_is_refused_in_one_line(fleet, capsys, tmp_path):
    whole = status_of(capsys, "plants/paint-shop.yaml", tmp_path / "whole")
    again = status_of(capsys, "plants/paint-shop.yaml", tmp_path / "again", "booth-b")
    result = run_cli(capsys, "fleet", "summary", fleet, whole, again)
    assert (result.code == 1
            and result.problems == [f"error: {again}: line plants/paint-shop.yaml:booth-b is in "
                                    f"{whole} too — "
                                                    "give each line's status once"])
    Path(fleet).write_text(FLEET.replace("      - {bus: booth-b, runner: line-booth-b}\n", ""))
    result = run_cli(capsys, "fleet", "summary", fleet, whole)
    assert (result.code == 1
            and result.problems == [f"error: {whole}: bus booth-b of plants/paint-shop.yaml is not a line "
                                    f"of {fleet} — "
                                                    "give the status of the fleet's lines"])
    (tmp_path / "plan.json").write_text('{"format": "prc3cfg-plan/1"}')
    result = run_cli(capsys, "fleet", "summary", fleet, tmp_path / "plan.json")
    assert (result.code == 1
            and result.problems == [f"error: {tmp_path / 'plan.json'}: not a prc3cfg-status/1 document — "
                                                    "give what prc3cfg status PLANT "
                                                    "--json printed"])


# -- the same, over random fleets (soak)
# -------------------------------------------------------------------------------

NAMES = st.text("abcdefgh-", min_size=1, max_size=4)


@st.composite
def fleets(draw):
    """Lines of 1–4 plant files with 1–3 buses each, some plant files naming one of two policies; a change of
    some of their files (and files of no line); the lines that report a status, some of them waiting."""
    plants = draw(st.lists(NAMES, min_size=1, max_size=4, unique=True))
    policies = {plant: draw(st.sampled_from([None, "plants/rules.yaml", "plants/freeze.yaml"]))
                for plant in plants}
    lines = [lines_of.FleetLine(f"plants/{plant}.yaml", bus, f"runner-{bus}", bus, (f"{bus}-1",),
                                policies[plant])
             for plant in plants for bus in draw(st.lists(NAMES, min_size=1, max_size=3, unique=True))]
    files = sorted({line.plant for line in lines} | {"plants/rules.yaml", "plants/freeze.yaml", "README.md"})
    changed = draw(st.lists(st.sampled_from(files), unique=True))
    reported = draw(st.lists(st.sampled_from(lines), unique=True)) if lines else []
    waiting = {line: draw(st.sampled_from([None, "window 'w' | open"])) for line in reported}
    return lines, changed, waiting


def check_consistent(lines: list[lines_of.FleetLine], changed: list[str],
                     waiting: dict[lines_of.FleetLine, str | None]) -> None:
    selected = lines_of.selected(lines, set(changed))
    expected = [line for line in lines if line.plant in changed or line.policy in changed]
    assert selected == expected  # every changed line, once, in the fleet's order
    entries = lines_of.matrix(selected)["include"]
    assert [e["line"] for e in entries] == [line.name for line in expected]
    assert len({e["group"] for e in entries}) == len(entries)
    status = {"health": "NORMAL",
              "modules": [{"name": "m", "drift_seen": False, "travel_pending": True, "last_failed": False,
                                               "last_verified": None}]}
    document = lines_of.summary(lines, {line: lines_of.LineStatus(status, why)
                                        for line, why in waiting.items()})
    SUMMARY_CHECK.validate(document)
    assert [row["line"] for row in document["lines"]] == [line.name for line in lines]  # a row per line
    assert [row["waiting"] for row in document["lines"]] == [waiting.get(line) for line in lines]
    rows = [row for row in lines_of.markdown(document).splitlines() if row.startswith("| ")
            and not row.startswith("| line |")]
    # a `|` in a cell stays in it
    assert len(rows) == len(lines) and all(len(re.split(r"(?<!\\)\|", row)) == 9 for row in rows)


@given(fleets())
@settings(max_examples=15)  # the fast tier's few; the soak tier's profile takes many
def test_matrix_and_summary_agree_with_the_fleet(case):
    check_consistent(*case)


@pytest.mark.soak
@given(fleets())
def test_matrix_and_summary_agree_with_the_fleet_soak(case):
    check_consistent(*case)


#: The addresses of the demo's first bus, which `written` gives every line.
ADDRESSES = [module["address"] for module in yaml.safe_load(DEMO.read_text())["buses"][0]["modules"]]


class Unshared(yaml.SafeDumper):
    """A value the document holds twice, written out twice: a plant file refuses aliases."""

    def ignore_aliases(self, data: object) -> bool:
        return True


def written(folder: Path, lines: list[lines_of.FleetLine]) -> None:
    """The fleet file and plant files of `lines` in `folder`: each plant file the demo's first bus once a
    line, renamed."""
    template = yaml.safe_load(DEMO.read_text())
    fleet: dict[str, list] = {}
    for line in lines:
        fleet.setdefault(line.plant, []).append({"bus": line.bus, "runner": line.runner})
    for plant, buses in fleet.items():
        document = dict(template, plant=Path(plant).stem, buses=[
            dict(template["buses"][0], name=bus["bus"], port=f"emulator://{Path(plant).stem}-{bus['bus']}",
                 modules=[dict(m, name=f"{bus['bus']}-{m['address']}")
                          for m in template["buses"][0]["modules"]]) for bus in buses])
        policy = next(line.policy for line in lines if line.plant == plant)
        if policy is not None:
            document["policy"] = Path(policy).name
        (folder / plant).parent.mkdir(parents=True, exist_ok=True)
        (folder / plant).write_text(yaml.dump(document, Dumper=Unshared, sort_keys=False))
    (folder / "fleet.yaml").write_text(yaml.safe_dump({"format": "prc3cfg-fleet/1", "plants": [
        {"plant": plant, "lines": buses} for plant, buses in fleet.items()]}))


@pytest.mark.soak
@given(fleets())
@settings(max_examples=12)  # two real processes each: about a second an example
def test_the_commands_select_and_summarise_random_fleets_as_the_fleet_file_says_soak(tmp_path_factory, case):
    """The same through real `prc3cfg fleet` processes, on fleet and plant files written to disk: every
    changed line selected once, a summary row per line, each reported line's waiting words in its row."""
    lines, changed, waiting = case
    # its modules as `written` names them, its policy beside its plant file
    def on_disk(line: lines_of.FleetLine) -> lines_of.FleetLine:
        return replace(line, modules=tuple(f"{line.bus}-{a}" for a in ADDRESSES), policy=line.policy
                       and f"plants/{Path(line.policy).name}")

    lines, waiting = [on_disk(line) for line in lines], {on_disk(line): why for line, why in waiting.items()}
    folder = tmp_path_factory.mktemp("fleet")
    written(folder, lines)
    run = {"cwd": folder, "capture_output": True, "text": True, "env": os.environ | {"PYTHONPATH": str(ROOT)}}
    done = subprocess.run([sys.executable, "-m", "prc3cfg", "fleet", "matrix", "fleet.yaml", "--changed",
                           "--", *changed], **run)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == lines_of.matrix(lines_of.selected(lines, set(changed)))
    statuses = []
    for n, line in enumerate(waiting):
        (folder / str(n)).mkdir()
        module = {"name": f"{line.bus}-1", "drift_seen": True, "travel_pending": False, "last_failed": False,
                  "last_verified": None}
        (folder / str(n) / "status.json").write_text(json.dumps({"format": "prc3cfg-status/1",
                                                                 "plant_file": line.plant,
                                                                 "lines": [{"bus": line.bus,
                                                                            "health": "NORMAL",
                                                                            "modules": [module]}]}))
        if waiting[line] is not None:
            (folder / str(n) / "waiting.txt").write_text(waiting[line])
        statuses.append(f"{n}/status.json")
    done = subprocess.run([sys.executable, "-m", "prc3cfg", "fleet", "summary", "fleet.yaml", *statuses,
                           "--json"], **run)
    if not statuses:
        assert done.returncode == 64  # STATUS_JSON… is required
        return
    assert done.returncode == 0, done.stderr
    rows = json.loads(done.stdout)["lines"]
    assert [row["line"] for row in rows] == [line.name for line in lines]
    assert [row["waiting"] for row in rows] == [waiting.get(line) for line in lines]
    assert [row["drift"] for row in rows] == [[f"{line.bus}-1"] if line in waiting else None
                                              for line in lines]


# -- the workflow
# ------------------------------------------------------------------------------------------------------


def test_the_fleet_workflow_passes_actionlint(tmp_path):
    workflow = tmp_path / "fleet.yml"
    workflow.write_text(WORKFLOW_TEXT)
    done = actionlint(workflow)
    assert done.returncode == 0, done.stdout + done.stderr
    workflow.write_text(WORKFLOW_TEXT.replace("fromJSON(needs.lines.outputs.matrix)",
                                              "fromJSON(needs.line.outputs.matrix)"))
    assert actionlint(workflow).returncode == 1  # it does look at what the jobs need


@pytest.mark.parametrize("persona", ["pedantic", "auditor"])
def test_the_fleet_workflow_passes_zizmor_and_what_it_ignores_is_the_design_with_its_reason(tmp_path,
                                                                                            persona):
    found = zizmor_findings(tmp_path, WORKFLOW_TEXT, "--persona", persona)
    assert found == [], json.dumps(found, indent=1)[:3000]
    ignored = sorted(f["ident"]
                     for f in zizmor_findings(tmp_path, WORKFLOW_TEXT, "--persona", persona, "--no-ignores"))
    assert ignored == ["dangerous-triggers"] + (["self-hosted-runner"] * 2 if persona == "auditor" else [])
    reasons = re.findall(r"# zizmor: ignore\[([a-z-]+)\](.*)", WORKFLOW_TEXT)
    assert sorted(rule for rule, _ in reasons) == ["dangerous-triggers"] + ["self-hosted-runner"] * 2
    assert all(len(reason.split()) >= 4 for _, reason in reasons), reasons
    kept = re.sub(r"\n +with:\n +persist-credentials: false   # main's[^\n]*", "", WORKFLOW_TEXT)
    assert kept != WORKFLOW_TEXT
    assert [f["ident"] for f in zizmor_findings(tmp_path, kept, "--persona", persona)] == ["artipacked"]


def test_each_line_job_is_on_its_runner_in_its_group_and_the_others_reach_no_line():
    jobs = WORKFLOW["jobs"]
    assert set(jobs) == {"lines", "plan", "comment", "apply", "summary"}
    for name, job in jobs.items():
        assert isinstance(job.get("timeout-minutes"), int) and 0 < job["timeout-minutes"] <= 60, name
        assert job["name"] and job["permissions"], name
        on_a_line = name in ("plan", "apply")
        assert job["runs-on"] == (["self-hosted", "${{ matrix.runner }}"] if on_a_line
                                  else "ubuntu-latest"), name
        assert job["concurrency"]["cancel-in-progress"] is False, name  # none cancelled midway
        assert (job["concurrency"]["group"] == "${{ matrix.group }}") == on_a_line, name
        if on_a_line:
            assert job["strategy"] == {"fail-fast": False,
                                       "matrix": "${{ fromJSON(needs.lines.outputs.matrix) }}"}, name
    assert jobs["apply"]["environment"] == "${{ matrix.environment }}"  # the line's required reviewers
    assert (jobs["plan"]["permissions"] == {"contents": "read"}
            and jobs["lines"]["permissions"] == {"contents": "read"})
    assert jobs["apply"]["permissions"] == {"contents": "read", "actions": "read", "pull-requests": "read"}
    # the pull request as data
    assert not [s for s in jobs["plan"]["steps"] if s.get("uses", "").startswith("actions/checkout")]
    token_only_where_github_is_called(WORKFLOW)


@pytest.fixture
def three_lines(tmp_path):
    """The fleet's repository with its two plant files on emulators (three lines), the policy's window shut on
    booth-b."""
    sources = repository(tmp_path / "sources")
    (tmp_path / "paint-shop").mkdir()
    (tmp_path / "washer").mkdir()
    with emulate(sources.parent / "plants" / "paint-shop.yaml", tmp_path / "paint-shop",
                 timeout=0.1) as paint_shop, \
         emulate(sources.parent / "plants" / "washer.yaml", tmp_path / "washer",
                 timeout=0.1) as washer_line:
        files = {"fleet.yaml": FLEET, "plants/paint-shop.yaml": paint_shop.path.read_text(),
                 "plants/washer.yaml": washer_line.path.read_text(),
                 "plants/rules.yaml": "format: prc3cfg-policy/1\n"}
        plant = Plant(tmp_path, paint_shop, files=files, workflow=WORKFLOW)
        plant.env["PRC3CFG_POLICY_NOW"] = MONDAY_MORNING  # in the paint shop's shift
        yield plant, paint_shop, washer_line


def run_matrix(plant: Plant, job: str, event: dict[str, object], lines: object) -> dict[str, object]:
    """Every entry of the job's matrix (the `lines` job's output), each on its runner, in turn."""
    done = {}
    for entry in json.loads(lines.outputs["matrix"])["include"]:
        ran = plant.run(job, event, matrix=entry, needs={"lines": lines})
        assert ran.labels == ["self-hosted", entry["runner"]]
        done[entry["bus"]] = ran
    return done


@needs("jq")
def test_a_merge_over_three_lines_applies_two_and_the_one_in_its_window_waits(three_lines):
    plant, paint_shop, washer_line = three_lines
    factory = paint_shop.images()

    def shift(document: dict) -> None:  # the change: the policy, which every line's plant file names
        document.update(yaml.safe_load(SHIFT))

    event = plant.pull_request(shift, file="plants/rules.yaml")
    lines = plant.run("lines", event)
    assert lines.ok and lines.outputs["any"] == "true", lines.output()
    plans = run_matrix(plant, "plan", event, lines)
    assert sorted(plans) == ["booth-a", "booth-b", "washer"]
    assert all(job.ok for job in plans.values()), [j.output() for j in plans.values()]
    comment = plant.run("comment", event, needs={"lines": lines, "plan": plans["washer"]})
    assert comment.ok, comment.output()
    (said,) = plant.comments()
    assert said["body"].startswith("<!-- prc3cfg-fleet-plan -->") and said["body"].count("prc3cfg plan") == 3
    # the plan shows what the apply will meet
    assert "deny window 'production' is open until 2026-11-30 16:00 CET" in said["body"]
    assert paint_shop.images() == factory  # planning wrote nothing

    merged = plant.merge(7)
    lines = plant.run("lines", merged)
    assert lines.ok and [e["bus"] for e in json.loads(lines.outputs["matrix"])["include"]] == ["booth-a",
                                                                                               "booth-b",
                                                                                               "washer"]
    applies = run_matrix(plant, "apply", merged, lines)
    # a line in its window is no failure
    assert all(job.ok for job in applies.values()), [j.output() for j in applies.values()]
    assert "Apply complete: 3 modules written and verified." in applies["booth-a"].output()
    assert "waits for a window; nothing was written" in applies["booth-b"].output()
    assert washer_line.matches_plant()
    held = paint_shop.images()
    # nothing written in the shift
    assert all(held[key] == factory[key] for key in factory if key[0] == "booth-b")
    assert all(held[key] != factory[key] for key in factory if key[0] == "booth-a")
    artifacts = plant.state / "artifacts"
    records = {entry["bus"]: artifacts / f"prc3cfg-records-{9000 + plant.runs - 2 + n}-{entry['id']}"
               for n, entry in enumerate(json.loads(lines.outputs["matrix"])["include"])}
    # kept for restore
    assert (records["booth-a"] / "snapshots").is_dir() and (records["washer"] / "journal").is_dir()

    summary = plant.run("summary", merged, needs={"lines": lines, "apply": applies["washer"]})
    assert summary.ok, summary.output()
    rows = [row for row in summary.summary.splitlines() if row.startswith("| plants/")]
    assert len(rows) == 3
    assert (rows[0].startswith("| plants/paint-shop.yaml:booth-a | 3 | NORMAL | none |")
            and rows[0].endswith("| done |"))
    assert ("| waiting: " in rows[1]
            and "deny window 'production' is open until 2026-11-30 16:00 CET |" in rows[1])
    assert rows[2].startswith("| plants/washer.yaml:washer | 3 | NORMAL |") and rows[2].endswith("| done |")
    posted = [c for c in plant.comments() if c["body"].startswith("<!-- prc3cfg-fleet -->")]
    # on the merged pull request
    assert [c["body"] for c in posted] == [summary.summary] and posted[0]["issue"] == 7


@needs("jq")
def test_a_commit_that_came_from_no_pull_request_is_not_applied(three_lines):
    plant, paint_shop, _ = three_lines
    factory = paint_shop.images()
    before = plant.main()
    pushed = plant.clone / "plants" / "paint-shop.yaml"
    pushed.write_text(pushed.read_text() + "# pushed\n")
    plant.git("commit", "-q", "-am", "pushed to main, reviewed by nobody")
    plant.git("push", "-q", "origin", "main")
    push = {"github.event_name": "push", "github.sha": plant.main(), "github.event.before": before}
    lines = plant.run("lines", push)
    applies = run_matrix(plant, "apply", push, lines)
    assert sorted(applies) == ["booth-a", "booth-b"] and not any(job.ok for job in applies.values())
    assert all("came from no pull request: there is no reviewed plan to apply" in job.output()
               for job in applies.values())
    assert paint_shop.images() == factory
    summary = plant.run("summary", push, needs={"lines": lines, "apply": applies["booth-a"]})
    assert summary.ok, summary.output()
    rows = [row for row in summary.summary.splitlines() if row.startswith("| plants/paint-shop.yaml")]
    assert (len(rows) == 2
            and all(row.endswith("| refused: the job failed before its apply: see "
                                 "its log |") for row in rows))


@needs("jq")
def test_a_merge_whose_plant_file_is_not_the_reviewed_one_is_not_applied_on_its_line(three_lines):
    """The approvals' last check: the apply job applies the plan made for the pull request's head — the
    reviewed commit — and `apply --plan` refuses it where the merged plant file is not byte for byte the one
    planned."""
    plant, paint_shop, washer_line = three_lines
    plant.env["PRC3CFG_POLICY_NOW"] = "2026-11-29T09:00:00+01:00"  # a Sunday: no window judges this
    washer_factory = washer_line.images()
    event = plant.pull_request(lambda document: document.update(yaml.safe_load(SHIFT)),
                               file="plants/rules.yaml")
    lines = plant.run("lines", event)
    assert all(job.ok for job in run_matrix(plant, "plan", event, lines).values())
    # meanwhile on main: the washer's plant file, reviewed in another pull request
    plant.git("switch", "-q", "main")
    (plant.clone / "plants" / "washer.yaml").write_text((plant.clone / "plants" / "washer.yaml").read_text()
                                                        + "# a comment\n")
    plant.git("commit", "-q", "-am", "the washer, commented")
    plant.git("push", "-q", "origin", "main")
    before = plant.main()
    # a merge commit: not the reviewed head
    plant.git("merge", "-q", "--no-ff", "-m", "merge the shift", "change")
    plant.git("push", "-q", "origin", "main")
    pulls = plant.pulls()
    pulls[-1].update(state="merged", merge_commit_sha=plant.main())
    (plant.state / "pulls.json").write_text(json.dumps(pulls))
    merged = {"github.event_name": "push", "github.sha": plant.main(), "github.event.before": before}
    lines = plant.run("lines", merged)
    applies = run_matrix(plant, "apply", merged, lines)
    # their plant file is the reviewed one
    assert applies["booth-a"].ok and applies["booth-b"].ok and paint_shop.matches_plant()
    assert not applies["washer"].ok
    assert ("stale plan — the plant file plants/washer.yaml changed since the plan was made; "
            "plan again") in applies["washer"].output()
    assert washer_line.images() == washer_factory  # nothing written
    summary = plant.run("summary", merged, needs={"lines": lines, "apply": applies["washer"]})
    rows = [row for row in summary.summary.splitlines() if row.startswith("| plants/")]
    assert [row.rsplit("|", 2)[1].strip() for row in rows[:2]] == ["done", "done"]
    assert "| refused: " in rows[2] and "stale plan — the plant file plants/washer.yaml changed" in rows[2]
