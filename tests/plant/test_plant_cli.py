"""`prc3cfg validate`, `show` and `schema` from the command line: output and exit codes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from emulated import run_cli
from typer.testing import CliRunner

import prc3cfg.cli.plant_commands  # noqa: F401  (registers the commands on `app`)
from prc3cfg.cli import app
from prc3cfg.cli.plant_commands import github_annotation
from prc3cfg.plant import plant_schema_text
from prc3cfg.plant.problems import Finding

ROOT = Path(__file__).parents[2]
DEMO = ROOT / "plants" / "demo-line.yaml"
BROKEN = Path(__file__).parent / "broken"
runner = CliRunner()


def test_validate_a_good_plant() -> None:
    result = runner.invoke(app, ["validate", str(DEMO)])
    assert result.exit_code == 0
    assert result.stdout == f"{DEMO}: valid (2 buses, 6 modules)\n"


def validate(*args: str | Path, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prc3cfg", "validate", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd)


def test_validate_a_broken_plant_prints_the_problems_on_stderr_as_every_error_is() -> None:
    path = BROKEN / "unknown-key-program.yaml"
    done = validate(path)
    assert (done.returncode, done.stdout) == (1, "")
    assert done.stderr == (f"error: {path}:13:13: unknown key 'sped' in program 3 — expected one of "
                           "position, "
                           "speed, relative_speed, dwell, f1, f2, next\n")


def test_validate_format_json_lists_every_problem_at_its_place(tmp_path: Path) -> None:
    path = BROKEN / "many-problems.yaml"
    done = validate(path, "--format", "json")
    assert (done.returncode, done.stderr) == (1, "")
    expected = [line.split(":", 2) for line in path.with_suffix(".expected").read_text().splitlines()]
    assert json.loads(done.stdout) == [{"file": str(path), "line": int(line), "column": int(column),
                                        "message": message.strip()}
                                       for line, column, message in expected]
    missing = tmp_path / "missing.yaml"
    assert json.loads(validate(missing, "--format", "json").stdout) == [
        {"file": str(missing), "line": None, "column": None, "message": "no such file — check the path"}]
    done = validate(DEMO, "--format", "json")
    assert (done.returncode, done.stdout) == (0, "[]\n")


def test_validate_format_github_annotates_each_problem_where_it_is(tmp_path: Path) -> None:
    """GitHub's workflow commands: `%`, CR and LF escaped in the message, and `:` and `,` as well in a
    property."""
    odd = tmp_path / "a,b:c%d"
    odd.mkdir()
    path = odd / "plant.yaml"
    path.write_text("plant: demo\nbuses:\n  - name: a\n    port: emulator://a\n    modules:\n"
                    "      - {address: 1, name: m1, programs: {3: {position: 0.2, sped: 0.3}}}\n")
    done = validate("a,b:c%d/plant.yaml", "--format", "github", cwd=tmp_path)
    assert (done.returncode, done.stderr) == (1, "")
    assert done.stdout == ("::error file=a%2Cb%3Ac%25d/plant.yaml,line=6,col=62,title=prc3cfg::unknown key "
                           "'sped' in program 3 "
                           "— expected one of position, speed, relative_speed, dwell, f1, f2, next\n")
    assert validate("missing.yaml", "--format", "github", cwd=tmp_path).stdout == (
        "::error file=missing.yaml,title=prc3cfg::no such file — check the path\n")
    done = validate(DEMO, "--format", "github")
    assert (done.returncode, done.stdout) == (0, f"{DEMO}: valid (2 buses, 6 modules)\n")


def test_github_escaping_is_githubs() -> None:
    assert github_annotation(Finding("x%y:z,w.yaml", 1, 2, "100% sure\r\nnext: a, b")) == (
        "::error file=x%25y%3Az%2Cw.yaml,line=1,col=2,title=prc3cfg::100%25 sure%0D%0Anext: a, b")


def test_a_name_that_could_start_a_workflow_command_is_refused_and_every_annotation_is_one_line() -> None:
    """`name: "m1\\n::error::injected"` would start a command of its own in a CI log: each name with a control
    character is one problem, each problem one `::error` line, its text escaped."""
    path = BROKEN / "names-control.yaml"
    done = validate(path.name, "--format", "github", cwd=BROKEN)
    assert (done.returncode, done.stderr) == (1, "")
    lines = done.stdout.splitlines()
    assert len(lines) == len(path.with_suffix(".expected").read_text().splitlines()) == 11
    assert all(line.startswith("::error file=names-control.yaml,line=") for line in lines), lines
    assert "name 'm1\\n::error::injected' holds a control character" in done.stdout
    assert "::module 8 has no address" in done.stdout  # another problem of that module names it by its place


# two real processes a name: an escape sequence and a C1 control in the fast tier, a bell and a line separator
# in the soak tier
@pytest.mark.parametrize(
    "name",
    [
        pytest.param("bell\a.yaml", marks=pytest.mark.soak),
        "clear\x1b[2J.yaml",
        pytest.param("line\u2028sep.yaml", marks=pytest.mark.soak),
        "c1\x9b31m.yaml",
    ],
)
def test_a_file_name_with_control_characters_is_shown_escaped(tmp_path: Path, name: str) -> None:
    """What prc3cfg says of a file names it as printable text, in every format: nothing it prints rings,
    moves, colours."""
    text = validate(tmp_path / name)
    github = validate(tmp_path / name, "--format", "github")
    assert text.returncode == github.returncode == 1
    assert text.stderr == (f"error: {str(tmp_path / name).encode('unicode_escape').decode()}: no such file "
                           "— check the path\n")
    assert github.stdout.count("\n") == 1 and not any(c in github.stdout[:-1] for c in "\a\x1b\u2028\x9b\r\n")


def test_validate_as_a_process_never_shows_a_traceback(tmp_path: Path) -> None:
    for path, code in [(DEMO, 0), (BROKEN / "tab-indent.yaml", 1), (BROKEN / "empty.yaml", 1),
                       (BROKEN / "not-utf8.yaml", 1), (tmp_path / "missing.yaml", 1), (tmp_path, 1)]:
        done = subprocess.run([sys.executable, "-m", "prc3cfg", "validate", str(path)],
                              capture_output=True, text=True, cwd=ROOT)
        assert done.returncode == code, done.stderr
        assert "Traceback" not in done.stderr
        assert done.stdout.startswith(str(path)) if code == 0 else done.stderr.startswith(f"error: {path}")


def test_show_a_module_names_every_source() -> None:
    result = runner.invoke(app, ["show", str(DEMO), "--module", "booth-a-top"])
    assert result.exit_code == 0
    out = result.stdout
    assert "module booth-a-top — bus booth-a, address 5" in out
    for text in ("upper_reversing_point (S1)", "1.800 m", "profile reciprocator", "profile short-stroke",
                 "default", "program 10", "set at 0.020 m", "1 → 2 → 1 (loop)"):
        assert text in out


def test_show_without_a_module_lists_the_modules() -> None:
    result = runner.invoke(app, ["show", str(DEMO)])
    assert result.exit_code == 0
    assert "booth-b-right" in result.stdout and "reset" in result.stdout


def test_show_an_unknown_module_is_one_clean_line() -> None:
    done = subprocess.run([sys.executable, "-m", "prc3cfg", "show", str(DEMO), "--module", "nope"],
                          capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 1
    assert done.stderr.startswith(f"error: {DEMO}: no module named 'nope' — the modules are booth-a-left, ")
    assert "Traceback" not in done.stderr


def test_schema_prints_the_schema() -> None:
    result = runner.invoke(app, ["schema"])
    assert result.exit_code == 0
    assert result.stdout == plant_schema_text()


TAGGED = ("plant: demo\nbuses:\n  - name: a\n    port: socket://127.0.0.1:9\n    {key}: {value}\n    "
          "modules:\n      - {{address: 1, name: m1}}\n")


@pytest.mark.parametrize(("key", "value", "at", "tag"), [
    ("timeout", "!!bool x", "5:14", "!!bool"),
    ("timeout", "!!timestamp x", "5:14", "!!timestamp"),
    ("timeout", '!!int ""', "5:14", "!!int"),
    ("timeout", '!!float "_"', "5:14", "!!float"),
    ("timeout", "!!float 0.3", "5:14", "!!float"),
    ("timeout", "! 0.3", "5:14", "!"),
    ("!!str timeout", "0.3", "5:5", "!!str"),
    ("timeout", "!foo 0.3", "5:14", "!foo"),
    ("gateway", "!!map {receive_db: 30, receive_dw: 1, cpu: 0, identifier: 1}", "5:14", "!!map"),
])
@pytest.mark.parametrize("command", ["validate", "plan"])
def test_a_tag_anywhere_is_one_line_naming_it(tmp_path: Path, capsys, command: str, key: str, value: str,
                                              at: str, tag: str) -> None:
    """In this process (the first case also as a command of its own:
    test_a_tag_is_one_line_of_the_process)."""
    path = tmp_path / "plant.yaml"
    path.write_text(TAGGED.format(key=key, value=value))
    done = run_cli(capsys, command, path)
    assert (done.code, done.out) == (1, "")
    assert done.err == f"error: {path}:{at}: tags are not used in plant files — remove {tag}\n"


@pytest.mark.parametrize("command", ["validate", "plan"])
def test_a_tag_is_one_line_of_the_process(tmp_path: Path, command: str) -> None:
    path = tmp_path / "plant.yaml"
    path.write_text(TAGGED.format(key="timeout", value="!!bool x"))
    done = subprocess.run([sys.executable, "-m", "prc3cfg", command, str(path)], capture_output=True,
                          text=True, cwd=tmp_path)
    assert (done.returncode, done.stdout) == (1, "")
    assert done.stderr == f"error: {path}:5:14: tags are not used in plant files — remove !!bool\n"
