"""The JSON files prc3cfg writes and reads back — plan files, module images, snapshots, an
emulator's state — as pydantic models, and a refusal of one said in words.

Owns the kinds of value those models hold (`Whole`, `Text`, `Flag`, `Number`; `within` a range, `one_of` some
texts: never "2", 2.7 or true for a whole number) and the wording of pydantic's first error about a document:
where in it, what is there, what belongs there — 'buses[0].modules[2] has no "steps"', "buses[1].name is null,
where text belongs", "fault is a list, where text or null belongs" (`takes_null`: the contract's type there is
`X | None`), "module 3: program 7: P = 12000 is outside 0..9999". Each contract's own module names its file,
words its places when a JSON path is not the best name for them, and says what to do. Plant files (YAML,
positions) are `prc3cfg.plant.messages`. Pure.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Iterable, Sequence
from typing import Annotated, Any, get_args, get_origin, get_type_hints

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
    "int_type": "a whole number", "string_type": "text", "bool_type": "true or false",
          "float_type": "a number",
    "model_type": "an object", "model_attributes_type": "an object", "dataclass_type": "an object",
          "dict_type": "an object",
    "list_type": "a list", "tuple_type": "a list",
}

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

    def check(value: str) -> str:
        if value not in allowed:
            raise PydanticCustomError("one_of", "not one of {values}", {"values": allowed})
        return value

    return AfterValidator(check)


def every_key(keys: Iterable[str]) -> BeforeValidator:
    """An object that gives each of `keys`, as metadata of a model whose fields have defaults
    (a default serves code, not a file, which says every value)."""
    required = tuple(keys)

    def check(value: Any) -> Any:
        if (isinstance(value, dict)
            and (missing := next((key for key in required if key not in value), None)) is not None):
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


def said(error: ValidationError, place: Place, contract: Any) -> str:
    """The first problem pydantic found checking a document as `contract` (the model, or the type the
    `TypeAdapter` checks), in words, at the place `place` names ("buses[0].name")."""
    return worded(error.errors(include_url=False)[0], place, contract)


def worded(detail: ErrorDetails, place: Place, contract: Any) -> str:
    """One pydantic error about a JSON document checked as `contract` in words; where null may stand
    instead (`X | None` there), what belongs says so: "fault is a list, where text or null belongs"."""
    loc, kind, value = detail["loc"], detail["type"], detail["input"]
    at = place(loc)
    ctx = detail.get("ctx", {})
    null = ["null"] if takes_null(contract, loc) else []
    if kind == "missing":
        return f'{place(loc[:-1])} has no "{loc[-1]}"'
    if kind == "missing_key":
        return f'{at} has no "{ctx["key"]}"'
    if kind == "outside":
        return f"{at} = {described(value)} is outside {ctx['low']}..{ctx['high']}"
    if kind in ("too_short", "too_long") and isinstance(value, list | tuple):
        return (f"{at} is a list of {len(value)}, where a list of "
                f"{ctx.get('min_length', ctx.get('max_length'))} belongs")
    if kind == "one_of":
        return f"{at} is {described(value)}, where {either([*map(json.dumps, ctx['values']), *null])} belongs"
    wanted = WANTED.get(kind)
    if wanted is None:  # a rule of the model's own (a value error): its words
        return f"{at} is {described(value)}: {detail['msg'].removeprefix('Value error, ')}"
    return f"{at} is {described(value)}, where {either([wanted, *null])} belongs"


def either(words: Sequence[str]) -> str:
    """Alternatives in words: "text", "text or null", '"stop", "run" or "manual"'."""
    return ", ".join(words[:-1]) + f" or {words[-1]}" if len(words) > 1 else words[0]


def takes_null(contract: Any, loc: Sequence[str | int]) -> bool:
    """Whether the place `loc` of a document checked as `contract` may hold null: the type there is
    `X | None`. Followed through models, dataclasses, lists, tuples and objects of values."""
    kind = contract
    for part in loc:
        kind = _not_null(kind)
        if isinstance(part, str) and part in (fields := _fields(kind)):
            kind = fields[part]
        elif isinstance(part, int) and get_origin(kind) in (list, tuple):
            kind = get_args(kind)[0]
        elif isinstance(part, str) and get_origin(kind) is dict:
            kind = get_args(kind)[1]
        else:
            return False
    return type(None) in get_args(_bare(kind))


def _bare(kind: Any) -> Any:
    """A type without its `Annotated` metadata."""
    while get_origin(kind) is Annotated:
        kind = get_args(kind)[0]
    return kind


def _not_null(kind: Any) -> Any:
    """The type of a value at a place of type `kind` that is not null."""
    kind = _bare(kind)
    others = [arg for arg in get_args(kind) if arg is not type(None)]
    return _bare(others[0]) if type(None) in get_args(kind) and len(others) == 1 else kind


def _fields(kind: Any) -> dict[str, Any]:
    """The types of a model's or a dataclass's fields, by name ({} for any other type)."""
    if isinstance(getattr(kind, "__pydantic_fields__", None), dict):
        return {name: field.annotation for name, field in kind.__pydantic_fields__.items()}
    return get_type_hints(kind, include_extras=True) if dataclasses.is_dataclass(kind) else {}


def described(value: Any) -> str:
    """A JSON value in a few words: null, true, 2.7, the text "2", a list, an object."""
    if value is None or isinstance(value, bool | int | float):
        text = json.dumps(value)
        return text if len(text) <= 20 else f"a number of {len(text)} characters"
    if isinstance(value, str):
        return f"the text {json.dumps(value[:20])}" + ("…" if len(value) > 20 else "")
    return "a list" if isinstance(value, list | tuple) else "an object"
