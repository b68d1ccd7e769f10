"""A plant file read as YAML: plain data, exact numbers, and where every key and value stands.

PyYAML (pure-Python `SafeLoader`, so messages do not depend on whether libyaml is
installed) composes the node tree; this module builds the data from it itself so that
- a float keeps the text it was written with: `0.1` becomes `Decimal("0.1")`, never the
  binary 0.1000000000000000055…; integers, booleans, strings are YAML 1.1 as usual;
- a duplicate key is a problem at the second key's line and column (the first value stays);
- a merge key (`<<`) is refused: profiles are the plant file's way to share settings;
- every key and value keeps its position, by path: `("buses", 0, "modules", 2, "name")`.

Problems that stop reading altogether (no such file, not UTF-8, a YAML syntax error, an
empty file, a top level that is not a mapping) raise `PlantError` at once; the others are
collected in `Document.problems`. Does not know what a plant file contains.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any

import yaml
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from prc3cfg.plant.problems import FIRST, Path_, PlantError, Problem

_FLOAT_TAG = "tag:yaml.org,2002:float"
_MERGE_TAG = "tag:yaml.org,2002:merge"
_NULL_TAG = "tag:yaml.org,2002:null"
_SPECIAL_FLOATS = {".inf": "Infinity", "+.inf": "Infinity", "-.inf": "-Infinity", ".nan": "NaN"}

#: What to do about a YAML syntax error, by a piece of PyYAML's wording of it; the flag
#: says the error is best shown where the construct began (an unclosed quote), not where
#: PyYAML gave up (the end of the file).
_SYNTAX_HINTS = {
    "'\\t'": ("a tab character — indent with spaces; YAML does not allow tabs here", False),
    "mapping values are not allowed here": ("a colon where no key can start — indent this key "
                                            "under its parent, or put a value that contains ': ' in quotes", False),
    "could not find expected ':'": ("a line that is not 'key: value' — add the colon, or start a list "
                                    "item with '- '", False),
    "expected <block end>": ("this line is indented differently from the lines above it — line it up "
                             "with the keys beside it", False),
    "while scanning a quoted scalar": ("a quoted value that never ends — close the quote", True),
    "found undefined alias": ("an alias (*name) with no anchor (&name) before it — define the anchor first", False),
    "expected a single document": ("a second YAML document (---) — a plant file is one document", False),
}

Position = tuple[int, int]  # 1-based line and column


@dataclass
class Document:
    """The data of one YAML file and the positions of its keys and values."""

    name: str
    data: dict[Any, Any]
    #: path → (position of its key, or None for a list item; position of its value)
    positions: dict[Path_, tuple[Position | None, Position]]
    problems: list[Problem] = field(default_factory=list)

    def position(self, path: Path_, at_key: bool = False) -> Position:
        """Where `path` is, or the nearest enclosing node; parts the file does not have are skipped.

        Skipping lets a path of the models' shape find the file's shape: a chain written
        as a list has no `programs` key, and pydantic's `[key]` marks a mapping key.
        """
        found: Path_ = ()
        for part in path:
            if found + (part,) in self.positions:
                found += (part,)
        key, value = self.positions[found]
        return key if at_key and key is not None else value

    def format(self, problem: Problem) -> tuple[Position, str]:
        line, column = problem.at or self.position(problem.path, problem.at_key)
        message = problem.message
        if problem.first is not None:
            message = message.replace(FIRST, f"first at line {self.position(problem.first)[0]}")
        return (line, column), f"{self.name}:{line}:{column}: {message}"


def read_document(path: Path) -> Document:
    """Read and parse `path`; `PlantError` if it is not a YAML mapping at all."""
    name = str(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise PlantError([f"{name}: no such file — check the path"]) from None
    except IsADirectoryError:
        raise PlantError([f"{name}: is a directory — give the plant file (*.yaml) in it"]) from None
    except UnicodeDecodeError as error:
        before = error.object[: error.start].decode("utf-8", "replace")
        line, column = _line_column(before, len(before))
        raise PlantError([f"{name}:{line}:{column}: not UTF-8 text — save the file as UTF-8"]) from None
    except OSError as error:
        raise PlantError([f"{name}: cannot read it ({error.strerror}) — check the path and its permissions"]) from None
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.MarkedYAMLError as error:
        raise PlantError([_syntax_error(name, error)]) from None
    except yaml.reader.ReaderError as error:
        line, column = _line_column(text, error.position)
        raise PlantError([f"{name}:{line}:{column}: a control character (#x{error.character:04x}) "
                          "— remove it; a plant file is plain text"]) from None
    if root is None or (isinstance(root, ScalarNode) and root.tag == _NULL_TAG):
        raise PlantError([f"{name}:1:1: the file is empty — a plant file starts with 'plant: NAME' and 'buses:'"])
    if not isinstance(root, MappingNode):
        line, column = _position(root)
        kind = "a list" if isinstance(root, SequenceNode) else f"the value {root.value!r}"
        raise PlantError([f"{name}:{line}:{column}: the top level is {kind}, not a mapping "
                          "— a plant file is a mapping with 'plant:' and 'buses:'"])
    reader = _Reader()
    reader.positions[()] = (None, _position(root))
    data = reader.value(root, ())
    return Document(name, data, reader.positions, reader.problems)


class _Reader:
    """Builds plain data from YAML nodes, recording positions and the problems found on the way."""

    def __init__(self) -> None:
        self.constructor = yaml.SafeLoader("")
        self.positions: dict[Path_, tuple[Position | None, Position]] = {}
        self.problems: list[Problem] = []
        self.open: set[int] = set()  # nodes being built: an alias to one of them is a cycle

    def value(self, node: Node, path: Path_) -> Any:
        if id(node) in self.open:
            self.problems.append(Problem(path, "an alias that contains itself — write the value out"))
            return None
        self.open.add(id(node))
        try:
            if isinstance(node, MappingNode):
                return self.mapping(node, path)
            if isinstance(node, SequenceNode):
                items = []
                for index, item in enumerate(node.value):
                    self.positions[path + (index,)] = (None, _position(item))
                    items.append(self.value(item, path + (index,)))
                return items
            return self.scalar(node, path)
        finally:
            self.open.discard(id(node))

    def mapping(self, node: MappingNode, path: Path_) -> dict[Any, Any]:
        result: dict[Any, Any] = {}
        for key_node, value_node in node.value:
            key_at = _position(key_node)
            if key_node.tag == _MERGE_TAG:
                self.problems.append(Problem(path, "a YAML merge key (<<) — share settings with "
                                             "profiles: and a module's profiles: [NAME] instead", at=key_at))
                continue
            key = self.scalar(key_node, path) if isinstance(key_node, ScalarNode) else None
            if key is None or not _hashable(key):
                self.problems.append(Problem(path, "a key that is not a name or a number — write a plain key", at=key_at))
                continue
            if key in result:
                first = self.positions[path + (key,)][0]
                self.problems.append(Problem(path, f"duplicate key '{key}' — it is already given at "
                                             f"{first[0]}:{first[1]}; give each key once", at=key_at))
                continue
            empty = isinstance(value_node, ScalarNode) and value_node.tag == _NULL_TAG and not value_node.value
            self.positions[path + (key,)] = (key_at, key_at if empty else _position(value_node))
            result[key] = self.value(value_node, path + (key,))
        return result

    def scalar(self, node: ScalarNode, path: Path_) -> Any:
        try:
            if node.tag == _FLOAT_TAG:
                return self.decimal(node)
            return self.constructor.construct_object(node)
        except (yaml.YAMLError, ValueError, TypeError, ArithmeticError):
            self.problems.append(Problem(path, f"'{node.value}' cannot be read as {node.tag} — remove the tag; "
                                         "a plant file needs none"))
            return node.value

    def decimal(self, node: ScalarNode) -> Decimal:
        """A float exactly as written: "0.1" is Decimal("0.1")."""
        text = node.value.replace("_", "")
        try:
            return Decimal(_SPECIAL_FLOATS.get(text.lower(), text))
        except InvalidOperation:  # YAML 1.1 sexagesimal "1:30.5"
            return Decimal(repr(self.constructor.construct_object(node)))


def mappings_in(data: Any, path: Path_) -> Iterator[tuple[Path_, dict[Any, Any]]]:
    """The mappings in the list that `data` holds under `path[-1]`, with their paths; others skipped."""
    items = data.get(path[-1]) if isinstance(data, dict) else None
    for index, item in enumerate(items if isinstance(items, list) else ()):
        if isinstance(item, dict):
            yield path + (index,), item


def _position(node: Node) -> Position:
    return node.start_mark.line + 1, node.start_mark.column + 1


def _line_column(text: str, offset: int) -> Position:
    before = text[:offset]
    return before.count("\n") + 1, offset - (before.rfind("\n") + 1) + 1


def _hashable(key: Any) -> bool:
    try:
        hash(key)
    except TypeError:
        return False
    return True


def _syntax_error(name: str, error: yaml.MarkedYAMLError) -> str:
    problem = error.problem or error.context or "not valid YAML"
    said = f"{problem} {error.context or ''}"
    hint, at_start = next((h for piece, h in _SYNTAX_HINTS.items() if piece in said), (None, False))
    if hint is None:
        where = f" ({error.context} at line {error.context_mark.line + 1})" if error.context and error.context_mark else ""
        hint = f"not valid YAML: {problem}{where} — check the indentation, colons, quotes and brackets here"
    mark = (error.context_mark if at_start else error.problem_mark) or error.problem_mark or error.context_mark
    return f"{name}:{mark.line + 1}:{mark.column + 1}: {hint}"
