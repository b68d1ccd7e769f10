"""What several commands share: loading a plant, choosing modules, progress, reading back, planning."""

from __future__ import annotations

import contextlib
import json
import sys
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from prc3cfg.bustime import LineCost
from prc3cfg.cancel import Cancellation
from prc3cfg.device import can_clamp
from prc3cfg.errors import UserError
from prc3cfg.image import MAX_MODULE_ADDRESS, ModuleImage
from prc3cfg.link import Link, Trace, open_plant_links
from prc3cfg.link.ports import EMULATOR_SCHEME, emulator_state_path
from prc3cfg.locks import line_keys, line_lock
from prc3cfg.planner import UnreachableImage, plan_module
from prc3cfg.plant import Plant
from prc3cfg.plantplan import ModuleChange, PlantPlan
from prc3cfg.readback import Target, read_all

stderr = Console(stderr=True)
#: Ctrl-C and SIGTERM for the running command (`main` installs the handlers).
CANCEL = Cancellation()

PlantArg = Annotated[Path, typer.Argument(help="The plant file (YAML).", show_default=False)]
ModuleOpt = Annotated[Optional[list[str]], typer.Option("--module", help="Only this module (name); repeatable.")]
TraceOpt = Annotated[Optional[Path], typer.Option(help="Write every frame, both directions, with timestamps, in hex.")]
RetriesOpt = Annotated[int, typer.Option(help="Retries of a lost or damaged reply, per message.")]
LockOpt = Annotated[float, typer.Option("--lock-timeout", help="Seconds to wait while another prc3cfg uses the line.")]

Key = tuple[str, int]  # (bus name, module address)


def parse_addresses(text: str) -> list[int]:
    """"1,3-5" → [1, 3, 4, 5]; every address must lie in 1..30."""
    addresses: set[int] = set()
    for part in filter(None, (p.strip() for p in text.split(","))):
        low, _, high = part.partition("-")
        try:
            first, last = int(low), int(high or low)
        except ValueError:
            raise UserError(f"--modules: '{part}' is not an address or a range like 3-5") from None
        if not 1 <= first <= last <= MAX_MODULE_ADDRESS:
            raise UserError(f"--modules: '{part}' is outside 1..{MAX_MODULE_ADDRESS} — module addresses are 1..30")
        addresses.update(range(first, last + 1))
    return sorted(addresses)


def chosen_modules(plant: Plant, names: Iterable[str] | None) -> list[tuple[object, object]]:
    """(bus, module) pairs of the plant, limited to the named modules; unknown names are an error."""
    pairs = list(plant.modules())
    if not names:
        return pairs
    wanted = set(names)
    unknown = wanted - {module.name for _, module in pairs}
    if unknown:
        raise UserError(
            f"{plant.path}: no module named {', '.join(sorted(unknown))} — the plant's modules are "
            + ", ".join(module.name for _, module in pairs)
        )
    return [(bus, module) for bus, module in pairs if module.name in wanted]


def line_cost(bus) -> LineCost:
    return LineCost.of(bus.framing, bus.line, bus.turnaround, bus.zvz)


@contextlib.contextmanager
def progress_bar(total: int, description: str) -> Iterator[Callable[..., None]]:
    """A rich progress bar on stderr; yields a function that advances it by one."""
    with Progress(
        TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
        console=stderr, transient=True, disable=not stderr.is_terminal,
    ) as progress:  # fmt: skip
        task = progress.add_task(description, total=total)
        yield lambda *_: progress.advance(task)


def _lock_waiting(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


@contextlib.contextmanager
def locked_line(keys: tuple[str, ...], description: str, timeout: float, purpose: str) -> Iterator[None]:
    """Hold the lock of one line (`prc3cfg.locks`), saying on stderr whose lock a wait is for."""
    with line_lock(keys, description, timeout=timeout, purpose=purpose, waiting=_lock_waiting):
        yield


def bus_line_keys(plant: Plant, bus) -> tuple[str, ...]:
    """The identities of a bus's line: its port, or for `emulator://` the emulator's state file."""
    state = emulator_state_path(plant.path, bus.port) if bus.port.startswith(EMULATOR_SCHEME) else None
    return line_keys(bus.port, emulator_state=state)


@contextlib.contextmanager
def plant_links(
    plant: Plant, buses: Iterable[str], trace: Path | None, retries: int, observer=None, *,
    lock_timeout: float = 0.0, purpose: str = "read",
) -> Iterator[dict[str, Link]]:  # fmt: skip
    """A `Link` per named bus, each line locked first: only one prc3cfg talks on a line at a time.

    Two buses that are one line (two spellings of one address) are refused: they would
    wait for each other's lock."""
    names = set(buses)
    keys = {bus.name: bus_line_keys(plant, bus) for bus in plant.buses if bus.name in names}
    owner: dict[str, str] = {}
    for name, identities in keys.items():
        for key in identities:
            if key in owner:
                raise UserError(f"{plant.path}: buses {owner[key]} and {name} are one line ({key}) — "
                                "describe each line once, as one bus")  # fmt: skip
            owner[key] = name
    with contextlib.ExitStack() as stack:
        for bus in plant.buses:
            if bus.name in names:
                stack.enter_context(locked_line(keys[bus.name], f"bus {bus.name} ({bus.port})", lock_timeout, purpose))
        tracer = Trace(stack.enter_context(trace.open("a"))) if trace else None
        links = stack.enter_context(
            open_plant_links(plant, buses, trace=tracer, retries=retries, observer=observer, cancel=CANCEL.event)
        )
        yield links
        note_repeats(links.values())  # after a success only: a failure's own line says what went wrong


def note_repeats(links: Iterable[Link]) -> None:
    """One line per line that had to repeat exchanges: a noisy line is worth knowing about."""
    for link in links:
        if link.repeated:
            print(f"note: bus {link.bus}: {link.repeated} of {link.exchanges} exchanges were lost or damaged and "
                  "made again — check the cabling if this is not a test line (--trace shows every frame)",
                  file=sys.stderr)  # fmt: skip


def plant_targets(pairs) -> list[Target]:
    """What to read of each module: its managed programs, and every program its plant
    system parameters could clamp."""
    return [
        Target(bus.name, module.address, module.name, tuple(module.managed_programs()), module.desired_system())
        for bus, module in pairs
    ]


def read_images(targets: list[Target], links: dict[str, Link]) -> dict[Key, ModuleImage]:
    """Every target read back; a Ctrl-C stops after the exchange in flight (`Interrupted`)."""
    with CANCEL.deferred(), progress_bar(len(targets), "reading modules") as tick:
        return read_all(targets, links, progress=tick)


def load_actual(path: Path, plant: Plant, pairs) -> dict[Key, ModuleImage]:
    """Module images saved by `read --json`, matched to the plant's modules by bus and address."""
    try:
        entries = json.loads(path.read_text())
        saved = [(entry.get("bus"), ModuleImage.from_json(entry)) for entry in entries]
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as error:
        raise UserError(f"{path}: not a list of module images as `prc3cfg read --json` writes ({error})") from None
    images: dict[Key, ModuleImage] = {}
    for bus, module in pairs:
        found = [img for b, img in saved if img.address == module.address and b in (None, bus.name)]
        if len(found) != 1:
            raise UserError(
                f"{path}: {'no' if not found else 'more than one'} image for bus {bus.name}, module "
                f"{module.address} ({module.name}) — save the images again with prc3cfg read --json"
            )
        missing = [n for n in module.managed_programs() if found[0].programs[n - 1] is None]
        if missing:
            raise UserError(
                f"{path}: the image of bus {bus.name}, module {module.address} lacks program {missing[0]}, "
                "which the plant manages — save the images again with prc3cfg read --json"
            )
        unread = [n for n, p in enumerate(found[0].programs, start=1) if p is None]
        if unread and can_clamp(found[0].system, module.desired_system()):
            raise UserError(
                f"{path}: the image of bus {bus.name}, module {module.address} lacks program {unread[0]}, which "
                "the plant's system parameters would clamp — save the images again with prc3cfg read --json"
            )
        images[(bus.name, module.address)] = found[0]
    return images


def make_plan(plant: Plant, pairs, actual: dict[Key, ModuleImage], desired: dict[Key, ModuleImage] | None = None) -> PlantPlan:
    """Plan every chosen module from its read-back to its desired image (the plant file's by default)."""
    changes = []
    for bus, module in pairs:
        key = (bus.name, module.address)
        target = desired[key] if desired is not None else module.desired_image()
        try:
            module_plan = plan_module(actual[key], target, line_cost(bus))
        except UnreachableImage as error:
            raise UserError(f"bus {bus.name}, module {module.address} ({module.name}): {error}") from None
        changes.append(ModuleChange(bus.name, module.name, actual[key], target, module_plan))
    return PlantPlan(plant.name, str(plant.path.resolve()), plant.sha256, tuple(changes))
