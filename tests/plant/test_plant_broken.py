"""Every broken plant file in `broken/` gives exactly the problems in its `.expected` file.

An `.expected` file holds the lines of `PlantError.problems` without the leading
"path:", one problem a line: "line:column: what is wrong — what would be right".
"""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from prc3cfg.errors import UserError
from prc3cfg.plant import PlantError, load_plant

BROKEN = sorted((Path(__file__).parent / "broken").glob("*.yaml"))


def test_there_are_at_least_thirty_broken_files() -> None:
    assert len(BROKEN) >= 30
    assert all(path.with_suffix(".expected").exists() for path in BROKEN)


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


DEMO_LINES = (Path(__file__).parents[2] / "plants" / "demo-line.yaml").read_text().splitlines(keepends=True)
DEBRIS = [":", "- ", "[", "]", "{", "}", "'", '"', "\t", "&a ", "*a", "<<: ", "!!float ", "!!int ", "? ",
          "0", "-0.1", "0.0005", "yes", "null", ".inf", "1_000", "2:30", "2024-01-01", "x", "\n", "  "]


@st.composite
def mangled_demo(draw: st.DrawFn) -> str:
    """The demo plant with a few lines dropped, repeated, or with debris typed into them."""
    lines = list(DEMO_LINES)
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(lines) - 1))
        action = draw(st.sampled_from(["insert", "delete", "drop", "repeat"]))
        line = lines[at]
        cut = draw(st.integers(0, len(line)))
        if action == "insert":
            lines[at] = line[:cut] + draw(st.sampled_from(DEBRIS)) + line[cut:]
        elif action == "delete":
            lines[at] = line[:cut] + line[cut + 1:]
        elif action == "drop":
            del lines[at]
        else:
            lines.insert(at, draw(st.sampled_from(DEMO_LINES)))
    return "".join(lines)


@settings(max_examples=300, suppress_health_check=[HealthCheck.function_scoped_fixture], deadline=None)
@given(mangled_demo())
def test_any_mistake_is_a_plant_error_never_a_traceback(tmp_path: Path, text: str) -> None:
    path = tmp_path / "plant.yaml"
    path.write_text(text)
    try:
        load_plant(path)
    except PlantError as error:
        assert error.problems
        for problem in error.problems:
            assert problem.startswith(f"{path}:") and "\n" not in problem and " — " in problem
            assert "Input should" not in problem and "is not valid:" not in problem
