"""What several commands share: loading a plant, choosing modules, progress, reading back, planning."""

from __future__ import annotations

import contextlib
import os
import stat
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import Annotated, Any, Optional

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from prc3cfg.bustime import LineCost
from prc3cfg.cancel import Cancellation
from prc3cfg.device import can_clamp
from prc3cfg.errors import UserError
from prc3cfg.files import FileProblem, Why, read_json, write_atomically
from prc3cfg.image import MAX_MODULE_ADDRESS, ModuleImage
from prc3cfg.link import Link, Trace, open_plant_links
from prc3cfg.link.ports import EMULATOR_SCHEME, emulator_state_path
from prc3cfg.locks import line_keys, line_lock
from prc3cfg.planner import UnreachableImage, plan_module
from prc3cfg.plant import Plant
from prc3cfg.plantplan import ModuleChange, PlantPlan
from prc3cfg.readback import Target, read_all
from prc3cfg.sharing import Module, share

stderr = Console(stderr=True)
#: Ctrl-C and SIGTERM for the running command (`main` installs the handlers).
CANCEL = Cancellation()

#: Bytes written and flushed in the folder of an output file before any time on the line:
#: a full disk or a read-only folder says so then, not after the read-back.
PROBE = 4096
#: Linux's /dev/full (character device 1:7): every write fails with "no space left on device".
DEV_FULL = (1, 7)


def check_output(path: Path | None, option: str, *, plant: Path | None = None) -> Path | None:
    """Refuse in one line — before any time is spent on the line — an output that cannot be written:
    a directory, a missing folder, a read-only or full one, /dev/full, the plant file itself."""
    if path is None:
        return None
    where = f"{option} {path}"
    try:
        found = os.stat(path)
    except FileNotFoundError:
        found = None
    except OSError as error:
        raise UserError(f"{where}: {error.strerror} — name a file in a folder you can write to") from None
    if found is not None:
        if stat.S_ISDIR(found.st_mode):
            raise UserError(f"{where} is a directory — name a file in it")
        if plant is not None and plant.exists() and os.path.samefile(path, plant):
            raise UserError(f"{where} is the plant file itself — name another file")
        if stat.S_ISCHR(found.st_mode) and (os.major(found.st_rdev), os.minor(found.st_rdev)) == DEV_FULL:
            raise UserError(f"{where}: no space left on device — name a file on a disk with space")
        if not stat.S_ISREG(found.st_mode):
            return path  # a device or a FIFO (/dev/stdout, a pipe): written as it is
    folder = path.parent
    if not folder.is_dir():
        raise UserError(f"{where}: the folder {folder} does not exist — create it, or name a file in an existing folder")
    try:
        fd, probe = tempfile.mkstemp(prefix=".prc3cfg-probe-", dir=folder)
        try:
            os.write(fd, bytes(PROBE))
            os.fsync(fd)
        finally:
            os.close(fd)
            os.unlink(probe)
    except OSError as error:
        raise UserError(f"{where}: cannot write in {folder} ({error.strerror}) — name a file on a disk and in a folder you can write to") from None
    return path


def write_output(path: Path, text: str, option: str) -> None:
    """Write an output file: a regular file atomically, a device or FIFO as it is; one line if it fails."""
    try:
        if path.exists() and not path.is_file():
            with path.open("w") as handle:
                handle.write(text)
        else:
            write_atomically(path, text)
    except OSError as error:
        raise UserError(f"{option} {path}: cannot write it ({error.strerror}) — nothing was saved there") from None


def read_input(path: Path, what: str, remedy: str) -> Any:
    """A JSON file prc3cfg wrote (`what`: "the plan file …"), within `files.JSON_LIMIT`; one line otherwise."""
    try:
        return read_json(path)
    except FileProblem as problem:
        raise UserError(f"{problem.where(path)}: {problem} — {remedy if problem.why is Why.NOT_JSON else f'name {what}'}") from None


def _output_option(option: str) -> Callable[[Optional[Path]], Optional[Path]]:
    return lambda value: check_output(value, option)


PlantArg = Annotated[Path, typer.Argument(help="The plant file (YAML).", show_default=False)]
ModuleOpt = Annotated[Optional[list[str]], typer.Option("--module", help="Only this module (name); repeatable.")]
TraceOpt = Annotated[
    Optional[Path],
    typer.Option(callback=_output_option("--trace"), help="Write every frame, both directions, with timestamps, in hex."),
]
RetriesOpt = Annotated[int, typer.Option(min=0, max=100, help="Retries of a lost or damaged reply, per message.")]
LockOpt = Annotated[float, typer.Option("--lock-timeout", min=0, help="Seconds to wait while another prc3cfg uses the line.")]

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
    remedy = "save the images again with prc3cfg read --json"
    entries = read_input(path, "the file prc3cfg read --json wrote", remedy)
    try:
        saved = [(entry.get("bus"), ModuleImage.from_json(entry)) for entry in entries]
    except (ValueError, KeyError, TypeError, AttributeError) as error:
        raise UserError(f"{path}: not a list of module images as `prc3cfg read --json` writes ({error}) — {remedy}") from None
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
    """Plan every chosen module from its read-back to its desired image (the plant file's by default),
    then broadcast what the modules of a line share, where every receiver is known (`sharing`)."""
    changes = []
    for bus, module in pairs:
        key = (bus.name, module.address)
        target = desired[key] if desired is not None else module.desired_image()
        try:
            module_plan = plan_module(actual[key], target, line_cost(bus))
        except UnreachableImage as error:
            raise UserError(f"bus {bus.name}, module {module.address} ({module.name}): {error}") from None
        changes.append(ModuleChange(bus.name, module.name, actual[key], target, module_plan))
    broadcast_time, unshared = 0.0, sum(c.plan.bus_time for c in changes)
    for bus in {bus.name: bus for bus, _ in pairs}.values():
        on_bus = [c for c in changes if c.bus == bus.name]
        if not receivers_known(bus, on_bus):
            continue
        shared = share([Module(c.actual, c.desired, c.plan) for c in on_bus], line_cost(bus))
        if shared.broadcasts:
            plans = {c.address: (plan, len(shared.broadcasts)) for c, plan in zip(on_bus, shared.plans)}
            changes = [replace(c, plan=plans[c.address][0], broadcasts=plans[c.address][1]) if c.bus == bus.name else c for c in changes]
            broadcast_time += sum(line_cost(bus).broadcast_time(step.message) for step in shared.broadcasts)
    return PlantPlan(plant.name, str(plant.path.resolve()), plant.sha256, tuple(changes), broadcast_time,
                     unshared if broadcast_time else None)  # fmt: skip


def receivers_known(bus, changes: list[ModuleChange]) -> bool:
    """Whether every module on the bus's line is planned: the plant lists all the line holds (all 30
    addresses, or `only_these_modules: true`) and the plan covers each of them."""
    listed = {m.address for m in bus.modules}
    complete = len(listed) == MAX_MODULE_ADDRESS or getattr(bus, "only_these_modules", False)
    return complete and {c.address for c in changes} == listed
