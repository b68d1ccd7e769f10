"""Every broken plant file in `broken/` gives exactly the problems in its `.expected` file.

An `.expected` file holds the lines of `PlantError.problems` without the leading
"path:", one problem a line: "line:column: what is wrong — what would be right".
"""

from __future__ import annotations

from pathlib import Path

import pytest

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
