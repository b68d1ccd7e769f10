"""The facts of `prc3cfg status`, gathered from prc3cfg's records only — never the bus (the line stays one
writer's): the journals beside the plant file (revision counter, last verified, last failed), each line's
record of what its modules hold (drift, evidence age: `prc3cfg.shell.line_record`), the records of pending
axis releases (`prc3cfg.shell.pending_records`) and the line's lock (an apply runs:
`prc3cfg.shell.locks.held_by`).

Another user's records are data: read bounded by the modules that read them, every text in them escaped
where it is shown (`prc3cfg.core.text.shown`), and nothing here writes. Owns gathering and `watched`, the
files whose change means the status may have changed; the decision is `prc3cfg.core.status`'s.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from prc3cfg.core.status import LastVerified, ModuleFacts, drifted
from prc3cfg.core.text import shown
from prc3cfg.plant import Plant
from prc3cfg.shell import line_record, machine_folder, pending_records
from prc3cfg.shell.audit import check_journal, journals, stamped
from prc3cfg.shell.locks import held_by, lock_dir
from prc3cfg.shell.records import records_dir
from prc3cfg.shell.sessions import bus_line_keys

#: Journal commands that change a module's configuration when they verify.
CHANGING = ("apply", "restore")


@dataclass
class _History:
    revision: int = 0
    last_verified: LastVerified | None = None
    last_failed: bool = False


def _text(value: Any) -> str | None:
    return shown(value) if isinstance(value, str) else None


def _verified(path: Path, header: dict[str, Any]) -> LastVerified:
    plant = header["plant"] if isinstance(header.get("plant"), dict) else {}
    git = plant["git"] if isinstance(plant.get("git"), dict) else {}
    user, host = _text(header.get("user")), _text(header.get("host"))
    when = stamped(path)
    return LastVerified(time="" if when is None else when.isoformat(timespec="microseconds"), by=None
                        if user is None else f"{user}@{host or '?'}",
                    plant_file=_text(plant.get("path")), plant_sha256=_text(plant.get("sha256")),
                        commit=_text(git.get("commit")))


def histories(plant_path: Path) -> dict[tuple[str, int], _History]:
    """Per (bus, address): the runs of the plant file's journals (oldest first) that wrote the module."""
    found: dict[tuple[str, int], _History] = {}
    for path in journals(plant_path):
        checked = check_journal(path)
        header = checked.header or {}
        if header.get("command", "apply") not in CHANGING:
            continue
        for record in checked.records:
            if (record.get("event") != "result" or not isinstance(record.get("bus"), str)
                or type(record.get("address")) is not int):
                continue
            if not record.get("written"):
                continue  # nothing written: the configuration did not change
            history = found.setdefault((record["bus"], record["address"]), _History())
            history.last_failed = record.get("verified") is not True
            if not history.last_failed:
                history.revision += 1
                history.last_verified = _verified(path, header)
    return found


def identities(plant: Plant) -> dict[str, tuple[str, ...]]:
    """Each bus's line identities (`bus_line_keys`), resolved once: a server that looks every second
    resolved every line's address twice a look."""
    return {bus.name: bus_line_keys(plant, bus) for bus in plant.buses}


def gather(plant: Plant, keys: Mapping[str, tuple[str, ...]],
           now: datetime | None = None) -> tuple[list[ModuleFacts], list[str]]:
    """Every module's facts, in the plant file's order, and notes on records passed over; `keys`:
    `identities`."""
    now = now or datetime.now(UTC)
    done = histories(plant.path)
    facts, notes = [], []
    for bus in plant.buses:
        line = keys[bus.name]
        running = held_by(line) is not None
        record = line_record.LineRecord(line)
        notes += record.passed_over()
        known = record.known()
        pending = pending_records.of_line(line, pending_records.RELEASE)
        for module in bus.modules:
            history = done.get((bus.name, module.address), _History())
            k = known.get(module.address)
            age = None if k is None else (now - datetime.fromisoformat(k.since)).total_seconds()
            travel = any(p.address in (0, module.address) for p in pending)
            facts.append(ModuleFacts(bus.name, module.address, module.name, history.revision,
                                     history.last_verified,
                                     history.last_failed, running, travel, k is not None
                                     and drifted(module.desired_image(), k.image),
                                     age, bus.record_max_age))
    return facts, notes


def watched(plant: Plant) -> Iterator[Path]:
    """The files and folders whose size or time of change tells that the status may have changed."""
    yield plant.path
    yield records_dir(plant.path, "journal")
    for directory in machine_folder.state_dirs():
        yield directory / line_record.KIND
        yield directory / machine_folder.RELEASES
    yield lock_dir()


def fingerprint(plant: Plant, keys: Mapping[str, tuple[str, ...]]) -> tuple[tuple[str, int, int], ...]:
    """What `watched` looks like now (name, size, time of change, folders with their entries') — polled by
    `status serve` to publish again when it changes; held locks change no file, so the lock's holder is asked
    too."""
    seen = []
    for path in watched(plant):
        with contextlib.suppress(OSError):
            status = path.stat()
            seen.append((str(path), status.st_size, status.st_mtime_ns))
            if path.is_dir():
                seen += [(str(p), (s := p.stat()).st_size, s.st_mtime_ns) for p in sorted(path.iterdir())]
    seen += [(bus.name, int(held_by(keys[bus.name]) is not None), 0) for bus in plant.buses]
    return tuple(seen)
