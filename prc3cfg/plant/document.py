"""A plant file read as YAML: plain data, exact numbers, the problems of its YAML, and their places.

PyYAML parses — with libyaml (`yaml.CSafeLoader`) when it is installed, else the pure-Python
`SafeLoader`. Its events are read in one pass that builds the data directly: no node tree (a
PyYAML node and its two marks cost several hundred bytes; a large plant has 160,000 of them),
and no position kept for a key or value that nothing is wrong with (`Document.lines` finds the
places of the problems it is given); only `spans`, which `adopt` splices by, keeps each node's
offsets in the text, read by the same pass. Where libyaml stops (a syntax error, a limit), the file is
parsed again by the pure parser and its first stop is said, so that messages do not depend on
which one ran; they differ only where the two disagree on what is valid YAML (libyaml takes a
tab inside a plain scalar, PyYAML does not), and where the pure parser would take more than
about a second to get there (`_REREAD_EVENTS`). This module builds the data itself so that
- every untagged scalar is read as `prc3cfg.plant.scalars` reads it: exact numbers (`0.1` is
  `Decimal("0.1")`), the YAML 1.2 reading, and a problem where YAML 1.1 reads it otherwise or
  where it has more digits than decimal arithmetic keeps exact;
- a tag (`!!bool x`, `!!str` on a key, `!!omap` on a list, `!env`, `!`) is refused wherever it
  is written: a plant file uses none, and PyYAML's constructors, which would read a tagged
  scalar, fail on many (`!!int ""`, `!!timestamp x`) with Python errors. A tagged scalar
  keeps its text, so that the tag is the only problem said there;
- `{position: 2,000}` is a decimal comma, not a position of 2 and a key `000`: a problem, and
  the number meant (2.000) is kept;
- a duplicate key is a problem at the second key's line and column (the first value stays);
- a merge key (`<<`) and an alias (`*name`) are refused: profiles are the plant file's way to
  share settings. Aliases are refused rather than expanded within a bound because a problem
  in an aliased value would have one position for several places (a speed above one
  module's max_speed but not another's), and because expanding them is how a 400-byte file
  becomes gigabytes ("billion laughs"). An anchor that no alias uses does nothing;
- a problem names its place by path, `("buses", 0, "modules", 2, "name")`, or by the line
  and column it was found at.

Reading is bounded in time and memory: the bytes are handed over, read by the shell within
its bounds (`prc3cfg.shell.plant_files`); more than `MAX_NODES` keys, values, lists and
mappings, or nesting deeper than `MAX_DEPTH`, is refused on the event stream where it is
reached; a scalar's reading is worked out once per text (`scalars.Readings`); at most
`MAX_PROBLEMS` problems are kept, and one more to show that there are more.

Problems that stop reading altogether (not UTF-8, a control character or a byte order mark
after the start, a YAML syntax error, a limit, an alias, an empty file, a top level that is
not a mapping) raise `PlantError` at once; the others are collected in `Document.problems`.
Does not know what a plant file contains, nor what a scalar's text means (`scalars`). Pure: bytes in.

It is long because it is one reader: the same pass over the events builds the data, finds the
places of problems (`wanted`) and records spans, so that paths and offsets always match the data;
and what stops it — the event stream's limits, the pure parser's re-read, a syntax error in words —
is raised from inside that pass. The meaning of a scalar's text, which needs none of this, is `scalars`.
"""

from __future__ import annotations

import hashlib
import itertools
import re
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from decimal import Decimal
from types import MappingProxyType
from typing import Any

import yaml
from yaml.composer import ComposerError
from yaml.events import (
    AliasEvent,
    CollectionStartEvent,
    DocumentStartEvent,
    MappingEndEvent,
    MappingStartEvent,
    ScalarEvent,
    SequenceEndEvent,
    SequenceStartEvent,
    StreamEndEvent,
)

from prc3cfg.plant.problems import DECIMAL_COMMA, FIRST, MAX_PROBLEMS, Path_, PlantError, Problem
from prc3cfg.plant.scalars import MERGE_TAG, NULL_TAG, Readings

#: The parser: libyaml's when PyYAML was built with it (issue 11 wants its speed).
LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
#: Keys, values, lists and mappings: 8 buses × 30 modules managing all 64 programs, each program
#: a flow mapping of position, speed, dwell and relative speed, have 157,000; with f1, f2 and
#: next on every program, 372,000. The worst a file of this many can do (every one wrong) is
#: read and reported in a few seconds and well under 200 MB (bench/plan_time_bench.py --worst).
MAX_NODES = 400_000
#: A plant file nests 8 deep (plant → buses → bus → modules → module → programs → program → f1).
MAX_DEPTH = 100
#: Events the pure parser re-reads where libyaml stopped (about a second of it): its first stop
#: there is said. Beyond, libyaml's stop stands, in libyaml's words.
_REREAD_EVENTS = 50_000

_NODE_EVENTS = frozenset({ScalarEvent, AliasEvent, MappingStartEvent, SequenceStartEvent})

#: The two sides of a decimal comma that a flow mapping split: `{position: 2,000}`.
_WHOLE = re.compile(r"[-+]?[0-9]+")
_DIGITS = re.compile(r"[0-9]+")
#: What to do about a YAML syntax error, by a piece of PyYAML's wording of it (of libyaml's too
#: where it differs: libyaml's stop is said as it is when the pure parser does not re-read the
#: file, see `_REREAD_EVENTS`); the flag says the error is best shown where the construct
#: began (an unclosed quote), not where PyYAML gave up (the end of the file).
_INDENTED = ("this line is indented differently from the lines above it — line it up with the keys beside it",
             False)
_COLON = ("a colon where no key can start — indent this key under its parent, or put a value that contains "
          "': ' in quotes", False)
_SYNTAX_HINTS = {
    "'\\t'": ("a tab character — indent with spaces; YAML does not allow tabs here", False),
    "mapping values are not allowed here": _COLON,
    "mapping values are not allowed in this context": _COLON,
    "could not find expected ':'": ("a line that is not 'key: value' — add the colon, or start a list "
                                    "item with '- '", False),
    "expected <block end>": _INDENTED,
    "did not find expected key": _INDENTED,
    "did not find expected '-' indicator": _INDENTED,
    "while scanning a quoted scalar": ("a quoted value that never ends — close the quote", True),
    "expected a single document": ("a second YAML document (---) — a plant file is one document", False),
    "found duplicate anchor": ("an anchor (&name) given twice — a plant file needs no anchors: remove them",
                               False),
}
#: What PyYAML refuses as not printable (`_not_text` looks for a byte order mark apart).
_NOT_PRINTABLE = yaml.reader.Reader.NON_PRINTABLE
_BYTE_ORDER_MARK = "\ufeff"
#: The tag of a mapping or a list that has none written.
_COLLECTIONS: dict[type[CollectionStartEvent], str] = {MappingStartEvent: "tag:yaml.org,2002:map",
                                                       SequenceStartEvent: "tag:yaml.org,2002:seq"}
Position = tuple[int, int]  # 1-based line and column


@dataclass
class Document:
    """The data of one YAML file, the problems found reading it, the SHA-256 of its bytes, its text."""

    name: str
    text: str
    data: dict[Any, Any]
    sha256: str
    problems: list[Problem] = field(default_factory=list)

    def lines(self, problems: Sequence[Problem]) -> list[tuple[Position, str]]:
        """Each problem as its position and its line, "file:line:column: message", in the order given.

        A problem's path is first followed in the data, skipping the parts the file does not
        have, so that a path of the models' shape finds the file's shape: a chain written as a
        list has no `programs` key, and pydantic's `[key]` marks a mapping key; where nothing
        is left, the nearest enclosing node is meant. The places of the paths so found are
        read in one more pass over the file (`_Reader` with `wanted`), only when needed.
        """
        paths = [(_in_file(self.data, p.path), None if p.first is None else _in_file(self.data, p.first))
                 for p in problems]
        wanted: dict[Any, Any] = {}
        for problem, (path, first) in zip(problems, paths):
            if problem.at is None:
                _want(wanted, path)
            if first is not None:
                _want(wanted, first)
        places = self._locate(wanted) if any(p.at is None or p.first is not None for p in problems) else {}
        result = []
        for problem, (path, first) in zip(problems, paths):
            if problem.at is not None:
                line, column = problem.at
            else:
                key, value = places[path]
                line, column = key if problem.at_key and key is not None else value
            message = problem.message
            if first is not None:
                message = message.replace(FIRST, f"first at line {places[first][1][0]}")
            result.append(((line, column), f"{self.name}:{line}:{column}: {message}"))
        return result

    def _locate(self, wanted: dict[Any, Any]) -> dict[Path_, tuple[Position | None, Position]]:
        """path → (position of its key, or None for a list item or the top; position of its value)."""
        reader = _Reader(_Events(self.name, self.text, LOADER), wanted)
        reader.read()
        return reader.positions


@dataclass(slots=True)
class Span:
    """Where a scalar, mapping or list of a file is in its text (`spans`): from `start` to `end`,
    offsets in the text (a block collection ends after its last child's text). A scalar has its
    text as `written` (unquoted) and whether it is `plain`; a collection whether it is `flow`, its
    `children` (by key, read as `parse_document` reads keys, or in order) and its `keys`' offsets."""

    start: int
    end: int
    flow: bool = False
    written: str | None = None
    plain: bool = True
    children: dict[Any, Span] | list[Span] = field(default_factory=dict)
    keys: dict[Any, int] = field(default_factory=dict)

    def items(self) -> Iterator[tuple[Any, Span]]:
        """Each child with its key or index."""
        return iter(self.children.items()) if isinstance(self.children, dict) else enumerate(self.children)


def spans(text: str) -> Span:
    """The span of every node of `text`, a YAML text `parse_document` took: read again by the same
    reader (`_Reader` with `spans`), so that its keys are the data's. The top node's span."""
    reader = _Reader(_Events("", text, LOADER), spans=True)
    reader.read()
    assert reader.top is not None  # a text that was read has a top node
    return reader.top


def parse_document(name: str, data: bytes) -> Document:
    """Parse `data`, the bytes of the file `name`; `PlantError` if it is not a YAML mapping at all."""
    # UTF-16's byte order mark: what Windows PowerShell 5.1's > writes
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise PlantError([f"{name}:1:1: UTF-16 text, as Windows PowerShell 5.1's > writes it — a plant file "
                          "is UTF-8: write it with "
                          "--out (prc3cfg import … --out plant.yaml), or save it as UTF-8"])
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        before = error.object[: error.start].decode("utf-8", "replace")
        line, column = _line_column(before, len(before))
        raise PlantError([f"{name}:{line}:{column}: not UTF-8 text — save the file as UTF-8"]) from None
    if (at := _not_text(text)) is not None:
        line, column = _line_column(text, at)
        what = "a byte order mark" if text[at] == _BYTE_ORDER_MARK else "a control character"
        raise PlantError([f"{name}:{line}:{column}: {what} (#x{ord(text[at]):04x}) — remove it; "
                          "a plant file is plain text"])
    reader = _read(name, text)
    root, value = reader.root, reader.value
    if root is None or (type(root) is ScalarEvent and reader.tag(root) == NULL_TAG):
        raise PlantError([f"{name}:1:1: the file is empty — a plant file starts with 'plant: NAME' "
                          "and 'buses:'"])
    if type(root) is not MappingStartEvent:
        line, column = _position(root)
        kind = f"the value {root.value!r}" if isinstance(root, ScalarEvent) else "a list"
        raise PlantError([f"{name}:{line}:{column}: the top level is {kind}, not a mapping "
                          "— a plant file is a mapping with 'plant:' and 'buses:'"])
    return Document(name, text, value, hashlib.sha256(data).hexdigest(), reader.problems)


def _not_text(text: str) -> int | None:
    """Where the first character PyYAML refuses as not printable is, or a byte order mark after the
    start, which PyYAML reads as part of a key and libyaml does not; None where there is neither.
    Looked for apart: as one pattern, the two took 30 ms of a plant file of 1.5 MB, apart 5 ms."""
    found, mark = _NOT_PRINTABLE.search(text), text.find(_BYTE_ORDER_MARK, 1)
    return min(([found.start()] if found else []) + ([mark] if mark > 0 else []), default=None)


def _read(name: str, text: str) -> _Reader:
    """`text` read by `LOADER`, or `PlantError` for what stops it: a syntax error, a limit, an alias,
    an anchor given twice, a second document.

    When libyaml stops (a syntax error, a limit, aliases), what is said is where the pure parser
    stops first: the two word syntax errors differently, and may meet them in another order.
    Not when libyaml got further than `_reread` looks (`_REREAD_EVENTS`): then the pure parser
    could stop first only where the two disagree on what is valid YAML, and looking would cost a
    second a file (a file at the node limit: 1.2 s, without 0.2 s).
    """
    events = _Events(name, text, LOADER)
    reader = _Reader(events)
    try:
        try:
            reader.read()
            events.refuse_aliases()
        except (yaml.MarkedYAMLError, PlantError):
            if LOADER is not yaml.SafeLoader and events.count <= _REREAD_EVENTS:
                _reread(name, text)
            raise  # the pure parser takes the file (as far as it reads it): libyaml's stop stands
        if events.stop is not None:
            raise events.stop
    except yaml.MarkedYAMLError as error:
        raise PlantError([_syntax_error(name, error)]) from None
    return reader


def _reread(name: str, text: str) -> None:
    """Where the pure parser stops in `text` (a syntax error, a limit, aliases), if it does within
    `_REREAD_EVENTS` events: it takes some 20 µs an event, libyaml a fiftieth of that."""
    pure = _Events(name, text, yaml.SafeLoader)
    if sum(1 for _ in itertools.islice(pure, _REREAD_EVENTS + 1)) <= _REREAD_EVENTS:
        pure.refuse_aliases()


class _Events:
    """The events of a text, refused at the limits as they come (`PlantError`: deeper than
    `MAX_DEPTH`, more than `MAX_NODES` nodes), with what PyYAML's composer would object to
    noted, to be said once the whole text has parsed (a syntax error anywhere comes first):
    each alias's places (`refuse_aliases`), and `stop`, the first anchor given twice or the
    second document."""

    def __init__(self, name: str, text: str, loader: type) -> None:
        self.name, self.text, self.loader = name, text, loader
        self.aliases: dict[str, list[Position]] = {}  # each alias name, where it is used
        self.stop: yaml.MarkedYAMLError | None = None
        self.document = 0  # documents begun
        self.count = 0  # events given so far

    def __iter__(self) -> Iterator[yaml.Event]:
        parser = self.loader(self.text)
        anchors: dict[str, yaml.Mark] = {}
        depth = nodes = 0
        while (event := parser.get_event()) is not None:
            kind = type(event)
            if kind in _NODE_EVENTS:
                nodes += 1
                if nodes > MAX_NODES:
                    line, column = _position(event)
                    raise PlantError([f"{self.name}:{line}:{column}: more than {MAX_NODES:,} keys, values, "
                                      "lists and "
                                      "mappings — 8 buses of 30 modules with all 64 programs written out "
                                      "have about "
                                      "160,000: check that this is the plant file"])
                if kind is AliasEvent:
                    self.aliases.setdefault(event.anchor, []).append(_position(event))
                elif event.anchor is not None and self.document == 1:
                    if event.anchor in anchors and self.stop is None:
                        self.stop = ComposerError("found duplicate anchor; first occurrence",
                                                  anchors[event.anchor],
                                                  "second occurrence", event.start_mark)
                    anchors.setdefault(event.anchor, event.start_mark)
                if kind is not ScalarEvent and kind is not AliasEvent:
                    depth += 1
                    if depth > MAX_DEPTH:
                        line, column = _position(event)
                        raise PlantError([f"{self.name}:{line}:{column}: lists and mappings nested more "
                                          f"than {MAX_DEPTH} "
                                          "deep — a plant file needs fewer than ten: check the brackets and "
                                          "the indentation"])
            elif kind is MappingEndEvent or kind is SequenceEndEvent:
                depth -= 1
            elif kind is DocumentStartEvent:
                self.document += 1
                if self.document == 2 and self.stop is None:
                    self.stop = ComposerError("expected a single document in the stream", None,
                                              "but found another document", event.start_mark)
            self.count += 1
            yield event

    def refuse_aliases(self) -> None:
        """`PlantError` naming every alias, once the text has been parsed."""
        lines = []
        for anchor, uses in self.aliases.items():
            (line, column), times = uses[0], f", used {len(uses)} times" if len(uses) > 1 else ""
            lines.append(f"{self.name}:{line}:{column}: an alias (*{anchor}{times}) — a plant file does not "
                         "use aliases: "
                         "share settings with profiles: and a module's profiles: [NAME], or write the "
                         "value out")
        if lines:
            raise PlantError(lines)


#: A path's end in a trie of wanted paths (`_Reader`): it is wanted, nothing under it is.
_LEAF: Mapping[Any, Any] = MappingProxyType({})


class _Reader:
    """One pass over the events of a YAML file.

    Without `wanted`, it builds the data and collects the problems found on the way (at most
    `MAX_PROBLEMS` + 1: enough to know that there are more). With `wanted`, a trie of paths
    (`_want`), it records `positions` of those paths and of the paths on the way to them, and
    only passes over the rest. The same code reads keys both times, so paths match. With
    `spans`, it also records the `Span` of every node it builds (`top`, the top node's), for
    `spans`: only then does it keep the last event it was given and go through `spanned`.
    """

    def __init__(self, events: Iterable[yaml.Event], wanted: dict[Any, Any] | None = None,
                 spans: bool = False) -> None:
        self.next: Callable[[], yaml.Event] = iter(events).__next__
        #: The value of the node that an event begins, read to its end: `read_node`, or `spanned`.
        self.node: Callable[[yaml.Event, Path_, Mapping[Any, Any] | None], Any] = self.read_node
        self.open: list[Span] | None = None  # with `spans`: the collections being read, innermost last
        self.top: Span | None = None
        self.last: yaml.Event | None = None  # with `spans`: the event given last
        if spans:
            self.open, self.next, self.node = [], self._kept(self.next), self.spanned
        self.wanted = wanted
        self.positions: dict[Path_, tuple[Position | None, Position]] = {}
        self.problems: list[Problem] = []
        self.root: yaml.Event | None = None  # the top node's first event; None for an empty stream
        self.value: Any = None
        self.readings = Readings()  # how each scalar's text reads

    def read(self) -> None:
        self.next()  # the stream's start
        if type(self.next()) is StreamEndEvent:
            return
        self.root = self.next()
        if self.wanted is not None:
            self.positions[()] = (None, _position(self.root))
        self.value = self.node(self.root, (), self.wanted)
        while type(self.next()) is not StreamEndEvent:  # the end of the document, or more of them
            pass

    def _kept(self, given: Callable[[], yaml.Event]) -> Callable[[], yaml.Event]:
        """`given`, each event it gives kept as `last`."""

        def next_event() -> yaml.Event:
            self.last = given()
            return self.last

        return next_event

    def spanned(self, event: yaml.Event, path: Path_, wanted: Mapping[Any, Any] | None) -> Any:
        """`node`, with the node's `Span` put in the collection it is in (`open`), or as `top`."""
        assert self.open is not None
        span = Span(marked(event.start_mark).index, marked(event.end_mark).index)
        if type(event) is ScalarEvent:
            span.written, span.plain = event.value, not event.style
        elif isinstance(event, CollectionStartEvent):
            span.flow = bool(event.flow_style)
            span.children = [] if type(event) is SequenceStartEvent else {}
        if not self.open:
            self.top = span
        elif isinstance(children := self.open[-1].children, list):
            children.append(span)
        else:
            children[path[-1]] = span
        self.open.append(span)
        value = self.read_node(event, path, wanted)
        self.open.pop()
        if isinstance(event, CollectionStartEvent):
            assert self.last is not None  # the collection's end
            children = list(span.children.values()) if isinstance(span.children, dict) else span.children
            span.end = children[-1].end if children and not span.flow else marked(self.last.end_mark).index
        return value

    def problem(self, problem: Problem) -> None:
        if len(self.problems) <= MAX_PROBLEMS:
            self.problems.append(problem)

    def read_node(self, event: yaml.Event, path: Path_, wanted: Mapping[Any, Any] | None) -> Any:
        """The value of the node that `event` begins, read to its end."""
        if type(event) is ScalarEvent:
            return self.scalar(event, path, path[-1] if path and isinstance(path[-1], str) else "")
        if not isinstance(event, CollectionStartEvent):
            return None  # an alias: refused once the whole file is read (`_Events.refuse_aliases`)
        if event.tag is not None:  # !!set, !!omap, !!float
            self.problem(_tagged(event.tag, event, path))
        if type(event) is MappingStartEvent:
            return self.mapping(event, path, wanted)
        items: list[Any] = []
        while type(item := self.next()) is not SequenceEndEvent:
            items.append(self.entry(path + (len(items),), None, item, wanted))
        return items

    def entry(self, path: Path_, key: yaml.Event | None, event: yaml.Event,
              wanted: Mapping[Any, Any] | None) -> Any:
        """The value of a list item or mapping value at `path`; passed over when locating another path."""
        if wanted is None:
            return self.node(event, path, None)
        below = wanted.get(path[-1])
        if below is not None:
            key_at = None if key is None else _position(key)
            value_at = key_at if key_at is not None and self.empty(event) else _position(event)
            self.positions[path] = (key_at, value_at)
        if below is None or below is _LEAF:
            self.skip(event)
            return None
        return self.node(event, path, below)

    def mapping(self, start: MappingStartEvent, path: Path_,
                wanted: Mapping[Any, Any] | None) -> dict[Any, Any]:
        result: dict[Any, Any] = {}
        keys: dict[Any, yaml.Event] = {}  # each key read here, by its event
        before: tuple[Any, yaml.Event] | None = None  # the key read last and its value's first event
        while type(key_event := self.next()) is not MappingEndEvent:
            if type(key_event) is not ScalarEvent:
                self.skip(key_event)
            value_event = self.next()
            if self.merge_key(key_event):
                self.problem(Problem(path, "a YAML merge key (<<) — share settings with "
                                     "profiles: and a module's profiles: [NAME] instead",
                                     at=_position(key_event)))
                self.skip(value_event)
                continue
            if before is not None and start.flow_style and (
                    written := self.split_number(before[1], key_event, value_event)):
                point = written.replace(",", ".")
                result[before[0]] = Decimal(point)  # what was meant, for the models to judge
                self.problem(Problem(path, DECIMAL_COMMA.format(what=before[0], written=written, point=point),
                                     at=_position(before[1]), models_fix=True))
                continue
            key = self.scalar(key_event, path, "key") if type(key_event) is ScalarEvent else None
            if key is None or (type(key) is not str and not _hashable(key)):
                self.problem(Problem(path, "a key that is not a name or a number — write a plain key",
                                     at=_position(key_event)))
                self.skip(value_event)
                continue
            if key in keys:
                first = _position(keys[key])
                self.problem(Problem(path, f"duplicate key '{key}' — it is already given at "
                                     f"{first[0]}:{first[1]}; give each key once", at=_position(key_event)))
                self.skip(value_event)
                continue
            keys[key] = key_event
            if self.open is not None:
                self.open[-1].keys[key] = marked(key_event.start_mark).index
            result[key] = self.entry(path + (key,), key_event, value_event, wanted)
            before = (key, value_event)
        return result

    def skip(self, event: yaml.Event) -> None:
        """Pass over the node that `event` begins."""
        depth = 0
        while True:
            kind = type(event)
            if kind is MappingStartEvent or kind is SequenceStartEvent:
                depth += 1
            elif kind is MappingEndEvent or kind is SequenceEndEvent:
                depth -= 1
            if depth == 0:
                return
            event = self.next()

    def tag(self, event: yaml.Event) -> str | None:
        """A node's tag as PyYAML's composer gives it: the one written, else YAML 1.1's reading; None for an
        alias."""
        if type(event) is ScalarEvent:
            return self.scalar_tag(event)
        if not isinstance(event, CollectionStartEvent):
            return None
        return event.tag if event.tag is not None and event.tag != "!" else _COLLECTIONS[type(event)]

    def scalar_tag(self, event: ScalarEvent) -> str:
        if event.tag is not None and event.tag != "!":
            return event.tag
        return self.readings.tag(event.value, event.implicit)

    def merge_key(self, event: yaml.Event) -> bool:
        """`<<`, or any key tagged `!!merge`."""
        if type(event) is ScalarEvent:
            if event.tag is None and event.value != "<<":
                return False  # most keys: no tag to resolve
            maybe = event.tag not in (None, "!") or event.value == "<<"
        elif isinstance(event, CollectionStartEvent):
            maybe = event.tag not in (None, "!")
        else:
            return False  # an alias
        return maybe and self.tag(event) == MERGE_TAG

    def empty(self, event: yaml.Event) -> bool:
        """An empty value (`key:` alone), which YAML reads as null."""
        return type(event) is ScalarEvent and not event.value and self.tag(event) == NULL_TAG

    def split_number(self, number: yaml.Event, key: yaml.Event, value: yaml.Event) -> str | None:
        """`{position: 2,000}`: a whole number, a comma and digits that became a key without a value;
        the number as written ("2,000"), or None."""
        if (type(value) is ScalarEvent and not value.value and self.empty(value)
                and type(number) is ScalarEvent and not number.style and _WHOLE.fullmatch(number.value)
                and type(key) is ScalarEvent and not key.style and _DIGITS.fullmatch(key.value)
                and marked(key.start_mark).index == marked(number.end_mark).index + 1):
            return f"{number.value},{key.value}"
        return None

    def scalar(self, event: ScalarEvent, path: Path_, key: str) -> Any:
        """The value of a scalar (under `key`, for messages); a problem when it is not one value to every
        reader, or when it has a tag (its text is kept)."""
        if event.tag is not None:
            self.problem(_tagged(event.tag, event, path))
            return event.value
        value, problem, models_fix = self.readings.of(event)
        if problem is not None:
            self.problem(Problem(path, problem(key), at=_position(event), models_fix=models_fix))
        return value

def _want(wanted: dict[Any, Any], path: Path_) -> None:
    """Add `path` to the trie `wanted`."""
    node = wanted
    for depth, part in enumerate(path, start=1):
        below = node.get(part)
        if depth == len(path):
            if below is None:
                node[part] = _LEAF
        else:
            if below is None or below is _LEAF:
                below = node[part] = {}
            node = below


def _in_file(data: Any, path: Path_) -> Path_:
    """The parts of `path` that the file has, in order: those it does not have are skipped."""
    found: Path_ = ()
    for part in path:
        key: Any = part  # the file's own key (a Decimal, a float) where pydantic wrote its repr
        if isinstance(data, dict):
            # pydantic writes a key that is no str or int as its repr
            if isinstance(part, str) and part not in data:
                key = next((k for k in data if isinstance(k, Decimal | float) and part in (str(k), repr(k))),
                           part)
            present = _hashable(key) and key in data
        else:
            present = isinstance(data, list) and isinstance(part, int) and 0 <= part < len(data)
        if present:
            data = data[key]
            found += (key,)
    return found


def mappings_in(data: Any, path: Path_) -> Iterator[tuple[Path_, dict[Any, Any]]]:
    """The mappings in the list that `data` holds under `path[-1]`, with their paths; others skipped."""
    items = data.get(path[-1]) if isinstance(data, dict) else None
    for index, item in enumerate(items if isinstance(items, list) else ()):
        if isinstance(item, dict):
            yield path + (index,), item


def _tagged(tag: str, event: yaml.Event, path: Path_) -> Problem:
    """The problem of a node with a tag written on it, at the tag."""
    return Problem(path, f"tags are not used in plant files — remove {_written(tag)}", at=_position(event))


def _written(tag: str) -> str:
    """A tag as a file writes it: `!!float`, `!env`."""
    return tag.replace("tag:yaml.org,2002:", "!!", 1)


def _position(event: yaml.Event) -> Position:
    start = marked(event.start_mark)
    return start.line + 1, start.column + 1


def marked(mark: yaml.error.Mark | yaml._yaml.Mark | None) -> yaml.error.Mark | yaml._yaml.Mark:
    """An event's start or end: the parser marks every event (the stubs allow None, for events made by
    hand)."""
    assert mark is not None
    return mark


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
        where = (f" ({error.context} at line {error.context_mark.line + 1})" if error.context
                 and error.context_mark else "")
        hint = f"not valid YAML: {problem}{where} — check the indentation, colons, quotes and brackets here"
    mark = marked((error.context_mark if at_start else error.problem_mark) or error.problem_mark
                  or error.context_mark)
    return f"{name}:{mark.line + 1}:{mark.column + 1}: {hint}"
