"""docs/ says what the code does: its tables against what prc3cfg writes and holds.

A plan file written by `plan --out` (plain, with broadcasts on a declared line, with a module the
plant does not list, with the module's own clamping) has exactly the keys docs/files.md lists for
it; so do the snapshot and the journal of an apply; the exit codes, message IDs, error codes and
the readings of the manual are those of the code. The README points at docs/, not at a
specification a user of the repository does not have.
"""

from __future__ import annotations

import json
import random
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from emulated import emulated_plant, run_cli
from emulator_client import serve
from test_broadcast import declared as declared_line
from test_broadcast import full_line

from prc3cfg.api import WindowShut
from prc3cfg.cli import EXIT_USAGE
from prc3cfg.cli.plan_commands import EXIT_CHANGES, EXIT_POLICY
from prc3cfg.core.codec import MESSAGE_TYPES
from prc3cfg.core.error_codes import ERROR_CODES
from prc3cfg.errors import Interrupted

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def section(document: str, heading: str) -> str:
    """The text under the `## ` heading that starts with `heading`, up to the next one."""
    text = (DOCS / document).read_text()
    start = text.index(f"\n## {heading}")
    end = text.find("\n## ", start + 1)
    return text[start : end if end >= 0 else None]


def tables(text: str) -> list[list[list[str]]]:
    """Every markdown table in `text`: its body rows (header and rule left out), cells stripped."""
    found: list[list[list[str]]] = []
    previous = ""
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("|") and previous.startswith("|"):
            if not re.fullmatch(r"\|(\s*-+\s*\|)+", line):
                found[-1].append([cell.strip() for cell in line.strip("|").split("|")])
        elif line.startswith("|"):
            found.append([])
        previous = line
    return found


def key(cell: str) -> str:
    return re.fullmatch(r"`([^`]+)`", cell).group(1)


def paths(value: object, at: str = "", maps: dict[str, str | None] | None = None) -> set[str]:
    """Every key path of a JSON value (`a.b[].c`); under a path in `maps` the keys are names, written
    as the placeholder given (None: not followed)."""
    maps = maps or {}
    found: set[str] = set()
    if isinstance(value, dict):
        for name, inner in value.items():
            if at in maps and maps[at] is None:
                continue
            here = f"{at}.{maps.get(at) or name}".lstrip(".")
            found |= {here} | paths(inner, here, maps)
    elif isinstance(value, list):
        for item in value:
            found |= paths(item, f"{at}[]", maps)
    return found


# keyed by program number; by "bus/module"
SYMBOLS = {"buses[].modules[].changes.symbols": None, "read.taken": None}

CLAMPING = """\
plant: short
buses:
  - name: line
    port: socket://127.0.0.1:1
    modules:
      - address: 1
        name: short
        system: {upper_reversing_point: 0.100}
"""


def planned(tmp_path: Path, capsys, name: str, source: Path | None = None, *args: object,
            read_first: bool = False,
            apply_first: bool = False, **emulated) -> dict:
    """The plan file of `source` on emulators; `read_first`: after a `read`, which the line's record then
    holds (a targeted plan); `apply_first`: after an apply (a targeted plan that takes every program from the
    record)."""
    directory = tmp_path / name
    directory.mkdir()
    with emulated_plant(directory, **({"source": source} if source else {}), **emulated) as plant:
        assert not read_first or run_cli(capsys, "read", plant.path).code == 0
        assert not apply_first or run_cli(capsys, "apply", plant.path, "--auto-approve",
                                          "--allow-axis-release").code == 0
        out = directory / "plan.json"
        result = run_cli(capsys, "plan", plant.path, "--out", out, *args)
        assert result.code == 0, result.err
        return json.loads(out.read_text())


def test_a_plan_file_has_exactly_the_keys_docs_files_lists(tmp_path, capsys):
    (rows,) = tables(section("files.md", "Plan file"))
    documented = {key(row[0]): row[2] for row in rows}
    declared, clamping = declared_line(full_line(tmp_path, modules=28)), tmp_path / "clamping.yaml"
    clamping.write_text(CLAMPING)
    plain = paths(planned(tmp_path, capsys, "plain"), maps=SYMBOLS)
    assert plain - set(documented) == set()
    assert {k for k, when in documented.items() if when == "always"} - plain == set()
    seen = plain | paths(planned(tmp_path, capsys, "broadcast", declared), maps=SYMBOLS)
    seen |= paths(planned(tmp_path, capsys, "unlisted", declared, unlisted={"line": [29]}), maps=SYMBOLS)
    seen |= paths(planned(tmp_path, capsys, "clamping", clamping), maps=SYMBOLS)
    seen |= paths(planned(tmp_path, capsys, "targeted", None, read_first=True), maps=SYMBOLS)
    seen |= paths(planned(tmp_path, capsys, "taken", None, apply_first=True), maps=SYMBOLS)
    assert seen == set(documented)


def test_the_records_of_an_apply_have_exactly_the_keys_docs_files_lists(tmp_path, capsys):
    records = section("files.md", "Records of an apply")
    snapshot_rows, journal_rows = tables(records)
    with emulated_plant(tmp_path) as plant:
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    (snapshot,) = (tmp_path / ".prc3cfg" / "snapshots").iterdir()
    found = paths(json.loads(snapshot.read_text()),
                  maps={"lines": "BUS", "modules[].system": None, "modules[].programs[]": None})
    assert found == {key(row[0]) for row in snapshot_rows}
    (journal,) = (tmp_path / ".prc3cfg" / "journal").iterdir()
    events: dict[str, set[str]] = {}
    for line in journal.read_text().splitlines():
        entry = json.loads(line)
        events.setdefault(entry.pop("event"), set()).update(set(entry) - {"time"})
    documented = {key(row[0]): set(re.findall(r"`([a-z_0-9]+)`", row[1])) for row in journal_rows}
    assert {event: documented[event] for event in events} == events
    api = "".join(path.read_text()
                  for path in [*(ROOT / "prc3cfg" / "api").glob("*.py"),
                               ROOT / "prc3cfg" / "shell" / "engine.py"])
    # interrupted: on Ctrl-C (the apply engine's `Keeping.note`); adopt, adopted: an adopt's
    # (`write_adoption`)
    assert all(event in events or f'keeping.note("{event}"' in api or f'journal.record("{event}"' in api
               for event in documented)


def test_the_exit_codes_are_the_codes_of_the_command_line():
    (rows,) = tables(section("files.md", "Exit codes"))
    assert {int(row[0]) for row in rows} == {0, 1, EXIT_CHANGES, EXIT_POLICY, EXIT_USAGE,
                                             WindowShut.exit_code, Interrupted.exit_code}


def test_the_message_table_is_the_codecs():
    message_rows = tables(section("protocol.md", "Messages"))[0]
    assert {int(row[0].removesuffix("h"), 16) for row in message_rows} == set(MESSAGE_TYPES)


def test_the_error_codes_are_the_codes_with_their_meanings():
    (rows,) = tables(section("protocol.md", "Error codes"))
    assert {int(row[0]): row[1] for row in rows} == {code: entry.meaning
                                                     for code, entry in ERROR_CODES.items()}


def test_every_reading_in_the_code_is_listed():
    readings = section("protocol.md", "Readings")
    marked = {path.name for path in (ROOT / "prc3cfg").rglob("*.py")
              if re.search(r"(?<!\w)\(reading\)", path.read_text())}
    assert marked and {name for name in marked if name not in readings} == set()


def test_the_readme_points_at_docs_and_at_no_folder_outside_the_repository():
    readme = (ROOT / "README.md").read_text()
    assert "../shared" not in readme
    for target in re.findall(r"\]\((docs/[^)#]+)", readme):
        assert (ROOT / target).is_file(), target
    assert {"docs/protocol.md", "docs/line.md", "docs/files.md"} <= set(re.findall(r"\]\((docs/[^)#]+)",
                                                                                   readme))
    for document in DOCS.glob("*.md"):
        for target in re.findall(r"\]\(([a-z-]+\.md)\)", document.read_text()):
            assert (DOCS / target).is_file(), f"{document.name} → {target}"
        assert "](docs/" not in document.read_text(), f"{document.name}: a link in docs/ is relative to docs/"


def test_the_api_doc_names_everything_the_api_exports():
    """`api.__all__` is what users' scripts call: docs/api.md's Python API names each of it."""
    from prc3cfg import api

    text = section("api.md", "Python API")
    assert api.__all__ and [name for name in api.__all__ if not re.search(rf"\b{name}\b", text)] == []


# -- the README: what a newcomer reads first ----------------------------------------------------------

README_MOST = 12 * 1024  # bytes: the first screen, the two commands, the day's workflow; the rest is in docs/
VENV = {"sh": "python3 -m venv .venv && . .venv/bin/activate && ",
        "powershell": "py -m venv .venv; .venv\\Scripts\\Activate.ps1; "}


def readme_commands(language: str) -> list[str]:
    """The README's two commands in `language` (sh: Linux and macOS; powershell: Windows), from "## Two
    commands"."""
    readme = (ROOT / "README.md").read_text()
    start = readme.index("\n## Two commands")
    block = re.search(rf"```{language}\n(.*?)```", readme[start : readme.index("\n## ", start + 1)], re.S)
    assert block, language
    return block.group(1).strip().splitlines()


def test_the_readme_fits_in_twelve_kilobytes():
    assert len((ROOT / "README.md").read_bytes()) <= README_MOST


def test_the_readme_s_two_commands_make_a_venv_run_the_demo_and_the_tests_and_ci_runs_the_second_verbatim():
    """Plain Debian has no `python` and refuses `pip install` outside a venv (PEP 668): each command makes and
    enters one first. Windows' are the same commands in PowerShell 5.1's words (`;` for `&&`)."""
    demo, tests = readme_commands("sh")
    assert demo.startswith(VENV["sh"]
                           + "python -m pip install . && prc3cfg plan plants/demo-line.yaml && "
                             "prc3cfg apply ")
    assert tests == VENV["sh"] + "python -m pip install -e '.[test]' && python -m pytest"
    as_powershell = [VENV["powershell"] + command.removeprefix(VENV["sh"]).replace(" && ", "; ")
                     for command in (demo, tests)]
    assert readme_commands("powershell") == as_powershell
    assert f"time {{ {tests}; }}" in (ROOT / ".ci" / "run").read_text().splitlines()  # timed: test_test_shape


def test_the_readme_s_demo_command_plans_and_applies_as_written(tmp_path):
    """What follows the install in the README's first command, run by bash in a copy of plants/ with this
    tree's prc3cfg (the install itself, on Debian's own Python, is tests/test_install.py's, in the soak tier).
    """
    shutil.copytree(ROOT / "plants", tmp_path / "plants", ignore=shutil.ignore_patterns(".prc3cfg"))
    shutil.copytree(ROOT / "schemas", tmp_path / "schemas")
    demo = readme_commands("sh")[0].removeprefix(VENV["sh"]).split(" && ", 1)[1]
    done = subprocess.run(["bash", "-ec", demo], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert "Apply complete: 6 modules written and verified." in done.stdout and "Traceback" not in done.stderr


def test_the_readme_links_into_docs_for_everything_else():
    readme = (ROOT / "README.md").read_text()
    linked = set(re.findall(r"\]\((docs/[^)#]+)", readme))
    wanted = ["commands", "plant-files", "files", "safety", "security", "windows", "ci", "api", "testing",
              "design"]
    assert {f"docs/{name}.md" for name in wanted} <= linked


def test_each_library_decision_names_tests_that_exist_and_the_libraries_kept_out_are_not_dependencies():
    """docs/design.md: for each need a library could meet, the decision and the tests that prove the guarantee
    kept — each a test function of the suite; a library prc3cfg decided against is not among its dependencies.
    """
    table = [row for row in (DOCS / "design.md").read_text().splitlines() if row.startswith("| ")
             and not row.startswith("| Need")]
    defined = {name for path in (ROOT / "tests").rglob("test_*.py")
               for name in re.findall(r"^def (test_\w+)", path.read_text(), re.M)}
    named = [name for row in table for name in re.findall(r"`(test_\w+)`", row.split("|")[-2])]
    assert len(table) >= 4 and all(re.findall(r"`(test_\w+)`", row.split("|")[-2]) for row in table), table
    assert set(named) <= defined, set(named) - defined
    dependencies = (ROOT / "pyproject.toml").read_text().split("[project.optional-dependencies]")[0]
    assert not [library for library in ("platformdirs", "filelock", "portalocker", "ruamel", "atomicwrites")
                if library in dependencies]


def test_no_text_cites_a_specification_the_repository_does_not_have():
    """The design's specifications (interfaces, link, prc3-protocol) are not in the repository: docs/ says it
    to a user and a maintainer (docs/files.md, docs/line.md, docs/protocol.md)."""
    texts = [*(ROOT / "prc3cfg").rglob("*.py"), *(ROOT / "tests").rglob("*.py"),
             *(ROOT / "bench").rglob("*.py"), *DOCS.glob("*.md"),
             ROOT / "README.md"]
    cited = [path.relative_to(ROOT) for path in texts
             if any(f"{name}.md" in path.read_text() for name in ("interfaces", "link", "prc3-protocol"))]
    assert cited == []


def test_every_command_the_readme_names_is_one_prc3cfg_has(capsys):
    """A command renamed or removed takes the README's line with it: each `prc3cfg COMMAND` there answers
    --help."""
    readme = (ROOT / "README.md").read_text()
    named = set(re.findall(r"(?:^|`|&& |; )prc3cfg ((?:records |emulator )?[a-z-]+)", readme, re.M))
    assert {"import", "validate", "plan", "apply", "adopt", "records list", "restore", "doctor"} <= named
    for command in sorted(named):
        helped = run_cli(capsys, *command.split(), "--help")
        assert helped.code == 0 and "Usage" in helped.out, (command, helped)


#: What a script adds to the README's day where a person would answer at a terminal, and what keeps it short.
ADDED = {"import": " --modules 1-3", "apply": " --auto-approve --allow-axis-release",
         "adopt": " --auto-approve",
         "restore": " --auto-approve --allow-axis-release"}


def the_day() -> list[str]:
    """The command lines of the README's "A day with prc3cfg", comments left out, in their order."""
    readme = (ROOT / "README.md").read_text()
    block = re.search(r"## A day with prc3cfg\n.*?```sh\n(.*?)```", readme, re.S)
    assert block
    return [line.split("  #", 1)[0].strip() for line in block.group(1).splitlines() if line.strip()]


@pytest.mark.soak
@pytest.mark.parametrize("seed", range(3))
def test_the_readme_s_day_runs_line_by_line_on_an_emulated_line(tmp_path, seed):
    """Each line of the README's day, by bash in its order, with `emulator serve` (three modules) in place of
    /dev/ttyUSB0 and only what `ADDED` says added: after `import` a seeded change of one module's program is
    written into the plant file (so there is a plan to apply), and before the drift line another plant file
    teaches the module another position (so there is drift to adopt); the restore takes the apply's snapshot.
    """
    rng = random.Random(seed)
    address, program = rng.randint(1, 3), rng.randint(1, 64)
    planned, taught = rng.sample(range(60, 400), 2)  # mm, within the factory S2..S1
    day = the_day()
    assert [line.split()[1] for line in day] == ["import", "validate", "plan", "apply", "plan", "adopt",
                                                 "records", "restore"]
    with serve(tmp_path, "--modules", "1-3", "--state", str(tmp_path / "state.json")) as served:
        url = f"socket://127.0.0.1:{served.port}"

        def run(line: str) -> subprocess.CompletedProcess:
            command = line.split()[1]
            line = (line.replace("/dev/ttyUSB0", url).replace("SNAPSHOT.json", snapshot())
                    if "restore" in line else line.replace("/dev/ttyUSB0", url))
            head, redirect = (line.split(" > ", 1) + [""])[:2]
            line = head + ADDED.get(command, "") + (f" > {redirect}" if redirect else "")
            done = subprocess.run(["bash", "-ec", line], cwd=tmp_path, capture_output=True, text=True,
                                  timeout=120)
            assert done.returncode == 0 and "Traceback" not in done.stderr, (line, done.stdout[-2000:],
                                                                             done.stderr[-2000:])
            return done

        def snapshot() -> str:
            (found, *_) = sorted((tmp_path / ".prc3cfg" / "snapshots").glob("*.json"))
            return found.name

        def plant_with(position: int) -> str:
            module = f"{{address: {address}, name: bus-1-{address}, profiles: [common]}}"
            assert module in imported, imported
            return imported.replace(module, module[:-1]
                                    + ", programs: "
                                      f"{{{program}: {{position: {position / 1000:.3f}, speed: 0.050}}}}}}")

        run(day[0])
        imported = (tmp_path / "plant.yaml").read_text()
        (tmp_path / "plant.yaml").write_text(plant_with(planned))
        for line in day[1:4]:
            run(line)
        (tmp_path / "teach").mkdir()
        (tmp_path / "teach" / "plant.yaml").write_text(plant_with(taught))
        run(f"prc3cfg apply teach/plant.yaml{ADDED['apply']}")  # a hand on the floor
        drift = run(day[4])
        assert f"{taught / 1000:.3f}" in drift.stdout, drift.stdout
        run(day[5])
        assert f"position: {taught / 1000:.3f}" in (tmp_path / "plant.yaml").read_text()
        assert run("prc3cfg plan plant.yaml --detailed-exitcode").returncode == 0
        listed = run(day[6])
        assert listed.stdout.count("apply") >= 1 and "adopt" in listed.stdout, listed.stdout
        # back to the modules as the apply found them (factory defaults): the adopted file has a change again
        run(day[7])
        again = subprocess.run(["prc3cfg", "plan", "plant.yaml", "--detailed-exitcode"], cwd=tmp_path,
                               capture_output=True, text=True)
        assert again.returncode == 2 and f"bus-1-{address}" in again.stdout, again.stdout + again.stderr
