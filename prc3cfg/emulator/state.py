"""The emulator state file `prc3-emulator/1` (interfaces.md §3): load and check, and save atomically.

Reading goes through `prc3cfg.files.read_json` (a regular file, bounded); saving through
`prc3cfg.files.write_atomically`, so a killed emulator leaves either the old or the new
file, never half of one.

Loading refuses, naming the module and the field, every value a module could not hold
because no message can carry it: each system parameter and program field must be a whole
number within the device's range for its kind (`prc3cfg.device.VALUE_RANGES`; P within
0..9999 and V within 1..600, the widest S1, S4 and S5 allow — all well inside a 16-bit
data word), the address S9 within 1..30, a program list of exactly 64, `mode`, `fault`,
`active_program` and `referenced` as interfaces.md §3 lists them. Relations between
values are not checked: a real module can hold a position above its S1 after a Teach In.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

from prc3cfg.device import VALUE_RANGES, ModuleState, value_range
from prc3cfg.errors import UserError
from prc3cfg.files import FileProblem, Why, read_json, write_atomically
from prc3cfg.image import DEFAULT_SYSTEM, MAX_MODULE_ADDRESS, PROGRAM_COUNT, PROGRAM_FIELDS, SYSTEM_KEYS, whole

FORMAT = "prc3-emulator/1"

#: System parameters under which P and V may take every value any module allows.
_WIDEST = replace(DEFAULT_SYSTEM, S1=VALUE_RANGES["S1"][1], S4=VALUE_RANGES["S4"][1], S5=VALUE_RANGES["S5"][0])


def load_state(path: Path) -> dict[int, ModuleState]:
    """The modules stored in `path` by address; {} when the file does not exist yet."""
    try:
        data = read_json(path)
    except FileProblem as problem:
        if problem.why is Why.MISSING:
            return {}
        remedy = "fix or delete it" if problem.why is Why.NOT_JSON else "give an emulator state file, or a path where none is yet"
        raise UserError(f"{problem.where(path)}: {problem} — {remedy}") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise UserError(f"{path}: not an emulator state file — expected \"format\": \"{FORMAT}\"")
    entries = data.get("modules", [])
    if not isinstance(entries, list):
        raise UserError(f"{path}: \"modules\" must be a list of modules — fix or delete it")
    modules: dict[int, ModuleState] = {}
    for index, entry in enumerate(entries):
        where = f"module entry {index}"
        try:
            if not isinstance(entry, dict):
                raise ValueError("is not an object")
            address = _whole(entry, "address", 1, MAX_MODULE_ADDRESS, name="address S9")
            where = f"module {address}"
            state = _module(entry)
        except ValueError as error:
            raise UserError(f"{path}: {where}: {error} — fix or delete the entry") from None
        if address in modules:
            raise UserError(f"{path}: module address {address} appears twice — keep one entry")
        modules[address] = state
    return modules


def _module(entry: dict[str, Any]) -> ModuleState:
    """A module from its checked state-file entry; ValueError names the field and what is wrong."""
    system = entry.get("system")
    if not isinstance(system, dict):
        raise ValueError("system: missing, or not an object")
    for key in SYSTEM_KEYS:
        _whole(system, key, *value_range(key, _WIDEST)[:2], name=f"system: {key}")
    programs = entry.get("programs")
    if not isinstance(programs, list) or len(programs) != PROGRAM_COUNT:
        held = f"{len(programs)} programs" if isinstance(programs, list) else repr(programs)
        raise ValueError(f"programs: a list of all {PROGRAM_COUNT} programs is needed, not {held}")
    for number, program in enumerate(programs, 1):
        if not isinstance(program, dict):
            raise ValueError(f"program {number}: {program!r} is not a program")
        for key in PROGRAM_FIELDS:
            _whole(program, key, *value_range(key, _WIDEST)[:2], name=f"program {number}: {key}")
    if entry.get("active_program") is not None:
        _whole(entry, "active_program", 1, PROGRAM_COUNT, name="active_program")
    if not isinstance(entry.get("fault"), str | None):
        raise ValueError(f"fault = {entry['fault']!r} must be null or the name of a fault")
    if not isinstance(entry.get("referenced", True), bool):
        raise ValueError(f"referenced = {entry['referenced']!r} must be true or false")
    return ModuleState.from_json(entry)  # mode and fault: the device model's own checks


def _whole(data: dict[str, Any], key: str, low: int, high: int, *, name: str) -> int:
    """`data[key]`, a whole number within low..high; ValueError saying what it is otherwise."""
    if key not in data:
        raise ValueError(f"{name} is missing")
    value = whole(data[key], name)
    if not low <= value <= high:
        raise ValueError(f"{name} = {value} is outside {low}..{high}")
    return value


def state_document(modules: dict[int, ModuleState]) -> dict:
    return {"format": FORMAT, "modules": [modules[a].to_json() for a in sorted(modules)]}


def save_state(path: Path, modules: dict[int, ModuleState]) -> None:
    """Write the state file atomically; OSError when it cannot be written."""
    write_atomically(path, json.dumps(state_document(modules), indent=1))


def cannot_save(path: Path, error: OSError) -> str:
    """What went wrong saving the state file `path`, in a few words (for logs and errors)."""
    reason = error.strerror or str(error)
    if error.filename is not None and Path(error.filename) in path.parents:  # its folder is the trouble
        reason = f"{reason}: {error.filename}"
    return f"{path}: cannot save the emulator state file ({reason})"
