"""One name per class across the package (style.md §9, issue 20): a name defined twice in
`prc3cfg/` — two `Bus`es, two `Problem`s — leaves every reader asking which one is meant."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "prc3cfg"


def class_definitions(folder: Path) -> dict[str, list[str]]:
    """Every class defined in the Python files under `folder` (nested ones too), by name: where each is."""
    found: dict[str, list[str]] = {}
    for path in sorted(folder.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                found.setdefault(node.name, []).append(f"{path.relative_to(folder)}:{node.lineno}")
    return found


def test_no_class_name_is_defined_twice() -> None:
    twice = {name: places for name, places in class_definitions(PACKAGE).items() if len(places) > 1}
    assert not twice, twice


def test_the_check_finds_a_name_defined_twice(tmp_path: Path) -> None:
    (tmp_path / "one.py").write_text("class Bus:\n    pass\n")
    (tmp_path / "two.py").write_text("def make():\n    class Bus:\n        pass\n")
    assert class_definitions(tmp_path) == {"Bus": ["one.py:1", "two.py:2"]}
