"""What several commands share: loading a plant, choosing modules, progress, reading back, planning."""

from __future__ import annotations

import contextlib
import json
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from prc3cfg.bustime import LineCost
from prc3cfg.errors import UserError
from prc3cfg.image import MAX_MODULE_ADDRESS, ModuleImage
from prc3cfg.link import Link, Trace, open_plant_links
from prc3cfg.planner import UnreachableImage, plan_module
from prc3cfg.plant import Plant
from prc3cfg.plantplan import ModuleChange, PlantPlan
from prc3cfg.readback import Target, read_all

stderr = Console(stderr=True)

PlantArg = Annotated[Path, typer.Argument(help="The plant file (YAML).", show_default=False)]
ModuleOpt = Annotated[Optional[list[str]], typer.Option("--module", help="Only this module (name); repeatable.")]
TraceOpt = Annotated[Optional[Path], typer.Option(help="Write every frame, both directions, with timestamps, in hex.")]
RetriesOpt = Annotated[int, typer.Option(help="Retries of a lost or damaged reply, per message.")]

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


@contextlib.contextmanager
def plant_links(plant: Plant, buses: Iterable[str], trace: Path | None, retries: int, observer=None) -> Iterator[dict[str, Link]]:
    with contextlib.ExitStack() as stack:
        tracer = Trace(stack.enter_context(trace.open("a"))) if trace else None
        yield stack.enter_context(open_plant_links(plant, buses, trace=tracer, retries=retries, observer=observer))


def plant_targets(pairs) -> list[Target]:
    return [Target(bus.name, module.address, module.name, tuple(module.managed_programs())) for bus, module in pairs]


def read_images(targets: list[Target], links: dict[str, Link]) -> dict[Key, ModuleImage]:
    with progress_bar(len(targets), "reading modules") as tick:
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
    return PlantPlan(plant.name, str(plant.path), plant.sha256, tuple(changes))
