"""The emulator state file `prc3-emulator/1` (interfaces.md §3): load, and save atomically.

Saving writes a temporary file beside the target, flushes it to disk and renames it over
the target, so a killed emulator leaves either the old or the new file, never half of one.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from prc3cfg.device import ModuleState
from prc3cfg.errors import UserError

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
    """Write the state file atomically (temporary file, fsync, rename)."""
    text = json.dumps(state_document(modules), indent=1)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
