"""What a plant file says and keeps: adopting Teach In into it, its records, its gateways and pictures.

`adopt` and `write_adoption` (and `reason_for`, the reason a bus with `require_reason` needs);
`verify_records`, `list_records`, `prune_records`; `init_data_block` of a gateway; `picture` and
`plot_format`. Does not own rewriting the file (`prc3cfg.plant.adopt`) nor checking, listing and
pruning records (`prc3cfg.shell.audit`, `prc3cfg.shell.recorded_runs`).
"""

from __future__ import annotations

import contextlib
import hashlib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path
from typing import TYPE_CHECKING, Any

from prc3cfg.api._plan import load, plan, read, select
from prc3cfg.core import gateway, plot
from prc3cfg.core.image import Key, ModuleImage
from prc3cfg.core.plant_plan import PlantPlan
from prc3cfg.errors import UserError
from prc3cfg.plant import Bus, Plant
from prc3cfg.shell import audit, pending_records, recorded_runs
from prc3cfg.shell.audit import Verified
from prc3cfg.shell.cancel import Cancellation
from prc3cfg.shell.files import replace_unless_changed
from prc3cfg.shell.locks import line_lock
from prc3cfg.shell.platform import python_command, resolved
from prc3cfg.shell.recorded_runs import Pruned, RecordedRun
from prc3cfg.shell.records import Journal, reason_given
from prc3cfg.shell.records import header as run_header
from prc3cfg.shell.sessions import LineOptions, bus_line_keys

if TYPE_CHECKING:
    from prc3cfg.plant.adopt import Adopted
    from prc3cfg.shell.link.client import Link


@dataclass(frozen=True)
class Adoption:
    """The plant file rewritten to describe what the modules hold (`adopt`), not written yet:
    `before` is the file as read, `after` the new text, `adopted` each value with its one-line `text`, `buses`
    the buses of the modules adopted from."""

    path: Path
    before: str
    after: str
    adopted: tuple[Adopted, ...]
    #: why it is adopted (`--reason`, `PRC3CFG_REASON`), and the plant's name: for the journal's header
    reason: str | None = None
    plant: str = ""
    command_line: tuple[str, ...] | None = None
    buses: tuple[str, ...] = ()


def adopt(plant: Plant, modules: Iterable[str] | None = None, programs: Iterable[int] | None = None,
          options: LineOptions | None = None, *, reason: str | None = None, check: bool = False,
          links: Mapping[str, Link] | None = None) -> Adoption:
    """Read the chosen modules and work out the plant file that describes what they hold: only the
    values that drifted, in the layer they came from (`prc3cfg.plant.adopt`); `write_adoption`
    writes it. Unless it is only a `check`, a bus with `require_reason` refuses before its line is
    opened when neither `reason` nor `PRC3CFG_REASON` gives one."""
    options = options or LineOptions()
    given = (None if check
             else reason_for(plant, {bus.name: bus for bus, _ in select(plant, modules)}.values(), reason,
                             "adopt"))
    before = _plant_text(plant.path)
    images = read(plant, modules, options, command="adopt", links=links)
    # its YAML splicing: for adopt only, not every apply that imports this module
    from prc3cfg.plant.adopt import adopt as adopt_text

    found = adopt_text(plant, images, before, programs)
    return Adoption(plant.path, before, found.text, found.adopted, given, plant.name, options.command_line,
                    found.buses)


def write_adoption(adoption: Adoption) -> None:
    """Write the adopted plant file in place of the one read, atomically and with its permissions
    (through a link, to the file linked to) — refused if the file changed since it was read, which is
    checked once the new text is on disk, around the rename (`replace_unless_changed`). A journal
    says who adopted what and why, before and after (`prc3cfg.shell.records`)."""
    target = resolved(adoption.path)
    before = adoption.before.encode("utf-8")
    said = run_header("adopt", adoption.path, adoption.plant, hashlib.sha256(before).hexdigest(),
                      reason=adoption.reason,
                      argv=adoption.command_line)
    journal = Journal(adoption.path, said, audit.follow(adoption.path))
    try:
        journal.record("adopt", buses=list(adoption.buses), values=[value.text for value in adoption.adopted])
    except OSError as error:
        raise UserError(f"{journal.path}: cannot write the journal ({error.strerror}) — the plant file was "
                        "not changed") from None
    try:
        try:
            written = replace_unless_changed(target, adoption.after, before)
        except OSError as error:
            raise UserError(f"{adoption.path}: cannot write it ({error.strerror}) — it was "
                            "not changed") from None
        try:
            journal.record("adopted", written=written,
                           sha256=(hashlib.sha256(adoption.after.encode("utf-8")).hexdigest() if written
                                   else None))
        # after the write: it is told, and the journal named as lacking its last record
        except OSError as error:
            done = ("was adopted and written" if written
                    else "changed while adopting — it was not written: adopt again")
            raise UserError(f"could not keep the journal ({journal.path}: {error.strerror}): the plant file "
                            f"{adoption.path} {done}; "
                            "the records on disk are incomplete (the journal lacks the record that says so) "
                            "— free the space") from None
    finally:
        with contextlib.suppress(OSError):  # a journal the disk refused: said above
            journal.close()
    if not written:
        raise UserError(f"{adoption.path}: the plant file changed while adopting — it was not written: "
                        "adopt again")


def reason_for(plant: Plant, buses: Iterable[Bus], reason: str | None, command: str) -> str | None:
    """Why `command` writes (`reason`, else `PRC3CFG_REASON`) — refused in one line, before any line
    is opened, where a bus says `require_reason: true` and nothing says why."""
    given = reason_given(reason)
    requiring = [bus.name for bus in buses if bus.require_reason]
    if given is None and requiring:
        raise UserError(f"{plant.path}: {'bus' if len(requiring) == 1 else 'buses'} {', '.join(requiring)} "
                        f"{'requires' if len(requiring) == 1 else 'require'} a reason for every {command} "
                        "(require_reason: true) "
                        "— nothing was written: give --reason TEXT or set PRC3CFG_REASON")
    return given


def verify_records(paths: Iterable[Path]) -> Verified:
    """Check the records under `paths` — plant files (their records), records folders, journals,
    snapshots (`prc3cfg.shell.audit.check`): the first record of each file that does not match."""
    return audit.check(list(paths))


def list_records(plant_path: Path) -> list[RecordedRun]:
    """Every apply, restore and adopt beside the plant file, oldest first, as its records tell it:
    none for a plant file never applied — and a one-line `UserError` for a path that is no plant
    file and has no records beside it (a typo, a folder, another file), which would list none too."""
    found = recorded_runs.runs(Path(plant_path))
    if not found:
        try:
            load(Path(plant_path))
        except UserError as error:
            what = str(error).split("\n", 1)[0].split(" — ", 1)[0]  # the first problem, without its remedy
            raise UserError(f"{what} — no plant file with records: {audit.WHERE}") from None
    return found


def prune_records(plant: Plant, *, keep: int | None = None, older_than_days: float | None = None,
                  dry_run: bool = False) -> Pruned:
    """Remove the plant's runs (journal and snapshot together) beyond the newest `keep` and older
    than `older_than_days` — nothing while a record beside it does not verify; never the newest
    snapshot of a line, never a run an axis release (or an E12) nobody was told of names."""
    if keep is None and older_than_days is None:
        raise UserError("say what to prune: --keep N (the newest N runs stay) or --older-than DAYS, or both")
    keys = {bus.name: bus_line_keys(plant, bus) for bus in plant.buses}
    with contextlib.ExitStack() as held:  # no apply of these lines writes its records meanwhile
        for bus in plant.buses:
            held.enter_context(line_lock(keys[bus.name], f"bus {bus.name} ({bus.port})",
                                         purpose="records prune"))
        every = [key for identities in keys.values() for key in identities]
        protected = [Path(r.journal) for kind in (pending_records.RELEASE, pending_records.E12)
                     for r in pending_records.of_line(every, kind) if r.journal]
        return recorded_runs.prune(plant.path, keep=keep, older_than_days=older_than_days,
                                   protected=protected, dry_run=dry_run)


def _plant_text(path: Path) -> str:
    try:
        return path.read_bytes().decode("utf-8", "replace")
    except OSError as error:
        raise UserError(f"{path}: cannot read it ({error.strerror}) — nothing was adopted") from None


def init_data_block(plant: Plant, bus_name: str) -> list[tuple[str, str, str]]:
    """The CP 524/525 Open Driver INIT data block of a bus's gateway: (label, notation, hex) per
    data word — refused in one line where the bus has no gateway or the driver would refuse it."""
    found = [b for b in plant.buses if b.name == bus_name]
    if not found:
        raise UserError(f"{plant.path}: no bus named {bus_name} — the plant's buses are "
                        f"{', '.join(b.name for b in plant.buses)}")
    bus = found[0]
    if bus.gateway is None:
        raise UserError(f"{plant.path}: bus {bus_name} has no gateway block — add gateway: "
                        f"{{receive_db, receive_dw, cpu, identifier}}")
    zvz_ms = Decimal(str(bus.zvz)) * 1000
    if zvz_ms != zvz_ms.to_integral_value():
        raise UserError(f"{plant.path}: bus {bus_name}: zvz {bus.zvz} s is not a whole number of "
                        "milliseconds — ZVZTIM is set in ms")
    settings = gateway.GatewaySettings(
        receive_db=bus.gateway.receive_db, receive_dw=bus.gateway.receive_dw, cpu=bus.gateway.cpu,
        identifier=bus.gateway.identifier, line=bus.line, zvz_ms=int(zvz_ms),
    )
    problems = gateway.refusals(settings)
    if problems:
        raise UserError(f"bus {bus_name}: the CP 524/525 Open Driver would refuse these settings: "
                        + "; ".join(map(str, problems)))
    return gateway.format_data_block(gateway.init_data_block(settings))


def picture(plant: Plant, module_name: str, *, fmt: str, images: dict[Key, ModuleImage] | None = None,
            planned: PlantPlan | None = None) -> bytes:
    """The chains of a module drawn (`prc3cfg.core.plot`, the plot extra): the plant file's, or what
    the module holds as before and what the plan leaves it holding as after — of `planned`, or of a
    plan from `images` (as `read` or `load_images` gave them)."""
    (bus, module), = select(plant, [module_name])
    title = f"module {module.name} — bus {bus.name}, address {module.address}"
    if images is None and planned is None:
        return plot.picture(module.desired_image(), fmt=fmt, title=f"{title}: the plant file",
                            python=python_command())
    planned = planned or plan(plant, [module.name], images=images)
    change = next(c for c in planned.modules if (c.bus, c.address) == (bus.name, module.address))
    return plot.picture(change.as_known(change.plan.predicted), change.as_known(change.actual), fmt=fmt,
                        title=f"{title}: before (dashed) and after the plan", python=python_command())


def plot_format(path: Path) -> str:
    """"svg" or "png", the format of a picture to write to `path` (by its suffix) — a PlotError for any
    other, and when matplotlib is missing, naming the command that installs it into this Python."""
    return plot.plot_format(path, python=python_command())


def status(plant: Plant) -> dict[str, Any]:
    """The plant's configuration status from prc3cfg's records only — no bus traffic: the
    `prc3cfg-status/1` document (`prc3cfg.core.status`), as `prc3cfg status --json` prints it."""
    from prc3cfg.core.status import document
    from prc3cfg.shell.status import gather, identities

    facts, notes = gather(plant, identities(plant))
    return document(str(plant.path), plant.sha256, facts, notes)


def serve_status(plant: Plant, listen: str, *, certificate: Path | None, private_key: Path | None,
                 trust: Path | None,
                 allow_anonymous: bool, no_security: bool, cancel: Cancellation) -> None:
    """Publish the plant's status read-only on OPC UA until `cancel` is (a signal, with
    `Cancellation.handling`) (`prc3cfg.shell.opcua`): a `UserError` naming the command that installs the
    optional extra where asyncua is missing."""
    try:
        from prc3cfg.shell import opcua
    except ImportError as error:
        if error.name is None or not error.name.startswith("asyncua"):
            raise
        raise UserError("prc3cfg status serve needs the OPC UA library asyncua (the extra opcua), which "
                        "the Python running prc3cfg "
                        f"does not have — install it there: {python_command()} -m pip "
                        "install asyncua") from None
    opcua.serve(plant, opcua.ServerSettings(listen, certificate, private_key, trust, allow_anonymous,
                                            no_security), cancel)
