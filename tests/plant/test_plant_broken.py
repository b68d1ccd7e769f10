"""Every broken plant file in `broken/` gives exactly the problems in its `.expected` file.

An `.expected` file holds the lines of `PlantError.problems` without the leading
"path:", one problem a line: "line:column: what is wrong — what would be right". Each file
is read with the pure-Python parser and, when installed, with libyaml: the lines are the same.

Hostile inputs (devices, pipes, huge files, alias and nesting bombs, numbers of a million
digits, hundreds of thousands of nodes, parts or problems) are refused by a limit the message
names, before the work they would cause: these tests would hang or run out of memory
otherwise, so none needs a clock. (bench/plan_time_bench.py --worst times files at the limits.)
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
from prc3cfg.plant import PlantError, document, loader, plant_schema, scalars
from prc3cfg.plant.problems import MAX_PROBLEMS
from prc3cfg.shell import plant_files
from prc3cfg.shell.plant_files import load_plant

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
    (_sparse, "larger than 16 MiB — a plant file is far smaller: check that this is the plant file"),
], ids=["dev-zero", "fifo", "socket", "directory", "16-GiB"])
def test_only_a_regular_file_is_read_and_only_its_first_16_mebibytes(tmp_path: Path, make,
                                                                     problem: str) -> None:
    path = make(tmp_path)
    with pytest.raises(PlantError) as raised:
        load_plant(path)
    assert raised.value.problems == [f"{path}: {problem}"]


def test_a_plant_file_may_be_16_mebibytes(tmp_path: Path) -> None:
    demo = (PLANTS / "demo-line.yaml").read_bytes()
    path = tmp_path / "plant.yaml"
    path.write_bytes(demo + b"#" * (plant_files.MAX_BYTES - len(demo) - 1) + b"\n")
    assert load_plant(path).name == "demo-line"
    path.write_bytes(demo + b"#" * (plant_files.MAX_BYTES - len(demo)) + b"\n")
    with pytest.raises(PlantError, match="larger than 16 MiB"):
        load_plant(path)


ALIAS_BOMB = "plant: &a [x]\nbuses: [" + "*a, " * 100_000 + "]\n"
FLOW_NESTING = "plant: demo\nbuses: " + "[" * 100_000 + "\n"
BLOCK_NESTING = "plant:\n" + "".join(f"{' ' * (depth + 1)}x{depth}:\n" for depth in range(200))
MANY_DIGITS = ("plant: demo\nbuses:\n  - name: a\n    port: emulator://a\n    timeout: " + "9" * 500_000
               + "\n    modules: [{address: 1, name: m1}]\n")
HUGE_EXPONENT = MANY_DIGITS.replace("9" * 500_000, "1.0e+" + "9" * 500_000)
TINY_EXPONENT = MANY_DIGITS.replace("9" * 500_000, "1.0e-" + "9" * 500_000)
#: What the nesting and the long numbers are told, after where.
NESTED = ("lists and mappings nested more than 100 deep — a plant file needs fewer than ten: check the "
          "brackets and the indentation")
DIGITS = ("has more than 28 digits, written out — a plant file's numbers are read exactly: write at most 28 "
          "digits")
BOMB_CASES = [
    (ALIAS_BOMB, "2:9: an alias (*a, used 100000 times) — a plant file does not use aliases: share settings "
                 "with profiles: and a module's profiles: [NAME], or write the value out"),
    (FLOW_NESTING, f"2:107: {NESTED}"),
    (BLOCK_NESTING, f"101:101: {NESTED}"),
    (MANY_DIGITS, f"5:14: timeout 99999999999999999999… {DIGITS}"),
    (HUGE_EXPONENT, f"5:14: timeout 1.0e+999999999999999… {DIGITS}"),
    (TINY_EXPONENT, f"5:14: timeout 1.0e-999999999999999… {DIGITS}"),
]


@pytest.mark.usefixtures("each_loader")
@pytest.mark.parametrize(("text", "problem"), BOMB_CASES,
                         ids=["aliases", "flow-nesting", "block-nesting", "many-digits", "huge-exponent",
                              "tiny-exponent"])
def test_bombs_are_refused_by_the_limit_they_meet_first(tmp_path: Path, text: str, problem: str) -> None:
    path = tmp_path / "plant.yaml"
    path.write_text(text)
    with pytest.raises(PlantError) as raised:
        load_plant(path)
    assert raised.value.problems == [f"{path}:{problem}"]


@pytest.mark.usefixtures("each_loader")
def test_no_node_tree_is_composed(monkeypatch: pytest.MonkeyPatch) -> None:
    """The data is built from the parser's events: PyYAML's composer, which recurses and keeps a
    node and two marks for every key and value, never runs."""

    def composer(*args, **kwargs):
        raise AssertionError("composed")

    monkeypatch.setattr(yaml.composer.Composer, "compose_node", composer)
    monkeypatch.setattr(yaml, "compose", composer)
    assert len(load_plant(PLANTS / "examples" / "coating-line.yaml").modules()) == 30


def _plant(modules: list[str], head: str = "plant: demo\n") -> str:
    return head + "buses:\n  - name: a\n    port: emulator://a\n    modules:\n" + "".join(f"      - {m}\n"
                                                                                          for m in modules)


@pytest.mark.usefixtures("each_loader")
def test_more_nodes_than_the_limit_are_refused_where_it_is_reached(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(document, "MAX_NODES", 50)
    path = tmp_path / "plant.yaml"
    path.write_text("plant: demo\nbuses: [" + "a, " * 60 + "]\n")  # the 51st node is the 46th a
    with pytest.raises(PlantError) as raised:
        load_plant(path)
    assert raised.value.problems == [f"{path}:2:144: more than 50 keys, values, lists and mappings — 8 "
                                     "buses of 30 "
                                     "modules with all 64 programs written out have about 160,000: check "
                                     "that this "
                                     "is the plant file"]


PROGRAMS = "{" + ", ".join(f"{n}: {{position: 0.1, speed: 0.1}}" for n in range(1, 6)) + "}"


#: What stands before the 31st node of module m2 on its line (see below).
NODE_31_BEFORE = ("      - {address: 2, name: m2, programs: " + PROGRAMS[:PROGRAMS.index("4: {")]
                  + "4: {position: 0.1, speed: ")


@pytest.mark.usefixtures("each_loader")
@pytest.mark.parametrize(
    ("text", "problem"),
    [
        # node 31 of module m2: the map, 2 keys and values, programs and its map, 6 nodes a program:
        # program 4's speed
        (
            _plant(["{address: 1, name: m1}", f"{{address: 2, name: m2, programs: {PROGRAMS}}}"]),
            (
                f"7:{len(NODE_31_BEFORE) + 1}:"
                " module m2 has more than 30 keys, values, lists and mappings — a module with every field of"
                " all 64 programs written out has about 2,000: check that this is the plant file"
            ),
        ),
        # node 31 of the rest: 16 up to the modules' list, then 5 for each module's stand-in: m3's name
        (
            _plant(
                [f"{{address: {a}, name: m{a}}}" for a in range(1, 6)],
                head="plant: demo\nprofiles: {p: {}}\n",
            ),
            (
                "9:28: the plant file has more than 30 keys, values, lists and mappings besides its modules"
                " and profiles — 8 buses of 30 modules have about 1,300: check that this is the plant file"
            ),
        ),
    ],
    ids=["module", "the-rest"],
)
def test_a_part_larger_than_the_limit_is_refused_where_it_is_reached(tmp_path: Path, monkeypatch, text,
                                                                     problem) -> None:
    """What one pydantic call sees is bounded: each module, each profile, the rest of the file."""
    monkeypatch.setattr(loader, "MAX_PART_NODES", 30)
    path = tmp_path / "plant.yaml"
    path.write_text(text)
    with pytest.raises(PlantError) as raised:
        load_plant(path)
    assert raised.value.problems == [f"{path}:{problem}"]


MORE = "more than 1000 problems, the file was checked no further — fix those listed and check it again"


@pytest.mark.usefixtures("each_loader")
def test_reading_stops_collecting_after_the_problem_limit(tmp_path: Path) -> None:
    path = tmp_path / "plant.yaml"
    path.write_text("plant: demo\nextra: [" + "on, " * (MAX_PROBLEMS + 100) + "]\n"
                    + _plant(["{address: 1, name: m1}"], ""))
    with pytest.raises(PlantError) as raised:
        load_plant(path)
    problem = ("'on' is read as the boolean true by YAML 1.1 and as text by YAML 1.2 — write true or false, "
               "or quote it")
    columns = [9 + 4 * k for k in range(MAX_PROBLEMS)]
    assert (raised.value.problems == [f"{path}:2:{c}: {problem}" for c in columns]
            + [f"{path}:2:{columns[-1]}: {MORE}"])


def test_checking_stops_after_the_problem_limit_with_the_first_problems(tmp_path: Path) -> None:
    """Parts are checked in file order until there are more problems than are listed: the first are."""
    module = "      - {{address: {a}, name: m{b}-{a}, unmanaged_programs: sometimes}}\n"
    buses = [f"  - name: b{b}\n    port: emulator://b{b}\n    modules:\n"
             + "".join(module.format(a=a, b=b) for a in range(1, 31))
             for b in range(MAX_PROBLEMS // 30 + 2)]
    path = tmp_path / "plant.yaml"
    path.write_text("plant: demo\nbuses:\n" + "".join(buses))
    with pytest.raises(PlantError) as raised:
        load_plant(path)
    *problems, more = raised.value.problems
    # module k: after 2 lines and its bus's 3
    lines = [6 + 33 * (k // 30) + k % 30 for k in range(MAX_PROBLEMS)]
    assert [int(p.split(":")[1]) for p in problems] == lines
    assert problems[0] == (f"{path}:6:54: unmanaged_programs cannot be 'sometimes' — expected one of "
                           "keep, reset")
    assert more == problems[-1].replace(problems[-1].split(": ", 1)[1], MORE)


def test_a_problem_far_into_a_large_file_is_found_where_it_is(tmp_path: Path) -> None:
    """Positions are not kept while reading: a second pass finds the places of the problems only."""
    programs = "{" + ", ".join(f"{n}: {{position: 0.{n:03d}, speed: 0.300}}" for n in range(1, 65)) + "}"
    modules = [f"{{address: {a}, name: m{a}, programs: {programs}}}" for a in range(1, 31)]
    modules[27] = modules[27].replace("40: {position: 0.040, speed: 0.300}",
                                      "40: {position: 0.040, speed: 0.900}")
    path = tmp_path / "plant.yaml"
    path.write_text(_plant(modules))
    column = modules[27].index("speed: 0.900") + len("speed: ") + 9
    with pytest.raises(PlantError) as raised:
        load_plant(path)
    assert raised.value.problems == [f"{path}:33:{column}: speed 0.900 m/s is out of range — speed must be "
                                     "0.001..0.600 m/s"]


@pytest.mark.skipif(not yaml.__with_libyaml__, reason="libyaml is not installed")
def test_past_the_reread_libyaml_words_the_syntax_error(tmp_path: Path, monkeypatch) -> None:
    """The pure parser re-reads the file for its wording only within `_REREAD_EVENTS`: it is fifty
    times slower than libyaml. Beyond, libyaml's words get the same hints where they say the same."""
    monkeypatch.setattr(document, "LOADER", yaml.CSafeLoader)
    path = tmp_path / "plant.yaml"
    path.write_text(_plant(["{address: 1, name: m1}"]) + "  other: 1\n")
    expected = (f"{path}:7:3: this line is indented differently from the lines above it — line it up with "
                "the keys beside it")
    with pytest.raises(PlantError) as raised:
        load_plant(path)
    assert raised.value.problems == [expected]  # PyYAML's words
    monkeypatch.setattr(document, "_REREAD_EVENTS", 5)
    with pytest.raises(PlantError) as raised:
        load_plant(path)
    assert raised.value.problems == [expected]  # libyaml's "did not find expected key"


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
    assert scalars.core_schema(text) == (f"tag:yaml.org,2002:{tag}", value)
    assert scalars.core_schema(".NaN")[1].is_nan()


# What a hurried edit leaves: YAML debris, YAML 1.1 forms, bombs in miniature, huge numbers.
DEBRIS = [":", "- ", "[", "]", "{", "}", "'", '"', "\t", "&a ", "*a", "<<: ", "!!float ", "!!int ", "? ",
          "0", "-0.1", "0.0005", "yes", "null", ".inf", "1_000", "2:30", "2024-01-01", "x", "\n", "  ",
          "010", "08", "on", "0b1", "0o17", "1e3", "+.5", "=", "2,000", ",", "#", "|", ">", "%", "@", "`",
          "!",
          "---\n", "...", "~", "é", "\ufeff", "\x07", "\r", "[" * 150, "{a: " * 120, "9" * 40, "1.0e+400",
          "1e-400", "0x" + "f" * 40, "socket://h", "emulator://../x",
          "!!bool x ", "!!timestamp x ", '!!int "" ', '!!float "_" ', "!!str ", "!foo ", "! ", "!!map ",
          "!!binary "]
#: How the whole file was saved: as written, with a byte order mark, with CRLF line ends, both, without a
#: final newline.
SAVED = [lambda t: t, lambda t: "\ufeff" + t, lambda t: t.replace("\n", "\r\n"),
         lambda t: "\ufeff" + t.replace("\n", "\r\n"), lambda t: t.rstrip("\n")]
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
    return draw(st.sampled_from(SAVED))("".join(lines))


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


@settings(max_examples=100, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(mangled_plant())
def test_any_mistake_is_a_plant_error_never_a_traceback(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                        text: str) -> None:
    """Every problem is one line, "file:line:column: what — what to do" or "file: what — what to do"."""
    said_once(tmp_path, monkeypatch, text)


@pytest.mark.soak
@settings(max_examples=2000, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(mangled_plant())
def test_2000_mistakes_are_plant_errors_never_a_traceback(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                          text: str) -> None:
    said_once(tmp_path, monkeypatch, text)


def said_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, text: str) -> None:
    """`text` loaded by each parser: each problem one line, the same lines from both where both read the
    YAML."""
    path = tmp_path / "plant.yaml"
    path.write_bytes(text.encode("utf-8", "surrogatepass"))
    line = re.compile(rf"{re.escape(str(path))}(:\d+:\d+)?: [^\n]+ — [^\n]+")
    said = {name: _problems(path, loader, monkeypatch) for name, loader in LOADERS.items()}
    for problems in said.values():
        assert problems is None or problems
        for problem in problems or ():
            assert line.fullmatch(problem), problem
            assert "Input should" not in problem and "is not valid:" not in problem
    if len({_valid_yaml(text, loader) for loader in LOADERS.values()}) == 1:  # they disagree on tabs in words
        assert len({json.dumps(problems) for problems in said.values()}) == 1
