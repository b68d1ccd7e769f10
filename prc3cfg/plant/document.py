"""A plant file read as YAML: plain data, exact numbers, and where every key and value stands.

PyYAML composes the node tree — with libyaml (`yaml.CSafeLoader`) when it is installed, else
the pure-Python `SafeLoader`; both keep every position. Where libyaml stops (a syntax error,
a limit), the file is parsed again by the pure parser and its first stop is said, so that
messages do not depend on which one ran; they differ only where the two disagree on what is
valid YAML (libyaml takes a tab inside a plain scalar, PyYAML does not). This module builds
the data from the nodes itself so that
- a float keeps the text it was written with: `0.1` becomes `Decimal("0.1")`, never the
  binary 0.1000000000000000055…; integers, booleans, strings are what both YAML versions read;
- a plain scalar that YAML 1.1 (PyYAML) and YAML 1.2 (yaml-language-server, JSON Schema
  tools, most other readers) read differently is a problem that says what to write: `010` is
  8 to one and 10 to the other, `on` true or text, `1:30` 90 or text, `1e3` text or 1000,
  `0b101`, `1_000`, `2024-01-01`, `=`. The 1.2 side is `core_schema`, the YAML 1.2.2 core
  schema's table (§10.3.2); the 1.1 side is PyYAML's resolver (which, unlike the 1.1 type
  repository, reads `y` and `n` as text, as 1.2 does). Quoted scalars and explicit tags are
  never ambiguous. The value kept is the YAML 1.2 reading, what editors and schema tools
  see; the models' objection to it, if any, says what the key wants. A tag on a scalar that
  it cannot be read as, or any tag on a mapping or a list (`!!set`, `!!omap`), is refused;
- a number has at most `MAX_DIGITS` digits written out in full (`1e30` has 31): decimal
  arithmetic is exact to that precision, and reading `1e999999` as an integer would take
  seconds, `1.0e+400` as a float would be infinite;
- `{position: 2,000}` is a decimal comma, not a position of 2 and a key `000`: a problem, and
  the number meant (2.000) is kept;
- a duplicate key is a problem at the second key's line and column (the first value stays);
- a merge key (`<<`) and an alias (`*name`) are refused: profiles are the plant file's way to
  share settings. Aliases are refused rather than expanded within a bound because a problem
  in an aliased value would have one position for several places (a speed above one
  module's max_speed but not another's), and because expanding them is how a 400-byte file
  becomes gigabytes ("billion laughs"). An anchor that no alias uses does nothing;
- every key and value keeps its position, by path: `("buses", 0, "modules", 2, "name")`.

Reading is bounded in time and memory: only a regular file is read (a FIFO could block,
`/dev/zero` never ends), at most `MAX_BYTES` of it; nesting deeper than `MAX_DEPTH` lists and
mappings is refused on the event stream, before the composer (which recurses) sees it.

Problems that stop reading altogether (no such file, not a regular file, too large, not UTF-8,
a control character or a byte order mark after the start, a YAML syntax error, an alias,
too deep, an empty file, a top level that is not a mapping) raise `PlantError` at once; the
others are collected in `Document.problems`. Does not know what a plant file contains.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any

import yaml
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from prc3cfg.files import FileProblem, Why, read_regular
from prc3cfg.plant.problems import DECIMAL_COMMA, FIRST, Path_, PlantError, Problem

#: The composer: libyaml's when PyYAML was built with it (issue 11 wants its speed).
LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
#: Far above a written plant (the 30-module coating-line example is 4 KB, with profiles) and
#: room for two buses as `bus import` writes them (30 modules, all 64 programs: 370 KB, read in
#: 0.4 s); the worst a file this size can do — 350 000 one-character list items, each wrong —
#: takes 8 s and 700 MB to read and report, so the limit is not much higher.
MAX_BYTES = 1024 * 1024
#: A plant file nests 8 deep (plant → buses → bus → modules → module → programs → program → f1).
MAX_DEPTH = 100
#: Python's decimal precision: arithmetic on numbers of more digits would round.
MAX_DIGITS = 28

_BOOL_TAG = "tag:yaml.org,2002:bool"
_FLOAT_TAG = "tag:yaml.org,2002:float"
_INT_TAG = "tag:yaml.org,2002:int"
_MERGE_TAG = "tag:yaml.org,2002:merge"
_NULL_TAG = "tag:yaml.org,2002:null"
_STR_TAG = "tag:yaml.org,2002:str"
_NUMBER_TAGS = (_INT_TAG, _FLOAT_TAG)
_SPECIAL_FLOATS = {".inf": "Infinity", "+.inf": "Infinity", "-.inf": "-Infinity", ".nan": "NaN"}

#: A number in the YAML 1.2 core schema's decimal or exponent notation: "0.300", "-5", "1e3".
DECIMAL_NUMBER = re.compile(r"[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?")
#: The YAML 1.2 core schema (YAML 1.2.2 §10.3.2): a plain scalar's tag by the first pattern it
#: matches, and its value; anything else is a string.
_CORE_SCHEMA: tuple[tuple[str, re.Pattern[str], Callable[[str], Any]], ...] = tuple(
    (tag, re.compile(pattern), value)
    for tag, pattern, value in (
        (_NULL_TAG, r"null|Null|NULL|~|", lambda text: None),
        (_BOOL_TAG, r"true|True|TRUE|false|False|FALSE", lambda text: text.lower() == "true"),
        (_INT_TAG, r"[-+]?[0-9]+", int),
        (_INT_TAG, r"0o[0-7]+", lambda text: int(text[2:], 8)),
        (_INT_TAG, r"0x[0-9a-fA-F]+", lambda text: int(text[2:], 16)),
        (_FLOAT_TAG, DECIMAL_NUMBER.pattern, Decimal),
        (_FLOAT_TAG, r"[-+]?(\.inf|\.Inf|\.INF)|\.nan|\.NaN|\.NAN", lambda text: Decimal(_SPECIAL_FLOATS[text.lower()])),
    )
)
_CORE_TAGS = {tag for tag, _, _ in _CORE_SCHEMA} | {_STR_TAG}  # every tag YAML 1.2 can give a plain scalar
#: How a message says what a reader takes a plain scalar for, by its tag (and value).
_READINGS: dict[str, Callable[[Any], str]] = {
    _INT_TAG: lambda value: _as_written(value),
    _FLOAT_TAG: lambda value: _as_written(value),
    _BOOL_TAG: lambda value: f"the boolean {str(value).lower()}",
    _STR_TAG: lambda value: "text",
    "tag:yaml.org,2002:timestamp": lambda value: "a date",
    "tag:yaml.org,2002:value": lambda value: "the default-value key",
    _MERGE_TAG: lambda value: "a merge key",
}
#: A number in decimal or exponent notation, with YAML 1.1's underscores: whole digits, fraction
#: digits, exponent — to count its digits without building it.
_DECIMAL_FORM = re.compile(r"[-+]?([0-9_]*)(?:\.([0-9_]*))?(?:[eE]([-+]?[0-9]+))?")

#: What to do about a YAML syntax error, by a piece of PyYAML's wording of it (of libyaml's too
#: where its composer's differs); the flag says the error is best shown where the construct
#: began (an unclosed quote), not where PyYAML gave up (the end of the file).
_SYNTAX_HINTS = {
    "'\\t'": ("a tab character — indent with spaces; YAML does not allow tabs here", False),
    "mapping values are not allowed here": ("a colon where no key can start — indent this key "
                                            "under its parent, or put a value that contains ': ' in quotes", False),
    "could not find expected ':'": ("a line that is not 'key: value' — add the colon, or start a list "
                                    "item with '- '", False),
    "expected <block end>": ("this line is indented differently from the lines above it — line it up "
                             "with the keys beside it", False),
    "while scanning a quoted scalar": ("a quoted value that never ends — close the quote", True),
    "expected a single document": ("a second YAML document (---) — a plant file is one document", False),
    "found duplicate anchor": ("an anchor (&name) given twice — a plant file needs no anchors: remove them", False),
}
#: What PyYAML refuses as not printable, and a byte order mark after the start, which PyYAML
#: reads as part of a key and libyaml does not.
_NOT_TEXT = re.compile(f"{yaml.reader.Reader.NON_PRINTABLE.pattern}|(?!\\A)\ufeff")
#: The tag of a mapping or a list that has none written, and what a message calls it.
_COLLECTIONS = {MappingNode: ("tag:yaml.org,2002:map", "mapping"), SequenceNode: ("tag:yaml.org,2002:seq", "list")}
Position = tuple[int, int]  # 1-based line and column


@dataclass
class Document:
    """The data of one YAML file, the positions of its keys and values, the SHA-256 of its bytes."""

    name: str
    data: dict[Any, Any]
    #: path → (position of its key, or None for a list item; position of its value)
    positions: dict[Path_, tuple[Position | None, Position]]
    sha256: str
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
    data = _read_bytes(path, name)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        before = error.object[: error.start].decode("utf-8", "replace")
        line, column = _line_column(before, len(before))
        raise PlantError([f"{name}:{line}:{column}: not UTF-8 text — save the file as UTF-8"]) from None
    if found := _NOT_TEXT.search(text):
        line, column = _line_column(text, found.start())
        what = "a byte order mark" if found.group() == "\ufeff" else "a control character"
        raise PlantError([f"{name}:{line}:{column}: {what} (#x{ord(found.group()):04x}) — remove it; "
                          "a plant file is plain text"])
    try:
        _check_events(name, text)
        root = yaml.compose(text, Loader=LOADER)
    except yaml.MarkedYAMLError as error:
        raise PlantError([_syntax_error(name, error)]) from None
    if root is None or (isinstance(root, ScalarNode) and root.tag == _NULL_TAG):
        raise PlantError([f"{name}:1:1: the file is empty — a plant file starts with 'plant: NAME' and 'buses:'"])
    if not isinstance(root, MappingNode):
        line, column = _position(root)
        kind = "a list" if isinstance(root, SequenceNode) else f"the value {root.value!r}"
        raise PlantError([f"{name}:{line}:{column}: the top level is {kind}, not a mapping "
                          "— a plant file is a mapping with 'plant:' and 'buses:'"])
    reader = _Reader()
    reader.positions[()] = (None, _position(root))
    result = reader.value(root, ())
    return Document(name, result, reader.positions, hashlib.sha256(data).hexdigest(), reader.problems)


#: What to do about a plant path that cannot be read, by why.
_REMEDIES = {
    Why.MISSING: "check the path",
    Why.DIRECTORY: "give the plant file (*.yaml) in it",
    Why.NOT_A_FILE: "give the plant file (*.yaml) itself",
    Why.UNREADABLE: "check the path and its permissions",
    Why.TOO_LARGE: "a plant file is far smaller: check that this is the plant file",
}


def _read_bytes(path: Path, name: str) -> bytes:
    """The bytes of the plant file, at most `MAX_BYTES` (`prc3cfg.files.read_regular`)."""
    try:
        return read_regular(path, MAX_BYTES)
    except FileProblem as problem:
        raise PlantError([f"{name}: {problem} — {_REMEDIES[problem.why]}"]) from None


def _check_events(name: str, text: str) -> None:
    """Refuse what composing would recurse on (deep nesting) or share (aliases), before it does.

    When libyaml stops (a syntax error, a limit), what is said is where the pure parser stops
    first: the two word syntax errors differently, and may meet them in another order.
    """
    try:
        _events_within_limits(name, text, LOADER)
    except (yaml.MarkedYAMLError, PlantError):
        if LOADER is yaml.SafeLoader:
            raise
        _events_within_limits(name, text, yaml.SafeLoader)
        raise  # the pure parser takes the whole file: libyaml's stop stands


def _events_within_limits(name: str, text: str, loader: type) -> None:
    """`PlantError` for nesting deeper than `MAX_DEPTH` or any alias, from `loader`'s events."""
    depth = 0
    aliases: dict[str, list[Position]] = {}  # each alias name, where it is used
    for event in yaml.parse(text, Loader=loader):
        if isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            if depth > MAX_DEPTH:
                line, column = _position(event)
                raise PlantError([f"{name}:{line}:{column}: lists and mappings nested more than {MAX_DEPTH} "
                                  "deep — a plant file needs fewer than ten: check the brackets and the indentation"])
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1
        elif isinstance(event, yaml.AliasEvent):
            aliases.setdefault(event.anchor, []).append(_position(event))
    lines = []
    for anchor, uses in aliases.items():
        (line, column), times = uses[0], f", used {len(uses)} times" if len(uses) > 1 else ""
        lines.append(f"{name}:{line}:{column}: an alias (*{anchor}{times}) — a plant file does not use aliases: "
                     "share settings with profiles: and a module's profiles: [NAME], or write the value out")
    if lines:
        raise PlantError(lines)


class _Reader:
    """Builds plain data from YAML nodes, recording positions and the problems found on the way."""

    def __init__(self) -> None:
        self.constructor = yaml.SafeLoader("")
        self.positions: dict[Path_, tuple[Position | None, Position]] = {}
        self.problems: list[Problem] = []

    def value(self, node: Node, path: Path_) -> Any:
        if type(node) in _COLLECTIONS and node.tag != _COLLECTIONS[type(node)][0]:  # !!set, !!omap, !!float
            self.problems.append(Problem(path, f"a {_COLLECTIONS[type(node)][1]} cannot be read as {_written(node.tag)} "
                                         "— remove the tag; a plant file needs none", at=_position(node)))
        if isinstance(node, MappingNode):
            return self.mapping(node, path)
        if isinstance(node, SequenceNode):
            items = []
            for index, item in enumerate(node.value):
                self.positions[path + (index,)] = (None, _position(item))
                items.append(self.value(item, path + (index,)))
            return items
        key = path[-1] if path and isinstance(path[-1], str) else ""
        return self.scalar(node, path, key)

    def mapping(self, node: MappingNode, path: Path_) -> dict[Any, Any]:
        result: dict[Any, Any] = {}
        before: tuple[Any, Node] | None = None  # the key and value node read last
        for key_node, value_node in node.value:
            key_at = _position(key_node)
            if key_node.tag == _MERGE_TAG:
                self.problems.append(Problem(path, "a YAML merge key (<<) — share settings with "
                                             "profiles: and a module's profiles: [NAME] instead", at=key_at))
                continue
            if before is not None and node.flow_style and _split_number(before[1], key_node, value_node):
                written = f"{before[1].value},{key_node.value}"
                point = written.replace(",", ".")
                result[before[0]] = Decimal(point)  # what was meant, for the models to judge
                self.problems.append(Problem(path, DECIMAL_COMMA.format(what=before[0], written=written, point=point),
                                             at=_position(before[1]), models_fix=True))
                continue
            key = self.scalar(key_node, path, "key") if isinstance(key_node, ScalarNode) else None
            if key is None or not _hashable(key):
                self.problems.append(Problem(path, "a key that is not a name or a number — write a plain key", at=key_at))
                continue
            if key in result:
                first = self.positions[path + (key,)][0]
                self.problems.append(Problem(path, f"duplicate key '{key}' — it is already given at "
                                             f"{first[0]}:{first[1]}; give each key once", at=key_at))
                continue
            self.positions[path + (key,)] = (key_at, key_at if _empty(value_node) else _position(value_node))
            result[key] = self.value(value_node, path + (key,))
            before = (key, value_node)
        return result

    def scalar(self, node: ScalarNode, path: Path_, key: str) -> Any:
        """The value of `node` (under `key`, for messages); a problem when it is not one value to every reader."""
        text, at = node.value, _position(node)
        plain = not node.style and node.tag == self.constructor.resolve(ScalarNode, text, (True, False))
        core_tag, core_value = _core_rule(text) if plain else (None, None)
        if (node.tag in _NUMBER_TAGS or core_tag in _NUMBER_TAGS) and _too_long(text):
            self.problems.append(Problem(path, f"{_subject(key, text, False)} has more than {MAX_DIGITS} digits, "
                                         f"written out — a plant file's numbers are read exactly: write at most "
                                         f"{MAX_DIGITS} digits", at=at))
            return text
        if plain:
            # a tag the core schema does not have (a date, `=`) differs without building a value
            yaml11 = (node.tag, self.construct(node) if node.tag in _CORE_TAGS else None)
            yaml12 = (core_tag, core_value(text))
            if (yaml11[0], str(yaml11[1])) != (yaml12[0], str(yaml12[1])):  # str: NaN is not equal to NaN
                subject = _subject(key, text, _STR_TAG in (yaml11[0], yaml12[0]))
                self.problems.append(Problem(path, _ambiguity(subject, yaml11, yaml12), at=at, models_fix=True))
                return yaml12[1]
            return yaml11[1]
        try:
            return self.construct(node)
        except (yaml.YAMLError, ValueError, TypeError, ArithmeticError):
            self.problems.append(Problem(path, f"'{text}' cannot be read as {_written(node.tag)} — remove the tag; "
                                         "a plant file needs none", at=at))
            return text

    def construct(self, node: ScalarNode) -> Any:
        """The YAML 1.1 value of a scalar; a float as an exact `Decimal`."""
        return self.decimal(node) if node.tag == _FLOAT_TAG else self.constructor.construct_object(node)

    def decimal(self, node: ScalarNode) -> Decimal:
        """A float exactly as written: "0.1" is Decimal("0.1")."""
        text = node.value.replace("_", "")
        try:
            return Decimal(_SPECIAL_FLOATS.get(text.lower(), text))
        except InvalidOperation:  # YAML 1.1 sexagesimal "1:30.5"
            return Decimal(repr(self.constructor.construct_object(node)))


def core_schema(text: str) -> tuple[str, Any]:
    """The tag and value the YAML 1.2 core schema gives the plain scalar `text`."""
    tag, value = _core_rule(text)
    return tag, value(text)


def _core_rule(text: str) -> tuple[str, Callable[[str], Any]]:
    """The core schema's tag for `text`, and how to build its value (not built yet: it may be long)."""
    return next(((tag, value) for tag, pattern, value in _CORE_SCHEMA if pattern.fullmatch(text)), (_STR_TAG, str))


def _ambiguity(subject: str, yaml11: tuple[str, Any], yaml12: tuple[str, Any]) -> str:
    """How YAML 1.1 and 1.2 read `subject`, and what to write so that both read one thing."""
    said = (f"{subject} is read as {_READINGS[yaml11[0]](yaml11[1])} by YAML 1.1 "
            f"and as {_READINGS[yaml12[0]](yaml12[1])} by YAML 1.2")
    if yaml11[0] in _NUMBER_TAGS and yaml12[0] in _NUMBER_TAGS:  # only a leading zero does that: 010
        return f"{said} — write {_as_written(yaml12[1])} (or {_as_written(yaml11[1])}), without the leading zero"
    tag, value = yaml11 if yaml12[0] == _STR_TAG else yaml12
    if tag in _NUMBER_TAGS:
        return f"{said} — write {_as_written(value)}, or quote it"
    if tag == _BOOL_TAG:
        return f"{said} — write true or false, or quote it"
    return f"{said} — quote it"


def _as_written(number: int | Decimal) -> str:
    """A number as both YAML versions read it: 90, 0.001, 1000 (not 1E+3)."""
    return format(number, "f") if isinstance(number, Decimal) and number.is_finite() else str(number)


def _too_long(text: str) -> bool:
    """More than `MAX_DIGITS` digits written out: 1e30 has 31, 1.0e-400 has 402; 0x1F, 1:30 their own."""
    form = _DECIMAL_FORM.fullmatch(text)
    if form is None:
        return sum(c.isalnum() for c in text) > MAX_DIGITS
    whole, fraction = (form[1] or "").replace("_", ""), (form[2] or "").replace("_", "")
    exponent = (form[3] or "0").lstrip("+")
    if len(exponent.lstrip("-0")) > 2:  # 100 or more: more than MAX_DIGITS either way, and not worth an int
        return True
    shift = int(exponent)
    return max(len(whole) + shift, 1) + max(len(fraction) - shift, 0) > MAX_DIGITS


def _split_number(number: Node, key: Node, value: Node) -> bool:
    """`{position: 2,000}`: a whole number, a comma and digits that became a key without a value."""
    return bool(isinstance(number, ScalarNode) and not number.style and re.fullmatch(r"[-+]?[0-9]+", number.value)
                and isinstance(key, ScalarNode) and not key.style and re.fullmatch(r"[0-9]+", key.value)
                and _empty(value) and key.start_mark.index == number.end_mark.index + 1)


def _subject(key: str, text: str, quoted: bool) -> str:
    """A scalar as a message names it: "address 010", "alarm 'on'"; shortened when long."""
    short = text if len(text) <= 24 else text[:20] + "…"
    return f"{key} {repr(short) if quoted else short}".lstrip()


def mappings_in(data: Any, path: Path_) -> Iterator[tuple[Path_, dict[Any, Any]]]:
    """The mappings in the list that `data` holds under `path[-1]`, with their paths; others skipped."""
    items = data.get(path[-1]) if isinstance(data, dict) else None
    for index, item in enumerate(items if isinstance(items, list) else ()):
        if isinstance(item, dict):
            yield path + (index,), item


def _written(tag: str) -> str:
    """A tag as a file writes it: `!!float`, `!env`."""
    return tag.replace("tag:yaml.org,2002:", "!!", 1)


def _empty(node: Node) -> bool:
    return isinstance(node, ScalarNode) and node.tag == _NULL_TAG and not node.value


def _position(node: Node | yaml.Event) -> Position:
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
