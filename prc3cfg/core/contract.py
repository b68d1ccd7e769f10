"""The JSON files prc3cfg writes and reads back — plan files, module images, snapshots, an
emulator's state — as pydantic models, and a refusal of one said in words.

Owns the kinds of value those models hold (`Whole`, `Text`, `Flag`, `Number`; `within` a
range, `one_of` some texts: never "2", 2.7 or true for a whole number) and the wording of pydantic's first error
about a document: where in it, what is there, what belongs there — 'buses[0].modules[2] has no
"steps"', "buses[1].name is null, where text belongs", "module 3: program 7: P = 12000 is
outside 0..9999". Each contract's own module names its file, words its places when a JSON path
is not the best name for them, and says what to do. Plant files (YAML, positions) are
`prc3cfg.plant.messages`. Pure.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Sequence
from typing import Annotated, Any

from annotated_types import Len
from pydantic import AfterValidator, BeforeValidator, ConfigDict, Strict, ValidationError
from pydantic_core import ErrorDetails, PydanticCustomError

#: The config of every model of a contract in the core: its validator is built at the first reading,
#: not at import — building one loads pydantic's plugins, which import `socket` (through
#: importlib.metadata), and the core imports no `socket` (tests/test_pure_core.py).
LATER = ConfigDict(defer_build=True)

Whole = Annotated[int, Strict()]
Text = Annotated[str, Strict()]
Flag = Annotated[bool, Strict()]
Number = Annotated[float, Strict()]  # a whole number too, never true or "2"

#: What belongs where pydantic found something else, by its error type.
WANTED = {
    "int_type": "a whole number", "string_type": "text", "bool_type": "true or false", "float_type": "a number",
    "model_type": "an object", "model_attributes_type": "an object", "dataclass_type": "an object", "dict_type": "an object",
    "list_type": "a list", "tuple_type": "a list",
}  # fmt: skip

Place = Callable[[Sequence[str | int]], str]


def within(low: int, high: int) -> AfterValidator:
    """A number within low..high, as metadata of `Whole` (its error names both ends, as pydantic's
    `ge`/`le` do not): `Annotated[int, Strict(), within(1, 30)]`."""

    def check(value: int) -> int:
        if not low <= value <= high:
            raise PydanticCustomError("outside", "outside {low}..{high}", {"low": low, "high": high})
        return value

    return AfterValidator(check)


def one_of(values: Iterable[str]) -> AfterValidator:
    """Text that is one of `values`, as metadata of `Text`."""
    allowed = tuple(values)
    expected = ", ".join(json.dumps(v) for v in allowed[:-1]) + f" or {json.dumps(allowed[-1])}"

    def check(value: str) -> str:
        if value not in allowed:
            raise PydanticCustomError("literal_error", "not one of {expected}", {"expected": expected})
        return value

    return AfterValidator(check)


def every_key(keys: Iterable[str]) -> BeforeValidator:
    """An object that gives each of `keys`, as metadata of a model whose fields have defaults
    (a default serves code, not a file, which says every value)."""
    required = tuple(keys)

    def check(value: Any) -> Any:
        if isinstance(value, dict) and (missing := next((key for key in required if key not in value), None)) is not None:
            raise PydanticCustomError("missing_key", "no {key}", {"key": missing})
        return value

    return BeforeValidator(check)


def exactly(count: int) -> Len:
    """A list of exactly `count` items."""
    return Len(count, count)


def json_path(loc: Sequence[str | int], root: str = "the document") -> str:
    """A place in a JSON document as a path, "buses[0].modules[2].steps"; `root` for the document itself."""
    path = "".join(f"[{part}]" if isinstance(part, int) else f".{part}" for part in loc).lstrip(".")
    return path or root


def said(error: ValidationError, place: Place) -> str:
    """The first problem pydantic found, in words, at the place `place` names ("buses[0].name")."""
    return worded(error.errors(include_url=False)[0], place)


def worded(detail: ErrorDetails, place: Place) -> str:
    """One pydantic error about a JSON document in words."""
    loc, kind, value = detail["loc"], detail["type"], detail["input"]
    at = place(loc)
    ctx = detail.get("ctx", {})
    if kind == "missing":
        return f'{place(loc[:-1])} has no "{loc[-1]}"'
    if kind == "missing_key":
        return f'{at} has no "{ctx["key"]}"'
    if kind == "outside":
        return f"{at} = {described(value)} is outside {ctx['low']}..{ctx['high']}"
    if kind in ("too_short", "too_long") and isinstance(value, list | tuple):
        return f"{at} is a list of {len(value)}, where a list of {ctx.get('min_length', ctx.get('max_length'))} belongs"
    if kind == "literal_error":
        return f"{at} is {described(value)}, where {ctx['expected']} belongs"
    wanted = WANTED.get(kind)
    if wanted is None:  # a rule of the model's own (a value error): its words
        return f"{at} is {described(value)}: {detail['msg'].removeprefix('Value error, ')}"
    return f"{at} is {described(value)}, where {wanted} belongs"


def described(value: Any) -> str:
    """A JSON value in a few words: null, true, 2.7, the text "2", a list, an object."""
    if value is None or isinstance(value, bool | int | float):
        text = json.dumps(value)
        return text if len(text) <= 20 else f"a number of {len(text)} characters"
    if isinstance(value, str):
        return f"the text {json.dumps(value[:20])}" + ("…" if len(value) > 20 else "")
    return "a list" if isinstance(value, list | tuple) else "an object"
