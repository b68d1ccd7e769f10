"""The emulator state file `prc3-emulator/1` (interfaces.md §3): load, and save atomically.

Saving goes through `prc3cfg.files.write_atomically`, so a killed emulator leaves either
the old or the new file, never half of one.
"""

from __future__ import annotations

import json
from pathlib import Path

from prc3cfg.device import ModuleState
from prc3cfg.errors import UserError
from prc3cfg.files import write_atomically

FORMAT = "prc3-emulator/1"


def load_state(path: Path) -> dict[int, ModuleState]:
    """The modules stored in `path` by address; {} when the file does not exist yet."""
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as error:
        raise UserError(f"{path}: cannot read the emulator state file ({error}) — fix or delete it") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise UserError(f"{path}: not an emulator state file — expected \"format\": \"{FORMAT}\"")
    modules: dict[int, ModuleState] = {}
    for index, entry in enumerate(data.get("modules", [])):
        try:
            state = ModuleState.from_json(entry)
        except (KeyError, TypeError, ValueError) as error:
            raise UserError(f"{path}: module entry {index}: {error} — fix or delete the entry") from None
        if state.address in modules:
            raise UserError(f"{path}: module address {state.address} appears twice — keep one entry")
        modules[state.address] = state
    return modules


def state_document(modules: dict[int, ModuleState]) -> dict:
    return {"format": FORMAT, "modules": [modules[a].to_json() for a in sorted(modules)]}


def save_state(path: Path, modules: dict[int, ModuleState]) -> None:
    """Write the state file atomically."""
    write_atomically(path, json.dumps(state_document(modules), indent=1))
