"""The plan file `prc3cfg-plan/1` (docs/files.md "Plan file"): written, read back, checked, shown and proved.

Owns the format, its writer beside its reader (as Terraform keeps its planfile's): a plan's data as
the file holds it (`to_json`: per bus, per module, the steps as sent, the hashes they were planned
from, the figures) and the file `plan --out` writes (`write`: that, what stays on the hardware, and
beside each module's steps the words people review); then, once the shell has read its bytes (at most
`PLAN_LIMIT`, `prc3cfg.shell.files.read_json`), its bounds — nesting, texts, lists: `MAX_DEPTH`,
`MAX_TEXT`, `MAX_ITEMS` — its structure and steps checked (`read`), whether it was made for this plant
file by this prc3cfg (`to_apply`), the document `show` shows (`to_show`), and the proof that it is the
plan prc3cfg makes from the read-back now (`check_modules`, then `check_plan`).

A plan file is data anyone may have edited. Every value of it is proved against what prc3cfg works
out again, or is the file's claim: of a targeted plan's `read`, the `base` (always `RECORD`), the
modules and programs not read and `taken` (whose verification the programs not read rest on) are
worked out again by the apply from its read-back and the line's record; `not_as_verified` (which
modules were read in full, and why) rests on the record as it was before the plan's own read, cannot
be, and — like `left_alone` — is words only: shown by `show` as what the plan file says, never by the
apply as its own, and never consulted for what is read or sent.

A bus's broadcasts (`prc3cfg.core.broadcast_search`) are the leading steps of every module of that bus, marked
`"broadcast": true` — so each module's steps still say, in order, everything that reaches it (a reader
that sent them addressed would do the same, only slower) — and the bus lists them once under
`"broadcasts"`.

A plan file is proved by its data, never by its spelling nor by the words it shows people: its steps as
messages, then each of its figures, names, hashes and keys against the value `to_json` writes for the
plan prc3cfg makes now (`check_plan`). The review beside a module's steps — its `changes`, `warning` and
steps' `summary`, `prc3cfg.core.render`'s words handed to `write` (`Words`: the rendering reads plan files
and so sits above this module) — is the file's claim about itself, written with its digest
(`review_sha256`, `Review`): `apply --plan` refuses a review that is not the text its digest was written
for (the reviewer approved that text; words changed after could mislead one while the steps stay
proved), and a plan file without digests as made by an older prc3cfg; a text its digest matches is
taken however prc3cfg would word it now, so that a new wording refuses no plan file. The digest is no
signature — the steps are what is proved — and `show` marks a review that is not as written as the
file's words. Pure: the path is only named.

Long because the format is one thing (over 500 lines): the writer, the two contracts it is read by
(`PlanDocument`; `ShownPlanDocument` for `show`) and the proof name the same keys, and apart they would
drift.
"""

from __future__ import annotations

import hashlib
import itertools
import json
from collections.abc import Iterable
from dataclasses import dataclass
from enum import StrEnum
from math import fsum
from pathlib import Path
from typing import Any, Protocol

from pydantic import BaseModel, Field, ValidationError

from prc3cfg import __version__
from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.contract import LATER, Flag, Number, Text, Whole, json_path, said
from prc3cfg.core.error_codes import describe
from prc3cfg.core.image import DEFAULT_SYSTEM, PROGRAM_COUNT, ModuleImage
from prc3cfg.core.planner import StepProblem, plan_from_steps, summarise
from prc3cfg.core.planner.check import MAX_STEPS
from prc3cfg.core.plant_plan import LineProof, ModuleChange, PlantPlan, Reading
from prc3cfg.core.text import address_ranges, shown
from prc3cfg.errors import UserError

Key = tuple[str, int]  # (bus name, module address)

FORMAT = "prc3cfg-plan/1"

#: What a targeted read-back compares with, in words: a plan file's `read.base` (`prc3cfg.shell.line_record`).
RECORD = "the line's record of what prc3cfg last read or verified"

#: The largest plan file prc3cfg reads: the largest it writes, of the largest plant (8 buses × 30 modules,
#: every field of every program changed, bench/plan_time_bench.py), is 17.4 MB.
PLAN_LIMIT = 32 * 2**20
#: How deep a plan file may nest: prc3cfg's nest 9 deep (the document, `buses`, a bus, `modules`, a
#: module, `changes`, `fields`, a field, its value); deeper, rendering and checking it would recurse
#: without end (900 deep was a RecursionError in `show`).
MAX_DEPTH = 16
#: The longest text (or key) of a plan file: prc3cfg's longest are a stroke chart (about 1,000
#: characters) and a path (4,096 at most on Linux).
MAX_TEXT = 65_536
#: The most items of a list, or keys of an object: prc3cfg writes at most MAX_STEPS steps and about 650
#: changed fields a module, 30 modules a bus, one axis release, one `taken` a module of the plant.
MAX_ITEMS = 100_000


class Words(Protocol):
    """What a plan file says to people beside a module's steps: the module `prc3cfg.core.render`, passed as it
    to `write` (it imports this one: a plan is shown from its `to_json`). Nothing proves a plan by them."""

    def review(self, change: ModuleChange) -> dict[str, Any]:
        """What the file holds beside a module's steps for people to review (its `changes`, its `warning`)."""


#: A module's review digest (docs/files.md): the SHA-256 of the words people review beside its steps, as
#: written.
REVIEW = "review_sha256"


def review_sha256(module: dict[str, Any]) -> str:
    """The digest of a module entry's review text as the file holds it: its `changes`, its `warning` and its
    steps' `summary`, in that object's canonical JSON — keys sorted, no whitespace, every other character than
    ASCII a \\u escape — so that a file another tool wrote again has the same digest. Any JSON (a key missing
    is null): the text of a hostile file has a digest too."""
    steps = module.get("steps")
    summaries = ([step.get("summary") if isinstance(step, dict) else None for step in steps]
                 if isinstance(steps, list) else None)
    review = {"changes": module.get("changes"), "warning": module.get("warning"), "summaries": summaries}
    return hashlib.sha256(json.dumps(review, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


class Review(StrEnum):
    """What a module's review text is to `show`: the text its digest was written for, changed since, or
    without a digest (a plan file made before plan files carried one)."""

    AS_WRITTEN = "as written"
    CHANGED = "changed"
    NO_DIGEST = "no digest"

    @classmethod
    def of(cls, module: dict[str, Any]) -> Review:
        said = module.get(REVIEW)
        if not isinstance(said, str):
            return cls.NO_DIGEST
        return cls.AS_WRITTEN if said == review_sha256(module) else cls.CHANGED


def image_sha256(image: ModuleImage) -> str:
    """The hash of a read-back, over its canonical JSON: what a module held when its plan was made."""
    text = json.dumps(image.to_json(), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


# -- writing ---------------------------------------------------------------------------------


def to_json(plan: PlantPlan, *, hashes: bool = True) -> dict[str, Any]:
    """A plan's data as its plan file holds it: what was planned from (the plant file's hash, each
    module's read-back hash), each module's steps, each bus's broadcasts and probes, the figures.
    Every output of a plan — the file, human, markdown — is made from it; those people read show no
    read-back's hash, and are made without them (`hashes=False`: each `state_sha256` None — 240
    modules' take 30 ms)."""
    phases = plan.phases()
    document = {
        "format": FORMAT,
        "prc3cfg_version": __version__,
        "plant": plan.plant,
        "plant_path": plan.plant_path,
        "plant_sha256": plan.plant_sha256,
        "buses": [
            {"name": bus,
             "modules": [_module_json(m, hashes) | ({"read": _module_read(plan.reading, m)}
                                                    if plan.reading else {}) for m in modules]}
            | (_proof_json(proof) if (proof := plan.proof(bus)) is not None else {})
            | ({"broadcasts": [
                {"message": step.message.hex(), "summary": step.summary, "releases_axes": step.releases_axes,
                 "modules": [m.address for m in modules if m.broadcasts]}
                for step in plan.broadcasts(bus)
            ]} if plan.broadcasts(bus) else {})
            for bus, modules in plan.buses().items()
        ],
        "estimated_bus_time_s": round(plan.bus_time, 4),
        "naive_bus_time_s": round(plan.naive_bus_time, 4),
        "estimated_phases_s": {phase: round(seconds, 3) for phase, seconds in phases.items()},
        "estimated_time_s": round(fsum(phases.values()), 3),
        "message_count": plan.message_count,
        "axis_releases": [f"{m.bus}/{m.name}" for m in plan.axis_releases],
        "evidence": evidence(plan),
    }
    if plan.unshared_bus_time is not None:
        document["without_broadcasts_bus_time_s"] = round(plan.unshared_bus_time, 4)
    if plan.reading is not None:
        document["read"] = _reading_json(plan.reading)
    return document


def write(plan: PlantPlan, notes: Iterable[str], words: Words) -> dict[str, Any]:
    """The plan file `plan --out` writes (and `plan --json` prints): the plan's data, what stays on the
    hardware (`notes`, as `left_alone`), and beside each module's steps what people review (`words`), with
    its digest (`review_sha256`)."""
    document = to_json(plan) | {"left_alone": list(notes)}
    for bus in document["buses"]:
        for entry, change in zip(bus["modules"], plan.buses()[bus["name"]]):
            entry.update(words.review(change))
            entry[REVIEW] = review_sha256(entry)
    return document


def _module_json(change: ModuleChange, hashes: bool) -> dict[str, Any]:
    return {
        "address": change.address,
        "name": change.name,
        "state_sha256": image_sha256(change.actual) if hashes else None,
        "releases_axes": change.releases_axes,
        "estimated_bus_time_s": round(change.plan.bus_time, 4),
        "steps": [
            {"message": step.message.hex(), "summary": step.summary, "releases_axes": step.releases_axes}
            | ({"broadcast": True} if index < change.broadcasts else {})
            for index, step in enumerate(change.steps)
        ],
    }


def _proof_json(proof: LineProof) -> dict[str, Any]:
    return ({"proven_silent": list(proof.silent)} if proof.silent else {}) | (
        {"unlisted_modules": list(proof.answered)} if proof.answered else {})


def evidence(plan: PlantPlan) -> dict[str, Any]:
    """What the plan's word rests on, as its headline says it: what was read now (each module's system block,
    and the programs read), what was taken from the line's record instead (programs, of how many modules) and
    the oldest of that (the module, since when, by whom) — and, an apply's, what it planned from the factory's
    programs without reading them (`from_factory`, only where it did: `what_to_read.assumed`); `complete` —
    every value the plan covers read in this run — is what "every module matches the plant file" needs."""
    not_read = {} if plan.reading is None else plan.reading.programs_not_read
    oldest = None if plan.reading is None else plan.reading.oldest
    taken = [programs for programs in not_read.values() if programs]
    assumed = [m.assumed for m in plan.modules if m.assumed]
    return {
        "complete": not taken and not assumed
            and not (plan.reading is not None and plan.reading.modules_not_read),
        "read_now": {"system_blocks": len(plan.modules),
                     "programs": sum(len(m.programs_read) for m in plan.modules)},
        "from_record": {"modules": len(taken), "programs": sum(map(len, taken))},
        "oldest": None if oldest is None
            else {"module": oldest.module, "since": oldest.since, "by": oldest.by},
    } | ({"from_factory": {"modules": len(assumed), "programs": sum(map(len, assumed))}} if assumed else {})


def _reading_json(reading: Reading) -> dict[str, Any]:
    return {"base": reading.base, "modules_not_read": list(reading.modules_not_read),
            "not_as_verified": list(reading.not_as_verified),
            "taken": dict(reading.taken)}


def _module_read(reading: Reading, change: ModuleChange) -> dict[str, Any]:
    return {"programs": list(change.programs_read),
            "programs_not_read": list(reading.programs_not_read.get((change.bus, change.address), ()))}


# -- reading ---------------------------------------------------------------------------------


class StalePlan(UserError):
    """A plan file made from another plant file, another read-back, or another prc3cfg."""


@dataclass(frozen=True, slots=True)
class PlannedModule:
    """A module's entry of a plan file, as `apply --plan` reads it back (not yet proved:
    `prc3cfg.core.planner.plan_from_steps` runs the steps on the device model from the read-back)."""

    bus: str
    address: int
    name: str
    state_sha256: str
    steps: tuple[codec.Message, ...]
    broadcasts: int  # how many of the leading steps are the bus's broadcasts
    programs_read: tuple[int, ...] | None = None  # a targeted plan's: exactly what to read again
    # its review's digest (`Review`): none in plan files made before it had one
    review_sha256: str | None = None


class PlanFileError(ValueError):
    """A plan file prc3cfg cannot take: `str()` says where and what, in words, and what to do."""


#: What to do about a damaged or edited plan file.
AGAIN = "make the plan again with prc3cfg plan --out"


class _Step(BaseModel):
    model_config = LATER

    message: Text
    releases_axes: Flag
    broadcast: Flag = False


class _ModuleRead(BaseModel):
    """A targeted plan's read-back of a module: the programs read, the managed ones taken as last verified."""

    model_config = LATER

    programs: list[Whole]
    programs_not_read: list[Whole]


class _ModuleEntry(BaseModel):
    model_config = LATER

    address: Whole
    name: Text
    state_sha256: Text
    releases_axes: Flag
    steps: list[_Step]
    read: _ModuleRead | None = None
    # none in plan files made before the review had a digest: `show` says so
    review_sha256: Text | None = None


class _Bus(BaseModel):
    model_config = LATER

    name: Text
    modules: list[_ModuleEntry]


class PlanRead(BaseModel):
    """A targeted plan's `read`, as the plan file says it (parsed here only, by `read`): the base it compared
    with, in words, the modules not read, those read in full and why, and whose verification the programs not
    read rest on."""

    model_config = LATER

    base: Text
    modules_not_read: list[Text]
    not_as_verified: list[Text]
    taken: dict[str, Text] = Field(default_factory=dict)  # none in plan files before the line's record


class PlanDocument(BaseModel):
    model_config = LATER

    """The plan file, as `apply --plan` reads it. The rest of it — the figures, held against what prc3cfg
    writes for the plan it proves; the review, against its digest (`check_plan`) — as any JSON."""

    plant: Text
    plant_path: Text
    plant_sha256: Text
    prc3cfg_version: Text = "before 0.1.0"
    buses: list[_Bus]
    read: PlanRead | None = None
    left_alone: list[Text]


# ... and as `show` reads it, to show it: the review beside the steps (`render.changes_json`), the
# figures, each bus's broadcasts. A key with a default may be left out (the default is never
# read: what is shown is the document), never null.
class _Field(BaseModel):
    model_config = LATER

    program: Whole | None
    field: Text
    text: Text


class _Clamped(BaseModel):
    model_config = LATER

    program: Whole
    text: Text


class _Changes(BaseModel):
    model_config = LATER

    fields: list[_Field]
    symbols: dict[str, Any] = Field(default_factory=dict)
    chains_removed: list[Text]
    chains_added: list[Text]
    clamped: list[_Clamped]
    charts: list[Text] = Field(default_factory=list)


class _ShownModule(_ModuleEntry):
    estimated_bus_time_s: Number = 0.0
    changes: _Changes


class _Broadcast(BaseModel):
    model_config = LATER

    message: Text
    releases_axes: Flag
    modules: list[Whole]


class _ShownBus(_Bus):
    broadcasts: list[_Broadcast] = Field(default_factory=list)
    proven_silent: list[Whole] = Field(default_factory=list)
    unlisted_modules: list[Whole] = Field(default_factory=list)
    modules: list[_ShownModule]  # type: ignore[assignment]  # a module as shown is a module


class _Phases(BaseModel):
    model_config = LATER

    reading: Number
    writing: Number
    verifying: Number


class _Oldest(BaseModel):
    model_config = LATER

    module: Text
    since: Text
    by: Text


class _Counted(BaseModel):
    model_config = LATER

    modules: Whole = 0
    programs: Whole
    system_blocks: Whole = 0


class _Evidence(BaseModel):
    model_config = LATER

    complete: Flag
    read_now: _Counted
    from_record: _Counted
    oldest: _Oldest | None


class ShownPlanDocument(PlanDocument):
    buses: list[_ShownBus]  # type: ignore[assignment]  # a bus as shown is a bus
    axis_releases: list[Text]
    message_count: Whole
    estimated_bus_time_s: Number
    naive_bus_time_s: Number
    left_alone: list[Text] = Field(default_factory=list)
    estimated_time_s: Number = 0.0
    estimated_phases_s: _Phases = Field(
        default_factory=lambda: _Phases(reading=0.0, writing=0.0, verifying=0.0))
    evidence: _Evidence | None = None  # none in plan files before issue 41: their headline says nothing of it


@dataclass(frozen=True, slots=True)
class PlanFile:
    """A plan file as read: what it was made from, by which prc3cfg, and its modules."""

    plant: str
    plant_path: str
    plant_sha256: str
    version: str
    modules: tuple[PlannedModule, ...]
    # as read: `apply --plan` holds it against what prc3cfg writes for the plan it proves
    document: dict[str, Any]
    read: PlanRead | None  # a targeted plan's `read`, parsed

    @property
    def targeted(self) -> bool:
        """Made from a targeted read-back (it has a `read`): read exactly what its plan read."""
        return self.read is not None


def parse(data: Any, *, for_show: bool = False) -> PlanFile:
    """A parsed plan file; raises PlanFileError.

    Refused here, before the line is touched: a file beyond any plan file prc3cfg writes
    (`within_bounds`), a damaged file — a key missing, a value of another kind (`PlanDocument`;
    with `for_show`, all that `show` shows, `ShownPlanDocument`) — a base other than `RECORD`, a
    module listed twice, more steps than any plan needs (`MAX_STEPS`), a message that is not
    in the bytes prc3cfg sends for it (a "don't care" byte changed), and `releases_axes` flags
    that are not what the steps' bytes say.
    """
    within_bounds(data)
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise PlanFileError(f'not a plan file — expected "format": "{FORMAT}"')
    try:
        contract = ShownPlanDocument if for_show else PlanDocument
        document = contract.model_validate(data)
    except ValidationError as error:
        raise PlanFileError("damaged plan file: "
                            f"{said(error, lambda loc: json_path(loc, 'the plan'), contract)} "
                            f"— {AGAIN}") from None
    if document.read is not None and document.read.base != RECORD:
        raise PlanFileError(f"read.base is not {json.dumps(RECORD)}, the only base prc3cfg compares a "
                            "read-back with — the plan "
                            f"file was changed after it was made: {AGAIN}")
    modules = []
    seen: set[tuple[str, int]] = set()
    for b, bus in enumerate(document.buses):
        for m, module in enumerate(bus.modules):
            entry = _planned_module(bus.name, module, f"buses[{b}].modules[{m}]")
            targeted = document.read is not None
            if targeted != (entry.programs_read is not None):
                raise PlanFileError(f"damaged plan file: buses[{b}].modules[{m}] "
                                    f"{'lacks' if targeted else 'has'} the \"read\" "
                                    f"of a plan made from a {'targeted' if targeted else 'full'} read-back "
                                    f"— {AGAIN}")
            if (entry.bus, entry.address) in seen:
                raise PlanFileError(f"bus {shown(entry.bus)}, module {entry.address} is listed twice "
                                    f"— {AGAIN}")
            seen.add((entry.bus, entry.address))
            modules.append(entry)
        if isinstance(bus, _ShownBus):
            for index, step in enumerate(bus.broadcasts):
                _message(step.message, f"buses[{b}].broadcasts[{index}]",
                         f"bus {bus.name}: broadcast {index + 1}")
    return PlanFile(document.plant, document.plant_path, document.plant_sha256, document.prc3cfg_version,
                    tuple(modules), data,
                    document.read)


def within_bounds(data: Any) -> None:
    """Refused (`PlanFileError`, naming the place) unless `data` nests at most `MAX_DEPTH` deep, holds no
    text or key longer than `MAX_TEXT` and no list or object of more than `MAX_ITEMS`: what no plan
    file prc3cfg writes does, and what would cost rendering and checking it a recursion without end, or
    the reader a screen of one name. Walked without recursion, each value once."""
    stack: list[tuple[Any, int, tuple[Any, ...]]] = [(data, 1, ())]
    while stack:
        value, depth, at = stack.pop()
        if isinstance(value, str):
            if len(value) > MAX_TEXT:
                raise PlanFileError(f"{_place(at)} is a text of {len(value):,} characters, longer than any "
                                    "prc3cfg writes in a plan "
                                    f"file ({MAX_TEXT:,}) — {AGAIN}")
            continue
        if not isinstance(value, dict | list):
            continue
        if depth > MAX_DEPTH:
            raise PlanFileError(f"{_place(at)} is nested deeper than {MAX_DEPTH} levels, which no plan file "
                                f"prc3cfg writes is — {AGAIN}")
        if len(value) > MAX_ITEMS:
            kind = "an object of" if isinstance(value, dict) else "a list of"
            raise PlanFileError(f"{_place(at)} is {kind} {len(value):,} "
                                f"{'keys' if isinstance(value, dict) else 'items'}, more than "
                                f"any plan file prc3cfg writes holds ({MAX_ITEMS:,}) — {AGAIN}")
        if isinstance(value, dict):
            for key, item in value.items():
                if len(key) > MAX_TEXT:
                    raise PlanFileError(f"{_place(at)} has a key of {len(key):,} characters, longer than "
                                        "any prc3cfg writes in a plan "
                                        f"file ({MAX_TEXT:,}) — {AGAIN}")
                stack.append((item, depth + 1, (at, key)))
        else:
            stack.extend((item, depth + 1, (at, index)) for index, item in enumerate(value))


def _place(at: tuple[Any, ...]) -> str:
    """The JSON path of a place `within_bounds` walked to ((((), "buses"), 0), "name") → "buses[0].name"),
    each key cut to 40 characters: a path is said in one line."""
    loc: list[str | int] = []
    while at:
        at, key = at
        loc.append(key if isinstance(key, int) or len(key) <= 40 else f"{key[:40]}…")
    return json_path(loc[::-1], "the plan")


def _planned_module(bus: str, module: _ModuleEntry, at: str) -> PlannedModule:
    """A module's entry, at `at` ("buses[0].modules[2]")."""
    where = f"bus {shown(bus)}, module {module.address}"
    if len(module.steps) > MAX_STEPS:
        raise PlanFileError(f"{where}: {len(module.steps)} steps, more than any plan of one module needs "
                            f"({MAX_STEPS}) — {AGAIN}")
    messages, flags = [], []
    for index, step in enumerate(module.steps, start=1):
        flags.append(step.broadcast)
        if flags[-1] and not all(flags):
            raise PlanFileError(f"{where}: step {index} ({step.message[:128]}) is marked broadcast after a "
                                "step that is not — "
                                f"broadcasts lead a module's steps: {AGAIN}")
        message = _message(step.message, f"{at}.steps[{index - 1}]", f"{where}: step {index}")
        if step.releases_axes is not message.RELEASES_AXES:
            raise PlanFileError(
                f"{where}: step {index} ({step.message}) says releases_axes: "
                f"{json.dumps(step.releases_axes)}, "
                f"but {message.ID:02X}h {'releases' if message.RELEASES_AXES else 'does not release'} the "
                f"axes — {AGAIN}"
            )
        messages.append(message)
    if module.releases_axes is not any(m.RELEASES_AXES for m in messages):
        raise PlanFileError(f"{where}: releases_axes: {json.dumps(module.releases_axes)} is not what its "
                            f"steps do — {AGAIN}")
    read = None
    if module.read is not None:
        read = tuple(module.read.programs)
        if list(read) != sorted(set(read)) or not all(1 <= n <= PROGRAM_COUNT for n in read):
            raise PlanFileError(f"damaged plan file: {at}.read.programs is not a list of program numbers "
                                f"1..{PROGRAM_COUNT}, "
                                f"each once, in order — {AGAIN}")
    return PlannedModule(bus, module.address, module.name, module.state_sha256, tuple(messages), sum(flags),
                         read, module.review_sha256)


def _message(text: str, at: str, where: str) -> codec.Message:
    """The message a step's `message` (at `at`) writes in hex, exactly as prc3cfg writes it."""
    try:
        data = bytes.fromhex(text)
    except ValueError:
        raise PlanFileError(f"damaged plan file: {at}.message is not a PRC 3 message in hex "
                            f"— {AGAIN}") from None
    try:
        message = codec.decode_message(data)
    except codec.Rejected as rejected:
        raise PlanFileError(f"{where} ({text[:64]}) is not a message prc3cfg sends: a module would "
                            "answer it with "
                            f"{describe(rejected.code)} — {AGAIN}") from None
    if message.hex() != text:  # "don't care" bytes that are not 00h, upper-case digits
        raise PlanFileError(f"{where} ({text}) is not written as prc3cfg writes that message "
                            f"({message.hex()}) — {AGAIN}")
    return message


def same_text(data: bytes) -> frozenset[str]:
    """The SHA-256 of a plant file's bytes `data` with its line endings as LF, and as CRLF: the digests
    of the same text in a Linux and in a Windows checkout (Git for Windows converts them)."""
    text = data.replace(b"\r\n", b"\n")
    return frozenset(hashlib.sha256(form).hexdigest() for form in (text, text.replace(b"\n", b"\r\n")))


def checked(document: Any, path: Path, *, for_show: bool = False) -> PlanFile:
    """The plan file at `path` (its JSON loaded), `parse`d; else a `UserError` of one line naming `path`."""
    try:
        return parse(document, for_show=for_show)
    except PlanFileError as error:
        raise UserError(f"{path}: {error}") from None


def to_apply(document: Any, path: Path, plant_path: Path, plant_sha256: str,
             alike: frozenset[str] = frozenset(),
             plant_name: str | None = None) -> PlanFile:
    """The plan file at `path` (as parsed) for `apply --plan` of the plant file at `plant_path` (its plant
    `plant_name`): refused (one line) when damaged, made by another prc3cfg, of another plant or for another
    version of this plant file (`StalePlan`). A plan made from the same text with other line endings (`alike`,
    of `same_text`) is the plan of this plant file: a plan made on Linux applies from a Windows checkout, and
    the other way round."""
    plan_file = checked(document, path)
    if plan_file.version != __version__:
        raise StalePlan(f"{path}: made by prc3cfg {shown(plan_file.version)}, this is {__version__} — plan "
                        "again with this version")
    if plant_name is not None and plan_file.plant != plant_name:
        raise UserError(f"{path}: the plan of plant {shown(plan_file.plant)} "
                        f"({shown(plan_file.plant_path)}), not of {plant_name} "
                        f"({plant_path}) — nothing was written: apply it with its own plant file, or "
                        "plan this one")
    if plan_file.plant_sha256 != plant_sha256 and plan_file.plant_sha256 not in alike:
        raise StalePlan(f"{path}: stale plan — the plant file {plant_path} changed since the plan was made; "
                        "plan again")
    return plan_file


def to_show(document: Any, path: Path) -> dict[str, Any]:
    """The plan file at `path` (as parsed) to show (`prc3cfg show PLAN.json`): checked as `apply
    --plan` checks it before the line (damaged, edited flags, a module twice, not prc3cfg's bytes:
    one line), each module's `review` said (`Review`: whether its review text is the one its digest was
    written for — `show` marks any other as the file's words), and every step's summary worked out again
    from its bytes — what is shown is what would be sent."""
    plan_file = checked(document, path, for_show=True)
    entries = iter(plan_file.modules)  # in the file's order
    for bus in plan_file.document["buses"]:
        for module, entry in zip(bus["modules"], entries):
            # before the summaries are made again: they are part of the text
            module["review"] = Review.of(module)
            # the words of a 20h
            said = module["changes"]["fields"] if module["review"] is Review.AS_WRITTEN else []
            system_keys = [f["field"] for f in said if f["program"] is None]
            for step, message in zip(module["steps"], entry.steps):
                step["summary"] = _summary(message, system_keys)
        for broadcast in bus.get("broadcasts", []):
            broadcast["summary"] = _summary(codec.decode_message(bytes.fromhex(broadcast["message"])), [])
    return plan_file.document


def _summary(message: codec.Message, system_keys: list[str]) -> str:
    """A step's summary from its bytes (a 20h names the system parameters the plan says it changes)."""
    if isinstance(message, codec.WriteSystem):
        return f"write system parameters {', '.join(system_keys) or '(all)'} (20h)"
    return summarise(message, DEFAULT_SYSTEM)


# -- proving ---------------------------------------------------------------------------------


def check_modules(path: Path, plan_file: PlanFile, names: dict[Key, str],
                  images: dict[Key, ModuleImage]) -> None:
    """The first part of the proof of a plan file (`check_plan` is the rest), before prc3cfg plans
    from the read-back `images`: refused when a module is not among those to apply (`names`, in the
    plant file's order) or is called otherwise, when a module changed since the plan was made
    (`StalePlan`), and when the modules are not listed in the plant file's order."""
    for entry in plan_file.modules:
        where = f"bus {shown(entry.bus)}, module {entry.address}"  # a name the plant may not have: escaped
        if (entry.bus, entry.address) not in names:
            raise UserError(f"{path}: {where} is not among the modules to apply — plan again")
        name = names[(entry.bus, entry.address)]
        if entry.name != name:
            raise UserError(f"{path}: {where} is called {entry.name!r} in the plan but {name!r} in the "
                            "plant file — plan again")
        if image_sha256(images[(entry.bus, entry.address)]) != entry.state_sha256:
            raise StalePlan(
                f"{path}: stale plan — {where} ({entry.name}) changed since the plan was made "
                "(teach-in or another apply?); nothing was written — plan again"
            )
    _in_plant_order(path, plan_file, list(names))


def check_plan(path: Path, plan_file: PlanFile, ours: PlantPlan, costs: dict[str, LineCost]) -> None:
    """The plan file proved against `ours`, the plan prc3cfg makes of its modules from the read-back
    now (each line priced by `costs`): by its steps and figures, never by the words people read.

    Refused when its steps do anything but turn a module's read-back into the plant file's image
    (`plan_from_steps` names the rule they break); and when they are not exactly the steps —
    broadcasts included — of `ours`: the plant file and the read-back are the same as when the
    file was made (`check_modules`), so any difference is an edit. Refused when a module's review text
    (its `changes`, `warning`, steps' `summary`) is not the text its `review_sha256` was written for — the
    reviewer approved that text — and, without a digest, as made by an older prc3cfg. A text its digest
    matches is taken as the file's words, however prc3cfg would word that review now: a new prc3cfg may
    word it otherwise. A targeted plan's `read` (as `read` parsed it) is what the apply read and the line's
    record says now (`ours`'s reading), said apart — the record may have changed since, as well as the
    file — but for its `not_as_verified`, the file's words (the module docstring says why). Then every
    other value — a figure, a name, a hash, a flag, a key — that is not the value `to_json` writes for that
    plan is an edit too (only `plant_path` and `plant_sha256` may differ: a plan made in another checkout,
    whose line endings `to_apply` checked; and `left_alone`, what the plan's maker compared with: words
    only, which send nothing). Values, not their spelling (`_differs_at`): a file another tool wrote again —
    indented otherwise, its keys in another order, CRLF, a byte-order mark, 0 for 0.0 — is the same plan
    file. Its figures come out the same on every system and Python: the times are summed with
    `math.fsum`, correctly rounded (`sum` of floats is compensated from Python 3.12 on, plain addition
    before: a plan made by 3.11 on Linux showed 1.0988 s where 3.13 on Windows proved 1.0987 s).
    """
    document = plan_file.document
    # a plan file from before issue 41, or one whose claim was cut out: `show` shows it
    if "evidence" not in document:
        raise UserError(f"{path}: it does not say what its plan rests on (no \"evidence\"): made before "
                        "plans named their evidence, "
                        "or changed after it was made; nothing was written: plan again and review it")
    if any(entry.review_sha256 is None for entry in plan_file.modules):
        raise StalePlan(f"{path}: made by an older prc3cfg — its review text has no digest (review_sha256), "
                        "so what was reviewed "
                        "cannot be told from an edit; nothing was written — plan again")
    _no_new_module_hears(path, plan_file, ours)
    for entry, change in zip(plan_file.modules, ours.modules):
        edited = (f"{path}: bus {entry.bus}, module {entry.address} ({entry.name}): {{}} — the plan file "
                  "was changed "
                  "after it was made; nothing was written: plan again and review it")
        theirs, steps = list(entry.steps), [step.message for step in change.steps]
        try:
            plan_from_steps(change.actual, change.desired, theirs, costs[entry.bus],
                            system_unset=change.system_unset)
        except StepProblem as problem:
            if problem.index:  # the step that breaks a rule
                raise UserError(edited.format(problem)) from None
            raise UserError(edited.format(f"{_first_difference(theirs, steps)}, and {problem}")) from None
        if theirs != steps:
            raise UserError(edited.format(_first_difference(theirs, steps)))
        if entry.broadcasts != change.broadcasts:
            raise UserError(edited.format(f"{entry.broadcasts} of its steps are marked broadcast, where the "
                                          f"plan has {change.broadcasts}"))
    for b, bus in enumerate(document["buses"]):
        for m, module in enumerate(bus["modules"]):
            if Review.of(module) is not Review.AS_WRITTEN:
                raise UserError(f"{path}: buses[{b}].modules[{m}].{REVIEW} (bus {shown(bus['name'])}, "
                                f"module {module['address']}) is not "
                                "the digest of the review text beside it (changes, warning, the steps' "
                                "summaries): the text was changed "
                                "after the plan was made; nothing was written: plan again and review it")
    expected = _their_words(to_json(ours), plan_file)
    if plan_file.read is not None and "read" in expected:
        expected["read"]["not_as_verified"] = list(plan_file.read.not_as_verified)
        if (at := _differs_at(plan_file.read.model_dump(), expected["read"], "read")) is not None:
            raise UserError(f"{path}: {at} is not what this apply read and the line's record says — the "
                            "plan file, or the record, was "
                            "changed after the plan was made; nothing was written: plan again and review it")
    if (at := _differs_at(document, expected)) is not None:
        raise UserError(f"{path}: {at or 'its list of keys'} is not what prc3cfg wrote for this plan — the "
                        "plan file was changed after it was "
                        "made; nothing was written: plan again and review it")


#: The words of a module entry, its review (`Review`): the file's, held to their digest, not to the words of
#: today's prc3cfg.
_REVIEW_KEYS = ("changes", "warning", REVIEW)
#: What a word the file lacks is expected as: a value of no JSON document.
_ABSENT = object()


def _their_words(expected: dict[str, Any], plan_file: PlanFile) -> dict[str, Any]:
    """`expected`, the data of the plan proved (`to_json`), with the plan file's words where the file has
    them — each module's review and its steps' summaries (held to the review's digest), each broadcast's
    summary as the first module receiving it says it, `left_alone`, where the plant file was — so that
    what is left to compare is the steps, the figures, the names and the keys. A word the file lacks is
    left as prc3cfg writes it: its list of keys then differs."""
    document = plan_file.document
    expected |= {"left_alone": document["left_alone"], "plant_path": plan_file.plant_path,
                 "plant_sha256": plan_file.plant_sha256}
    for bus, their_bus in zip(expected["buses"], document["buses"]):
        for module, theirs in zip(bus["modules"], their_bus["modules"]):
            module |= {key: theirs.get(key, _ABSENT) for key in _REVIEW_KEYS}  # absent: the keys differ
            for step, their_step in zip(module["steps"], theirs["steps"]):
                step["summary"] = their_step.get("summary", step["summary"])
        for index, broadcast in enumerate(bus.get("broadcasts", [])):
            said = [m["steps"][index] for m in their_bus["modules"] if len(m["steps"]) > index
                    and m["steps"][index].get("broadcast")]
            broadcast["summary"] = (said[0].get("summary", broadcast["summary"]) if said
                                    else broadcast["summary"])
    return expected


def _no_new_module_hears(path: Path, plan_file: PlanFile, ours: PlantPlan) -> None:
    """Refused where a module the plant file does not list now answers on a bus the plan file broadcasts
    on."""
    for proof in ours.proofs:
        if proof.answered and any(entry.bus == proof.bus and entry.broadcasts for entry in plan_file.modules):
            raise StalePlan(f"{path}: stale plan — on bus {proof.bus} a module now answers at "
                            f"{address_ranges(proof.answered)}, which the "
                            "plant file does not list: its broadcasts would reach it; nothing was written — "
                            "plan again")


def _in_plant_order(path: Path, plan_file: PlanFile, order: list[Key]) -> None:
    """Refused unless the plan file lists its modules in the plant file's order, as prc3cfg writes
    them: they are written in the order listed."""
    place = {key: index for index, key in enumerate(order)}
    entries = plan_file.modules
    for first, then in itertools.pairwise(entries):
        if place[(then.bus, then.address)] < place[(first.bus, first.address)]:
            raise UserError(f"{path}: bus {first.bus}, module {first.address} ({first.name}) is listed "
                            f"before bus {then.bus}, "
                            f"module {then.address} ({then.name}), where prc3cfg writes the modules in the "
                            "plant file's "
                            "order — the plan file was changed after it was made; nothing was written: plan "
                            "again and review it")


def _differs_at(theirs: object, ours: object, at: str = "") -> str | None:
    """Where the values of a plan file (`theirs`, as parsed) differ from those of the file prc3cfg
    writes for the plan proved — its texts and figures, which reach no module but a reviewer — as a
    JSON path ("" for the list of keys at the top); None where they are the same values.

    Compared as data, not as text: an object's keys in any order, and a figure prc3cfg writes as a
    float the same figure written without its ".0" (JavaScript's `JSON.stringify` and jq 1.6 write
    0.0 as 0); whitespace, line endings, a byte-order mark and escapes are gone once parsed. A text, a
    flag, a count or a null is the value prc3cfg writes or another: `true` is no 1, 2.0 no count."""
    if isinstance(theirs, dict) and isinstance(ours, dict) and theirs.keys() == ours.keys():
        return next((f for k in ours
                     if (f := _differs_at(theirs[k], ours[k], f"{at}.{k}".lstrip("."))) is not None), None)
    if isinstance(theirs, list) and isinstance(ours, list) and len(theirs) == len(ours):
        return next((f for i, (a, b) in enumerate(zip(theirs, ours))
                     if (f := _differs_at(a, b, f"{at}[{i}]")) is not None), None)
    same_kind = type(theirs) is type(ours) or (type(ours) is float and type(theirs) is int)
    return None if same_kind and theirs == ours else at


def _first_difference(theirs: list[codec.Message], ours: list[codec.Message]) -> str:
    """Where a plan file's steps part from the plan made from the same read-back."""
    index = next(i for i, (a, b) in enumerate(zip([*theirs, None], [*ours, None]), 1) if a != b)
    said = theirs[index - 1].hex() if index <= len(theirs) else "missing"
    planned = ours[index - 1].hex() if index <= len(ours) else "nothing"
    return f"step {index} is {said}, where the plan made from this read-back has {planned}"
