"""A plain scalar of a plant file as YAML 1.1 and YAML 1.2 read it: its value, exact, and a problem
where the two differ.

`document`'s reader hands every untagged scalar here (`Readings.of`), so that
- a float keeps the text it was written with: `0.1` becomes `Decimal("0.1")`, never the
  binary 0.1000000000000000055…; integers, booleans, strings are what both YAML versions read;
- a plain scalar that YAML 1.1 (PyYAML) and YAML 1.2 (yaml-language-server, JSON Schema tools, most other
  readers) read differently is a problem that says what to write: `010` is 8 to one and 10 to the other, `on`
  true or text, `1:30` 90 or text, `1e3` text or 1000, `0b101`, `1_000`, `2024-01-01`, `=`. The 1.2 side is
  `core_schema`, the YAML 1.2.2 core schema's table (§10.3.2); the 1.1 side is PyYAML's resolver, and the 1.1
  type repository's `y`, `Y`, `n`, `N` as booleans (PyYAML reads them as text, other 1.1 readers as true and
  false). Quoted scalars are never ambiguous. The value kept is the YAML 1.2 reading, what editors and schema
  tools see; the models' objection to it, if any, says what the key wants;
- a number has at most `MAX_DIGITS` digits written out in full (`1e30` has 31): decimal
  arithmetic is exact to that precision, and reading `1e999999` as an integer would take
  seconds, `1.0e+400` as a float would be infinite.

A scalar's reading, and YAML 1.1's tag of a text (`Readings.tag`, which the reader asks of keys
too), is worked out once per text (a plant file says the same few things many times). Does not
own tags written on a node, keys, positions or limits (`document`). Pure: text in.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from decimal import Decimal, InvalidOperation
from typing import Any

import yaml
from yaml.events import ScalarEvent
from yaml.nodes import ScalarNode

#: Python's decimal precision: arithmetic on numbers of more digits would round.
MAX_DIGITS = 28
#: Entries of each of `Readings`' caches before it starts again.
_CACHE_SIZE = 4096

_BOOL_TAG = "tag:yaml.org,2002:bool"
_FLOAT_TAG = "tag:yaml.org,2002:float"
_INT_TAG = "tag:yaml.org,2002:int"
MERGE_TAG = "tag:yaml.org,2002:merge"
NULL_TAG = "tag:yaml.org,2002:null"
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
        (NULL_TAG, r"null|Null|NULL|~|", lambda text: None),
        (_BOOL_TAG, r"true|True|TRUE|false|False|FALSE", lambda text: text.lower() == "true"),
        (_INT_TAG, r"[-+]?[0-9]+", int),
        (_INT_TAG, r"0o[0-7]+", lambda text: int(text[2:], 8)),
        (_INT_TAG, r"0x[0-9a-fA-F]+", lambda text: int(text[2:], 16)),
        (_FLOAT_TAG, DECIMAL_NUMBER.pattern, Decimal),
        (_FLOAT_TAG, r"[-+]?(\.inf|\.Inf|\.INF)|\.nan|\.NaN|\.NAN",
         lambda text: Decimal(_SPECIAL_FLOATS[text.lower()])),
    )
)
_CORE_TAGS = {tag for tag, _, _ in _CORE_SCHEMA} | {_STR_TAG}  # every tag YAML 1.2 can give a plain scalar
#: The table as one pattern: the name of the group that matches is the rule's index.
_CORE_PATTERN = re.compile("|".join(f"(?P<r{index}>{pattern.pattern})"
                                    for index, (_, pattern, _) in enumerate(_CORE_SCHEMA)))
#: How a message says what a reader takes a plain scalar for, by its tag (and value).
_READINGS: dict[str, Callable[[Any], str]] = {
    _INT_TAG: lambda value: _as_written(value),
    _FLOAT_TAG: lambda value: _as_written(value),
    _BOOL_TAG: lambda value: f"the boolean {str(value).lower()}",
    _STR_TAG: lambda value: "text",
    "tag:yaml.org,2002:timestamp": lambda value: "a date",
    "tag:yaml.org,2002:value": lambda value: "the default-value key",
    MERGE_TAG: lambda value: "a merge key",
}
#: A number in decimal or exponent notation, with YAML 1.1's underscores: whole digits, fraction
#: digits, exponent — to count its digits without building it.
_DECIMAL_FORM = re.compile(r"[-+]?([0-9_]*)(?:\.([0-9_]*))?(?:[eE]([-+]?[0-9]+))?")


#: How an untagged scalar reads (`Readings.of`): its value; None, or what is wrong with it, worded
#: for the key it is under; whether the models' fix is better than that message's.
Reading = tuple[Any, Callable[[str], str] | None, bool]


class Readings:
    """How scalars read, each text worked out once: YAML 1.1's tag of a plain or quoted text
    (`tag`), and an untagged scalar's value and problem (`of`). One for each pass over a file."""

    def __init__(self) -> None:
        self.constructor = yaml.SafeLoader("")
        self.tags: dict[tuple[str, tuple[bool, bool]], str] = {}  # YAML 1.1's tag of a plain or quoted text
        self.known: dict[str, Reading] = {}  # a plain scalar's, by its text

    def tag(self, text: str, implicit: tuple[bool, bool]) -> str:
        """YAML 1.1's tag of `text`, as PyYAML's resolver gives it (`implicit`: the event's, plain or
        quoted)."""
        if (tag := self.tags.get((text, implicit))) is None:
            tag = self.constructor.resolve(ScalarNode, text, implicit)
            _remember(self.tags, (text, implicit), tag)
        return tag

    def of(self, event: ScalarEvent) -> Reading:
        """How the scalar `event`, which has no tag written, reads."""
        if event.style:  # quoted, or a literal or folded block: text to every reader
            return event.value, None, False
        if (known := self.known.get(event.value)) is None:
            known = self.reading(event.value, self.tag(event.value, event.implicit))
            _remember(self.known, event.value, known)
        return known

    def reading(self, text: str, tag: str) -> Reading:
        """How an untagged plain scalar reads, its YAML 1.1 tag given (`Reading`)."""
        core_tag, core_value = _core_rule(text)
        if (tag in _NUMBER_TAGS or core_tag in _NUMBER_TAGS) and _too_long(text):
            return text, lambda key: (f"{_subject(key, text, False)} has more than {MAX_DIGITS} digits, "
                                      "written out "
                                      "— a plant file's numbers are read exactly: write at most "
                                      f"{MAX_DIGITS} digits"), False
        # a tag the core schema does not have (a date, `=`) differs without building a value
        yaml11 = (tag, self.construct(tag, text) if tag in _CORE_TAGS else None)
        if tag == _STR_TAG and text in _YES_NO:  # the 1.1 type repository's y and n, which PyYAML leaves out
            yaml11 = (_BOOL_TAG, text in "yY")
        yaml12 = (core_tag, core_value(text))
        if (yaml11[0], str(yaml11[1])) != (yaml12[0], str(yaml12[1])):  # str: NaN is not equal to NaN
            quoted = _STR_TAG in (yaml11[0], yaml12[0])
            return yaml12[1], lambda key: _ambiguity(_subject(key, text, quoted), yaml11, yaml12), True
        return yaml11[1], None, False

    def construct(self, tag: str, text: str) -> Any:
        """The YAML 1.1 value of a scalar; a float as an exact `Decimal`."""
        if tag == _STR_TAG:
            return text
        node = ScalarNode(tag, text)
        try:
            return self.decimal(node) if tag == _FLOAT_TAG else self.constructor.construct_object(node)
        finally:
            self.constructor.constructed_objects.clear()  # it would keep every node it built

    def decimal(self, node: ScalarNode) -> Decimal:
        """A float exactly as written: "0.1" is Decimal("0.1")."""
        text = node.value.replace("_", "")
        try:
            return Decimal(_SPECIAL_FLOATS.get(text.lower(), text))
        except InvalidOperation:  # YAML 1.1 sexagesimal "1:30.5"
            return Decimal(repr(self.constructor.construct_object(node)))


def _remember(cache: dict[Any, Any], key: Any, value: Any) -> None:
    """`cache[key] = value`, the cache emptied first when it is full: a file of all different values gains
    nothing."""
    if len(cache) >= _CACHE_SIZE:
        cache.clear()
    cache[key] = value


def core_schema(text: str) -> tuple[str, Any]:
    """The tag and value the YAML 1.2 core schema gives the plain scalar `text`."""
    tag, value = _core_rule(text)
    return tag, value(text)


def _core_rule(text: str) -> tuple[str, Callable[[str], Any]]:
    """The core schema's tag for `text`, and how to build its value (not built yet: it may be long)."""
    if (found := _CORE_PATTERN.fullmatch(text)) is None:
        return _STR_TAG, str
    rule = found.lastgroup  # every alternative is a group named r<index>
    assert rule is not None
    tag, _, value = _CORE_SCHEMA[int(rule[1:])]
    return tag, value


#: Plain scalars the YAML 1.1 type repository reads as booleans and PyYAML's resolver as text.
_YES_NO = frozenset({"y", "Y", "n", "N"})


def _ambiguity(subject: str, yaml11: tuple[str, Any], yaml12: tuple[str, Any]) -> str:
    """How YAML 1.1 and 1.2 read `subject`, and what to write so that both read one thing."""
    said = (f"{subject} is read as {_READINGS[yaml11[0]](yaml11[1])} by YAML 1.1 "
            f"and as {_READINGS[yaml12[0]](yaml12[1])} by YAML 1.2")
    if yaml11[0] in _NUMBER_TAGS and yaml12[0] in _NUMBER_TAGS:  # only a leading zero does that: 010
        return (f"{said} — write {_as_written(yaml12[1])} (or {_as_written(yaml11[1])}), without the "
                "leading zero")
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


def _subject(key: str, text: str, quoted: bool) -> str:
    """A scalar as a message names it: "address 010", "alarm 'on'"; shortened when long."""
    short = text if len(text) <= 24 else text[:20] + "…"
    return f"{key} {repr(short) if quoted else short}".lstrip()
