"""Every broken plant file in `broken/` gives exactly the problems in its `.expected` file.

An `.expected` file holds the lines of `PlantError.problems` without the leading
"path:", one problem a line: "line:column: what is wrong — what would be right". Each file
is read with the pure-Python parser and, when installed, with libyaml: the lines are the same.

Hostile inputs (devices, pipes, huge files, alias and nesting bombs, numbers of a million
digits) are refused by a limit the message names, before the work they would cause: these
tests would hang or run out of memory otherwise, so none needs a clock.
"""

from __future__ import annotations

import json
import os
import re
import socket
from pathlib import Path

import jsonschema
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from prc3cfg.errors import UserError
from prc3cfg.plant import PlantError, document, load_plant, plant_schema

BROKEN = sorted((Path(__file__).parent / "broken").glob("*.yaml"))
PLANTS = Path(__file__).parents[2] / "plants"
LOADERS = {"pure": yaml.SafeLoader, **({"libyaml": yaml.CSafeLoader} if yaml.__with_libyaml__ else {})}


@pytest.fixture(params=list(LOADERS.values()), ids=list(LOADERS))
def each_loader(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> type:
    monkeypatch.setattr(document, "LOADER", request.param)
    return request.param


def test_there_are_at_least_thirty_broken_files() -> None:
    assert len(BROKEN) >= 30
    assert all(path.with_suffix(".expected").exists() for path in BROKEN)


@pytest.mark.usefixtures("each_loader")
@pytest.mark.parametrize("path", BROKEN, ids=lambda p: p.stem)
def test_broken_file(path: Path) -> None:
    with pytest.raises(PlantError) as raised:
        load_plant(path)
    expected = [f"{path}:{line}" for line in path.with_suffix(".expected").read_text().splitlines()]
    assert raised.value.problems == expected
    assert str(raised.value) == "\n".join(expected)


@pytest.mark.parametrize("path", BROKEN, ids=lambda p: p.stem)
def test_problems_are_clean_lines_sorted_by_position(path: Path) -> None:
    with pytest.raises(PlantError) as raised:
        load_plant(path)
    positions = []
    for problem in raised.value.problems:
        assert "\n" not in problem and " — " in problem
        assert "Input should" not in problem and "pydantic" not in problem
        line, column = problem.removeprefix(f"{path}:").split(":")[:2]
        positions.append((int(line), int(column)))
    assert positions == sorted(positions)


def test_missing_file_and_directory(tmp_path: Path) -> None:
    with pytest.raises(PlantError, match=r"missing\.yaml: no such file — check the path"):
        load_plant(tmp_path / "missing.yaml")
    with pytest.raises(PlantError, match="is a directory"):
        load_plant(tmp_path)


def test_plant_error_is_a_user_error() -> None:
    assert issubclass(PlantError, UserError)


def _fifo(tmp_path: Path) -> Path:
    os.mkfifo(tmp_path / "plant.yaml")  # opening it to read would wait for a writer
    return tmp_path / "plant.yaml"


def _socket(tmp_path: Path) -> Path:
    server = socket.socket(socket.AF_UNIX)
    server.bind(str(tmp_path / "plant.yaml"))
    return tmp_path / "plant.yaml"


def _sparse(tmp_path: Path) -> Path:
    with open(tmp_path / "plant.yaml", "wb") as file:
        file.truncate(16 << 30)  # 16 GiB of nothing: reading it whole would not fit in memory
    return tmp_path / "plant.yaml"


@pytest.mark.parametrize(("make", "problem"), [
    (lambda tmp_path: Path("/dev/zero"), "is a device, not a file — give the plant file (*.yaml) itself"),
    (_fifo, "is a named pipe (FIFO), not a file — give the plant file (*.yaml) itself"),
    (_socket, "is a socket, not a file — give the plant file (*.yaml) itself"),
    (lambda tmp_path: tmp_path, "is a directory — give the plant file (*.yaml) in it"),
    (_sparse, "larger than 1 MiB — a plant file is far smaller: check that this is the plant file"),
], ids=["dev-zero", "fifo", "socket", "directory", "16-GiB"])
def test_only_a_regular_file_is_read_and_only_its_first_mebibyte(tmp_path: Path, make, problem: str) -> None:
    path = make(tmp_path)
    with pytest.raises(PlantError) as raised:
        load_plant(path)
    assert raised.value.problems == [f"{path}: {problem}"]


def test_a_plant_file_may_be_one_mebibyte(tmp_path: Path) -> None:
    demo = (PLANTS / "demo-line.yaml").read_bytes()
    path = tmp_path / "plant.yaml"
    path.write_bytes(demo + b"#" * (document.MAX_BYTES - len(demo) - 1) + b"\n")
    assert load_plant(path).name == "demo-line"
    path.write_bytes(demo + b"#" * (document.MAX_BYTES - len(demo)) + b"\n")
    with pytest.raises(PlantError, match="larger than 1 MiB"):
        load_plant(path)


ALIAS_BOMB = "plant: &a [x]\nbuses: [" + "*a, " * 100_000 + "]\n"
FLOW_NESTING = "plant: demo\nbuses: " + "[" * 100_000 + "\n"
BLOCK_NESTING = "plant:\n" + "".join(f"{' ' * (depth + 1)}x{depth}:\n" for depth in range(200))
MANY_DIGITS = ("plant: demo\nbuses:\n  - name: a\n    port: emulator://a\n    timeout: " + "9" * 500_000
               + "\n    modules: [{address: 1, name: m1}]\n")
HUGE_EXPONENT = MANY_DIGITS.replace("9" * 500_000, "1.0e+" + "9" * 500_000)
TINY_EXPONENT = MANY_DIGITS.replace("9" * 500_000, "1.0e-" + "9" * 500_000)
BOMB_CASES = [
    (ALIAS_BOMB, "2:9: an alias (*a, used 100000 times) — a plant file does not use aliases: share settings "
                 "with profiles: and a module's profiles: [NAME], or write the value out"),
    (FLOW_NESTING, "2:107: lists and mappings nested more than 100 deep — a plant file needs fewer than ten: "
                   "check the brackets and the indentation"),
    (BLOCK_NESTING, "101:101: lists and mappings nested more than 100 deep — a plant file needs fewer than ten: "
                    "check the brackets and the indentation"),
    (MANY_DIGITS, "5:14: timeout 99999999999999999999… has more than 28 digits, written out — a plant file's "
                  "numbers are read exactly: write at most 28 digits"),
    (HUGE_EXPONENT, "5:14: timeout 1.0e+999999999999999… has more than 28 digits, written out — a plant file's "
                    "numbers are read exactly: write at most 28 digits"),
    (TINY_EXPONENT, "5:14: timeout 1.0e-999999999999999… has more than 28 digits, written out — a plant file's "
                    "numbers are read exactly: write at most 28 digits"),
]


@pytest.mark.usefixtures("each_loader")
@pytest.mark.parametrize(("text", "problem"), BOMB_CASES, ids=["aliases", "flow-nesting", "block-nesting",
                                                               "many-digits", "huge-exponent", "tiny-exponent"])
def test_bombs_are_refused_by_the_limit_they_meet_first(tmp_path: Path, text: str, problem: str) -> None:
    path = tmp_path / "plant.yaml"
    path.write_text(text)
    with pytest.raises(PlantError) as raised:
        load_plant(path)
    assert raised.value.problems == [f"{path}:{problem}"]


@pytest.mark.parametrize("text", [ALIAS_BOMB, FLOW_NESTING, BLOCK_NESTING], ids=["aliases", "flow", "block"])
def test_aliases_and_deep_nesting_are_refused_before_the_composer_sees_them(tmp_path: Path, monkeypatch, text) -> None:
    def composer(*args, **kwargs):
        raise AssertionError("composed")

    monkeypatch.setattr(yaml, "compose", composer)
    path = tmp_path / "plant.yaml"
    path.write_text(text)
    with pytest.raises(PlantError):
        load_plant(path)


@pytest.mark.parametrize(("text", "tag", "value"), [
    # YAML 1.2.2 example 10.9, "Core Tag Resolution", every scalar of it
    ("null", "null", None), ("", "null", None), ("true", "bool", True), ("True", "bool", True),
    ("false", "bool", False), ("FALSE", "bool", False), ("0", "int", 0), ("0o7", "int", 7),
    ("0x3A", "int", 58), ("-19", "int", -19), ("0.", "float", 0), ("-0.0", "float", 0), (".5", "float", 0.5),
    ("+12e03", "float", 12000), ("-2E+05", "float", -200000), (".inf", "float", float("inf")),
    ("-.Inf", "float", float("-inf")), ("+.INF", "float", float("inf")),
    # and where YAML 1.1 (PyYAML) reads otherwise
    ("010", "int", 10), ("0b101", "str", "0b101"), ("1_000", "str", "1_000"), ("1:30", "str", "1:30"),
    ("on", "str", "on"), ("y", "str", "y"), ("2024-01-01", "str", "2024-01-01"), ("=", "str", "="),
    ("-0x1F", "str", "-0x1F"), ("0o17", "int", 15), ("1e3", "float", 1000), ("~", "null", None),
])
def test_the_yaml_1_2_core_schema(text: str, tag: str, value) -> None:
    assert document.core_schema(text) == (f"tag:yaml.org,2002:{tag}", value)
    assert document.core_schema(".NaN")[1].is_nan()


# What a hurried edit leaves: YAML debris, YAML 1.1 forms, bombs in miniature, huge numbers.
DEBRIS = [":", "- ", "[", "]", "{", "}", "'", '"', "\t", "&a ", "*a", "<<: ", "!!float ", "!!int ", "? ",
          "0", "-0.1", "0.0005", "yes", "null", ".inf", "1_000", "2:30", "2024-01-01", "x", "\n", "  ",
          "010", "08", "on", "0b1", "0o17", "1e3", "+.5", "=", "2,000", ",", "#", "|", ">", "%", "@", "`", "!",
          "---\n", "...", "~", "é", "\ufeff", "\x07", "\r", "[" * 150, "{a: " * 120, "9" * 40, "1.0e+400",
          "1e-400", "0x" + "f" * 40, "socket://h", "emulator://../x"]
SOURCES = [(PLANTS / "demo-line.yaml").read_text().splitlines(keepends=True),
           (PLANTS / "examples" / "coating-line.yaml").read_text().splitlines(keepends=True)]
VALIDATOR = jsonschema.Draft7Validator(plant_schema())


@st.composite
def mangled_plant(draw: st.DrawFn) -> str:
    """An example plant with a few lines dropped or repeated, characters deleted, debris typed in or over."""
    lines = list(draw(st.sampled_from(SOURCES)))
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(lines) - 1))
        action = draw(st.sampled_from(["insert", "replace", "delete", "drop", "repeat"]))
        line = lines[at]
        cut = draw(st.integers(0, len(line)))
        if action in ("insert", "replace"):
            lines[at] = line[:cut] + draw(st.sampled_from(DEBRIS)) + line[cut + (action == "replace"):]
        elif action == "delete":
            lines[at] = line[:cut] + line[cut + 1:]
        elif action == "drop":
            del lines[at]
        else:
            lines.insert(at, draw(st.sampled_from(lines)))
    return "".join(lines)


def _problems(path: Path, loader: type, monkeypatch: pytest.MonkeyPatch) -> list[str] | None:
    """The lines of `load_plant(path)` read with `loader`; None when it loads (and the schema agrees)."""
    monkeypatch.setattr(document, "LOADER", loader)
    try:
        load_plant(path)
    except PlantError as error:
        return error.problems
    VALIDATOR.validate(json.loads(json.dumps(yaml.load(path.read_text(), Loader=loader))))
    return None


def _valid_yaml(text: str, loader: type) -> bool:
    try:
        for _ in yaml.parse(text, Loader=loader):
            pass
    except yaml.YAMLError:
        return False
    return True


@settings(max_examples=300, derandomize=True, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(mangled_plant())
def test_any_mistake_is_a_plant_error_never_a_traceback(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, text: str) -> None:
    """Every problem is one line, "file:line:column: what — what to do" or "file: what — what to do"."""
    path = tmp_path / "plant.yaml"
    path.write_text(text)
    line = re.compile(rf"{re.escape(str(path))}(:\d+:\d+)?: [^\n]+ — [^\n]+")
    said = {name: _problems(path, loader, monkeypatch) for name, loader in LOADERS.items()}
    for problems in said.values():
        assert problems is None or problems
        for problem in problems or ():
            assert line.fullmatch(problem), problem
            assert "Input should" not in problem and "is not valid:" not in problem
    if len({_valid_yaml(text, loader) for loader in LOADERS.values()}) == 1:  # they disagree on tabs in words
        assert len({json.dumps(problems) for problems in said.values()}) == 1
