"""pydantic's errors in a plant engineer's words: "what is wrong — what would be right".

Owns the wording of every error about one key or one value: one template per pydantic
error type (the number errors are `models`' own types), and the names of places
("program 3", "module booth-a-left", "the gateway"). No "Input should be", no URLs.
Does not own positions (`document`) or rules that span values (`rules`).
"""

from __future__ import annotations

import functools
import re
from decimal import Decimal
from typing import Any, get_args

from pydantic import BaseModel, TypeAdapter, ValidationError
from pydantic_core import ErrorDetails

from prc3cfg.core.line import PortRefusal
from prc3cfg.core.text import has_control
from prc3cfg.plant.models import (
    BusSpec,
    ChainSpec,
    Draft07,
    FunctionOutputSpec,
    Gateway,
    ModuleSpec,
    PlantSpec,
    Port,
    ProfileSpec,
    ProgramSpec,
    SystemSpec,
)
from prc3cfg.plant.problems import DECIMAL_COMMA, Path_, Problem
from prc3cfg.plant.scalars import DECIMAL_NUMBER

#: The model of a mapping, by the key that holds it (a section) or holds a collection of them.
SECTIONS: dict[str, type[BaseModel]] = {
    "system": SystemSpec, "gateway": Gateway, "f1": FunctionOutputSpec, "f2": FunctionOutputSpec,
}
ITEMS: dict[str, tuple[str, type[BaseModel]]] = {
    "buses": ("bus", BusSpec), "modules": ("module", ModuleSpec), "profiles": ("profile", ProfileSpec),
    "programs": ("program", ProgramSpec), "chains": ("chain", ChainSpec),
}
#: What a list item or a mapping key is called, by the key of its list or mapping.
ENTRY_NAMES: dict[str | int, str] = {"programs": "program number", "profiles": "profile name"}

TEMPLATES = {
    "extra_forbidden": "unknown key '{key}' in {container} — expected one of {expected}",
    "invalid_key": "unknown key '{key}' in {container} — expected one of {expected}",
    "missing": "{container} has no {key} — add {key}:{hint}",
    "empty": "{what} is empty — give it a value or leave the key out",
    "empty_required": "{what} is empty — give it a value",
    "not_number": "{what} cannot be {input} — give a {number}{unit}",
    "quoted_number": "{what} cannot be the text {input} — write the number without quotes",
    "decimal_comma": DECIMAL_COMMA,
    "not_finite": "{what} {value} is not a finite number — give a number",
    "out_of_range": "{what} {value} is out of range — {what} must be {allowed}{note}",
    "not_whole": "{value} is not a whole number of {step_name} — {what_steps} in steps of {step}",
    "not_whole_count": "{what} {value} is not a whole number — {what} takes whole numbers",
    "not_allowed": "{what} cannot be {input} — expected one of {expected}",
    "literal_error": "{what} cannot be {input} — expected one of {expected}",
    "string_type": "{what} cannot be {input} — write text, in quotes if it looks like a number",
    "bool_type": "{what} cannot be {input} — write true or false",
    "model_type": "{what} is {input}, not a mapping — write it as key: value pairs",
    "dict_type": "{what} is {input}, not a mapping — write it as key: value pairs",
    "list_type": "{what} is {input}, not a list — write it as [a, b] or as '- ' lines",
    "tuple_type": "{what} is {input}, not a list — write it as [a, b] or as '- ' lines",
    "chain_type": "{what} is {input}, not a chain — write a list of program numbers or "
    "{{programs: [...], loop: true}}",
    "string_too_short": "{what} is empty — give it a name",
    "tcp_port": "{what} {input} has no TCP port 1..65535 — write {scheme}://HOST:PORT, e.g. "
                "{scheme}://127.0.0.1:7001",
    "emulator_name": "{what} {input} does not end in a plain emulator name — the name is a file in "
    ".prc3cfg/emulators/: letters, digits, '-', '_' and '.' (not first), e.g. emulator://booth-a",
    "too_short": "{what} is empty — list at least one {item}",
    "program_key": "{what} {input} is written with a decimal point — {fix}",
    "port_control": "{what} {input} holds a control character — write the device path or URL as plain text",
    "port_handler": "{what} {input} uses pyserial's {scheme}:// handler, which a plant file may not name — "
                    "write a device path, "
    "socket://HOST:PORT, rfc2217://HOST:PORT or emulator://NAME (trace a line with prc3cfg's --trace)",
    "port_not_device": "{what} {input} is not a serial device's full path — write the device's path under "
                       "/dev (/dev/ttyUSB0, "
    "/dev/serial/by-id/…), COMn or \\\\.\\COMn, socket://HOST:PORT, rfc2217://HOST:PORT or emulator://NAME",
    "port_not_a_line": "{what} {input} is this machine's own terminal, console or files, not a serial line "
                       "— write the path "
    "of the line's adapter, e.g. /dev/ttyUSB0",
    "name_control": "{what} {input} holds a control character — a name is printable text: write it without "
                    "line breaks, "
    "escapes or other control characters",
    "data_bits": "{what} {value} cannot carry a PRC 3 frame — its frames are binary and need 8 data bits: "
                 "write {bits}",
}
_LIST_ITEMS: dict[str | int, str] = {"buses": "bus", "modules": "module", "programs": "program"}
_DECIMAL_COMMA = re.compile(r"[-+]?[0-9]+,[0-9]+")


def from_pydantic(error: ErrorDetails, data: Any) -> Problem | None:
    """The problem a pydantic error describes, at the key or value it is about.

    None for pydantic's "too short" about a list whose items all failed: those items'
    own errors say what is wrong.
    """
    loc = tuple(error["loc"])
    ctx = error.get("ctx", {})
    if error["type"] == "too_short" and ctx.get("actual_length") == 0 and error["input"]:
        return None
    kind = _kind(error, loc, ctx)
    template = TEMPLATES.get(kind)
    if template is None:
        return Problem(loc, f"{what(loc, data)} is not valid: {error['msg']} — see schemas/plant.schema.json")
    at_key = kind in ("extra_forbidden", "invalid_key", "missing") or (loc and loc[-1] == "[key]")
    return Problem(loc, template.format(**_words(kind, error, loc, ctx, data)), at_key=bool(at_key))


def _kind(error: ErrorDetails, loc: Path_, ctx: dict[str, Any]) -> str:
    """The template an error is said with: pydantic's type, or one closer to what was written (nothing,
    a decimal comma, a number in quotes, a count that is not whole)."""
    kind, written = error["type"], error["input"]
    if written is None and kind != "missing":
        return "empty_required" if _required(loc) else "empty"
    if kind == "not_number" and isinstance(written, str) and _DECIMAL_COMMA.fullmatch(written):
        return "decimal_comma"
    if kind == "not_number" and _is_number_text(written):
        return "quoted_number"
    if kind == "not_whole" and not ctx.get("step_name"):
        return "not_whole_count"
    return kind


def _words(kind: str, error: ErrorDetails, loc: Path_, ctx: dict[str, Any], data: Any) -> dict[str, Any]:
    """What the templates fill in, for this error: the names of its place and container, the value as
    written, what was expected, and pydantic's or the models' context."""
    container = loc[:-1]
    return {
        "what": what(loc, data),
        "key": loc[-1] if loc else "",
        "container": what(container, data) if container else "the plant file",
        "input": shown(error["input"]),
        "expected": _expected(kind, ctx, container),
        "hint": _hint(container, loc[-1]) if kind == "missing" else "",
        "number": "whole number" if ctx.get("whole") else "number",
        "unit": f" in {ctx['unit']}" if ctx.get("unit") else "",
        "what_steps": ctx.get("what", ""),
        "written": error["input"],
        "point": str(error["input"]).replace(",", "."),
        "item": _LIST_ITEMS.get(loc[-1] if loc else "", "item"),
        **{k: v for k, v in ctx.items() if k not in ("unit", "what", "expected")},
    }


#: The errors of a port a plant file may not name, though a command line may (`port_error`).
PLANT_FILE_ONLY = frozenset(get_args(PortRefusal))


def port_error(what_: str, port: str, *, operators: bool = False) -> str | None:
    """What is wrong with `port` as a plant file's bus would say it, about `what_` ("--port"); None if
    nothing. `operators`: the port is the operator's own choice (a command line's), which may name any of
    pyserial's handlers and any path (`core.line.port_refusal` is for reviewed files)."""
    try:
        TypeAdapter(Port).validate_python(port)
    except ValidationError as error:
        details = error.errors()[0]
        if operators and details["type"] in PLANT_FILE_ONLY:
            return None
        template = TEMPLATES.get(details["type"])
        if template is None:
            return f"{what_} {shown(port)} is not a port: {details['msg']}"
        return template.format(what=what_, input=shown(port), **details.get("ctx", {}))
    return None


def what(path: Path_, data: Any) -> str:
    """How a message names the thing at `path`: "speed", "program 3", "module booth-a-left"."""
    if not path:
        return "the plant file"
    *head, last = path
    parent = head[-1] if head else None
    if last == "[key]":
        return ENTRY_NAMES.get(head[-2] if len(head) > 1 else "", "key")
    if parent == "programs" and len(head) >= 3 and head[-3] == "chains":
        return "program number"
    if last == "programs" and len(head) >= 2 and head[-2] == "chains":
        return what(tuple(head), data)
    if parent == "profiles" and isinstance(last, int):
        return "profile name"
    if parent in ITEMS and (isinstance(last, int) or len(head) == 1 or parent == "programs"):
        return _item(parent, last, path, data)
    return "the gateway" if last == "gateway" else str(last)


def _item(parent: str, last: Any, path: Path_, data: Any) -> str:
    """An item of a collection (`parent`): a bus or module by its name where it has a printable one,
    else by its place counted from 1; a program by its number."""
    label = ITEMS[parent][0]
    name = _lookup(data, path + ("name",)) if parent in ("buses", "modules") else None
    # a name that is not printable text is not one
    if isinstance(name, str) and name and not has_control(name):
        return f"{label} {name}"
    return f"{label} {last + 1 if isinstance(last, int) and parent != 'programs' else last}"


def shown(value: Any) -> str:
    """A value as a message quotes it: 'fast', 12, true, a list, nothing."""
    if value is None:
        return "nothing"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, (int, Decimal)):
        return str(value)
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    text = str(value)
    if len(text) > SHOWN:  # an error is one line a person reads, whatever the file holds
        return f"{text[:SHOWN]!r}… ({len(text):,} characters)"
    return repr(text)


#: The characters of a value an error quotes at most.
SHOWN = 60


def _model_at(container: Path_) -> type[BaseModel]:
    if not container:
        return PlantSpec
    *head, last = container
    if isinstance(last, str) and last in SECTIONS:
        return SECTIONS[last]
    parent = head[-1] if head else None
    if parent in ITEMS:
        return ITEMS[parent][1]
    return PlantSpec


def _is_number_text(value: Any) -> bool:
    """Text that is a number when written without quotes: "0.300", not "1_000" or "fast"."""
    return isinstance(value, str) and DECIMAL_NUMBER.fullmatch(value) is not None


def _required(loc: Path_) -> bool:
    field = _model_at(loc[:-1]).model_fields.get(loc[-1]) if loc and isinstance(loc[-1], str) else None
    return field is not None and field.is_required()


def _expected(kind: str, ctx: dict[str, Any], container: Path_) -> str:
    if kind in ("extra_forbidden", "invalid_key"):
        return ", ".join(_model_at(container).model_fields)
    return str(ctx.get("expected", "")).replace("'", "").replace(" or ", ", ")


def _hint(container: Path_, key: Any) -> str:
    description = _descriptions(_model_at(container)).get(key)
    return f" ({description})" if description else ""


@functools.cache
def _descriptions(model: type[BaseModel]) -> dict[str, str]:
    """Each key's description, as the schema gives it (numbers describe themselves there)."""
    properties = model.model_json_schema(schema_generator=Draft07).get("properties", {})
    return {key: p["description"] for key, p in properties.items() if "description" in p}


def _lookup(data: Any, path: Path_) -> Any:
    for part in path:
        try:
            data = data[part]
        except (KeyError, IndexError, TypeError):
            return None
    return data
