"""Plant files on disk: `load_plant(path)` reads one's bytes (`plant_bytes`) and hands them to the plant
layer; the policy file a plant file names (`load_policy`) and a fleet file (`load_fleet`) are read so too.

Only a regular file is read (a FIFO could block, `/dev/zero` never ends), at most `MAX_BYTES`
of it (`prc3cfg.shell.files.read_regular`); a path that cannot be read is a `PlantError` that
says what to do. What the bytes say — YAML, models, rules — is `prc3cfg.plant.parse_plant`'s.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from prc3cfg.plant import Plant, PlantError, parse_plant
from prc3cfg.plant.document import Document, parse_document
from prc3cfg.shell import platform
from prc3cfg.shell.files import FileProblem, Why, read_regular

if TYPE_CHECKING:
    from prc3cfg.plant.fleet import Fleet
    from prc3cfg.plant.policy import LoadedPolicy

#: A plant of 8 buses × 30 modules with all 64 programs written out is about 1.3 MB; with long
#: comments, long names and every field, a few MB. Bytes cost little: nodes are what is bounded
#: (`prc3cfg.plant.document.MAX_NODES`).
MAX_BYTES = 16 * 2**20

#: What to do about a plant path that cannot be read, by why.
_REMEDIES = {
    Why.MISSING: "check the path",
    Why.DIRECTORY: "give the plant file (*.yaml) in it",
    Why.NOT_A_FILE: "give the plant file (*.yaml) itself",
    Why.UNREADABLE: "check the path and its permissions",
    Why.TOO_LARGE: "a plant file is far smaller: check that this is the plant file",
}


def load_plant(path: str | Path) -> Plant:
    """The plant in the file `path`; `PlantError` with its problems ("file:line:column: …") otherwise — a
    bus with parity on a port that is this machine's pseudo-terminal among them (its device is looked up,
    never opened)."""
    return parse_plant(path, plant_bytes(path), pseudo_terminal=platform.is_pseudo_terminal)


def plant_bytes(path: str | Path) -> bytes:
    """The bytes of the plant file `path`; `PlantError` saying what to do where it cannot be read."""
    try:
        return read_regular(Path(path), MAX_BYTES)
    except FileProblem as problem:
        raise PlantError([f"{path}: {problem} — {_REMEDIES[problem.why]}"]) from None


def load_policy(plant: Plant) -> LoadedPolicy | None:
    """The policy file `plant` names (relative to the plant file), None when it names none; `PlantError` with
    its problems, or saying it cannot be read — a plant file that names a policy is never used without it."""
    path = plant.policy_path
    if path is None:
        return None
    try:
        data = read_regular(path, MAX_BYTES)
    except FileProblem as problem:
        raise PlantError([f"{path}: {problem} (the policy file {plant.path} names) — "
                          f"{_REMEDIES[problem.why]}"]) from None
    # its models and rules: only for a plant file that names a policy
    from prc3cfg.plant.policy import parse_policy

    return parse_policy(path, data)


def load_fleet(path: str | Path) -> Fleet:
    """The fleet file `path` (docs/fleet.md); `PlantError` with its problems, or saying it cannot be read."""
    try:
        data = read_regular(Path(path), MAX_BYTES)
    except FileProblem as problem:
        raise PlantError([f"{path}: {problem} (the fleet file) — "
                          f"{_REMEDIES[problem.why].replace('plant', 'fleet')}"]) from None
    from prc3cfg.plant.fleet import parse_fleet  # its models: for the fleet commands only

    return parse_fleet(str(path), data)


def plant_document(plant: Plant) -> Document:
    """The plant file read again as a document, to place what a policy found in it."""
    return parse_document(str(plant.path), plant_bytes(plant.path))
