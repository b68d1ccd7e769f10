"""A plan for a whole plant, and the plan file `prc3cfg-plan/1` (interfaces.md §4).

A plan is data: per bus, per module, the steps to send (the PRC 3 message, exactly as it
goes on the line), what they were planned from (the plant file's hash and each module's
read-back hash, so a stale plan can be refused) and what they are predicted to do. The
optimiser that makes a module's steps is `prc3cfg.core.planner`; rendering is `prc3cfg.core.render`.

A bus may start with broadcasts (`prc3cfg.core.sharing`): steps sent once to address 0 that
every module of the line processes. In the plan file they are the leading steps of every
module of that bus, marked `"broadcast": true` — so each module's steps still say, in
order, everything that reaches it (a reader that sent them addressed would do the same,
only slower) — and the bus lists them once under `"broadcasts"`. Pure.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from prc3cfg import __version__
from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.error_codes import describe
from prc3cfg.core.image import PROGRAM_COUNT, ModuleImage
from prc3cfg.core.planner import ModulePlan, Step
from prc3cfg.core.planner.check import MAX_STEPS
from prc3cfg.core.verification import read_messages, verification_time

FORMAT = "prc3cfg-plan/1"


def image_sha256(image: ModuleImage) -> str:
    """The hash of a read-back, over its canonical JSON."""
    text = json.dumps(image.to_json(), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True, slots=True)
class ModuleChange:
    """One module of a plant plan: where it is, what it holds, what it should hold, the steps.

    The first `broadcasts` steps are its bus's broadcasts; `plan.bus_time` counts its own steps only.
    `cost` prices its line's exchanges: what reading it back and verifying it take."""

    bus: str
    name: str
    actual: ModuleImage
    desired: ModuleImage
    plan: ModulePlan
    broadcasts: int = 0
    system_unset: bool = False  # the module reported E12: its plan writes the system parameters first
    cost: LineCost | None = None

    @property
    def reading_time(self) -> float:
        """Seconds the read-back it was planned from took on the line: a 50h and the fewest 51h/52h."""
        read = [n for n, program in enumerate(self.actual.programs, 1) if program is not None]
        return 0.0 if self.cost is None else sum(self.cost.message_time(self.address, m) for m in read_messages(read))

    @property
    def verifying_time(self) -> float:
        """Seconds the verifying read-back takes on the line (`Verify.FLOOR`: what the steps can change)."""
        return 0.0 if self.cost is None else verification_time(self.actual, self.plan.predicted, self.steps, self.cost)

    @property
    def address(self) -> int:
        return self.plan.address

    @property
    def steps(self) -> tuple[Step, ...]:
        return self.plan.steps

    @property
    def releases_axes(self) -> bool:
        return self.plan.releases_axes

    def to_json(self) -> dict[str, Any]:
        return {
            "address": self.address,
            "name": self.name,
            "state_sha256": image_sha256(self.actual),
            "releases_axes": self.releases_axes,
            "estimated_bus_time_s": round(self.plan.bus_time, 4),
            "steps": [
                {"message": step.message.hex(), "summary": step.summary, "releases_axes": step.releases_axes}
                | ({"broadcast": True} if index < self.broadcasts else {})
                for index, step in enumerate(self.steps)
            ],
        }


@dataclass(frozen=True, slots=True)
class LineProof:
    """What a line's probes found at the addresses its plant file does not list (before a broadcast):
    `silent` — none answered, the broadcasts reach only the plan's modules; `answered` — modules the
    plant file does not know are on the line, so it gets no broadcast."""

    bus: str
    silent: tuple[int, ...] = ()
    answered: tuple[int, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return ({"proven_silent": list(self.silent)} if self.silent else {}) | (
            {"unlisted_modules": list(self.answered)} if self.answered else {})


@dataclass(frozen=True, slots=True)
class Reading:
    """How a plan's read-back was targeted (`prc3cfg.core.targeting`): the base it was compared with,
    in words, the modules not read at all, and per module read the managed programs not read — all
    taken as last verified. A plan without one read every chosen module in full."""

    base: str
    modules_not_read: tuple[str, ...]  # "bus/name"
    programs_not_read: dict[tuple[str, int], tuple[int, ...]]

    def to_json(self) -> dict[str, Any]:
        return {"base": self.base, "modules_not_read": list(self.modules_not_read)}

    def module_json(self, change: ModuleChange) -> dict[str, Any]:
        read = [n for n, program in enumerate(change.actual.programs, 1) if program is not None]
        return {"programs": read, "programs_not_read": list(self.programs_not_read.get((change.bus, change.address), ()))}


@dataclass(frozen=True, slots=True)
class PlantPlan:
    """Every module's change, the broadcasts of each bus, and what they cost on the line."""

    plant: str
    plant_path: str
    plant_sha256: str
    modules: tuple[ModuleChange, ...]
    broadcast_time: float = 0.0  # every bus's broadcasts, once each, and the probes that proved them safe
    unshared_bus_time: float | None = None  # the same changes without broadcasts, where some were shared
    proofs: tuple[LineProof, ...] = ()  # per line probed: what answered at the addresses the plant does not list
    reading: Reading | None = None  # a targeted read-back: what was read, what was taken as last verified

    def proof(self, bus: str) -> LineProof | None:
        return next((p for p in self.proofs if p.bus == bus), None)

    @property
    def changes(self) -> tuple[ModuleChange, ...]:
        return tuple(m for m in self.modules if m.steps)

    @property
    def bus_time(self) -> float:
        return sum(m.plan.bus_time for m in self.modules) + self.broadcast_time

    def phases(self) -> dict[str, float]:
        """The time the operator waits for an apply of this plan, by phase — reading back, writing,
        verifying — each the longest of its lines' (the lines run at once, each line's modules one
        after another), by the bus-time model. Writing counts each line's broadcasts once; the
        probes that proved them are not counted."""
        lines = self.buses()

        def longest(seconds: Callable[[str, list[ModuleChange]], float]) -> float:
            return max((seconds(bus, modules) for bus, modules in lines.items()), default=0.0)

        def writing(bus: str, modules: list[ModuleChange]) -> float:
            cost = modules[0].cost
            shared = sum(cost.broadcast_time(step.message) for step in self.broadcasts(bus)) if cost is not None else 0.0
            return sum(m.plan.bus_time for m in modules) + shared

        return {
            "reading": longest(lambda _, modules: sum(m.reading_time for m in modules)),
            "writing": longest(writing),
            "verifying": longest(lambda _, modules: sum(m.verifying_time for m in modules)),
        }

    def broadcasts(self, bus: str) -> tuple[Step, ...]:
        """The steps sent once to address 0 on `bus`, before any module's own steps."""
        return next((m.steps[: m.broadcasts] for m in self.modules if m.bus == bus and m.broadcasts), ())

    @property
    def naive_bus_time(self) -> float:
        return sum(m.plan.naive_bus_time for m in self.modules)

    @property
    def message_count(self) -> int:
        """Messages on the lines: every module's own steps, and each broadcast once."""
        return sum(len(m.steps) - m.broadcasts for m in self.modules) + sum(len(self.broadcasts(b)) for b in self.buses())

    @property
    def axis_releases(self) -> tuple[ModuleChange, ...]:
        return tuple(m for m in self.modules if m.releases_axes)

    def buses(self) -> dict[str, list[ModuleChange]]:
        grouped: dict[str, list[ModuleChange]] = {}
        for module in self.modules:
            grouped.setdefault(module.bus, []).append(module)
        return grouped

    def to_json(self) -> dict[str, Any]:
        phases = self.phases()
        return {
            "format": FORMAT,
            "prc3cfg_version": __version__,
            "plant": self.plant,
            "plant_path": self.plant_path,
            "plant_sha256": self.plant_sha256,
            "buses": [
                {"name": bus, "modules": [m.to_json() | ({"read": self.reading.module_json(m)} if self.reading else {}) for m in modules]}
                | (proof.to_json() if (proof := self.proof(bus)) is not None else {})
                | ({"broadcasts": [
                    {"message": step.message.hex(), "summary": step.summary, "releases_axes": step.releases_axes,
                     "modules": [m.address for m in modules if m.broadcasts]}
                    for step in self.broadcasts(bus)
                ]} if self.broadcasts(bus) else {})
                for bus, modules in self.buses().items()
            ],
            "estimated_bus_time_s": round(self.bus_time, 4),
            "naive_bus_time_s": round(self.naive_bus_time, 4),
            "estimated_phases_s": {phase: round(seconds, 3) for phase, seconds in phases.items()},
            "estimated_time_s": round(sum(phases.values()), 3),
            "message_count": self.message_count,
            "axis_releases": [f"{m.bus}/{m.name}" for m in self.axis_releases],
        } | ({"without_broadcasts_bus_time_s": round(self.unshared_bus_time, 4)} if self.unshared_bus_time is not None else {}) | (
            {"read": self.reading.to_json()} if self.reading is not None else {})  # fmt: skip


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


class PlanFileError(ValueError):
    """A plan file prc3cfg cannot take: `str()` says where and what, in words, and what to do."""


#: What to do about a damaged or edited plan file.
AGAIN = "make the plan again with prc3cfg plan --out"


@dataclass(frozen=True)
class Kind:
    """A JSON value a plan file holds at some place: `words` as the error message says it."""

    words: str
    holds: Callable[[Any], bool]


@dataclass(frozen=True)
class Maybe:
    """A key an object may lack."""

    shape: Any


TEXT = Kind("text", lambda v: isinstance(v, str))
WHOLE = Kind("a whole number", lambda v: type(v) is int)
WHOLE_OR_NULL = Kind("a whole number or null", lambda v: v is None or type(v) is int)
NUMBER = Kind("a number", lambda v: type(v) in (int, float))
FLAG = Kind("true or false", lambda v: type(v) is bool)
OBJECT = Kind("an object", lambda v: isinstance(v, dict))

# The plan file, as `apply --plan` reads it (a key → its shape; [shape]: a list of them). The
# rest of it — summaries, figures, the review — is held against what prc3cfg writes for the
# plan it proves (`prc3cfg.api.prove`), as any JSON.
_STEP = {"message": TEXT, "releases_axes": FLAG, "broadcast": Maybe(FLAG)}
_MODULE = {"address": WHOLE, "name": TEXT, "state_sha256": TEXT, "releases_axes": FLAG, "steps": [_STEP],
           "read": Maybe({"programs": [WHOLE], "programs_not_read": [WHOLE]})}  # fmt: skip
PLAN_FILE = {
    "plant": TEXT, "plant_path": TEXT, "plant_sha256": TEXT, "prc3cfg_version": Maybe(TEXT),
    "buses": [{"name": TEXT, "modules": [_MODULE]}], "read": Maybe({"base": TEXT, "modules_not_read": [TEXT]}),
}  # fmt: skip
# ... and as `show` reads it, to show it: the review beside the steps (`render.changes_json`),
# the figures, each bus's broadcasts.
_CHANGES = {
    "fields": [{"program": WHOLE_OR_NULL, "field": TEXT, "text": TEXT}], "symbols": Maybe(OBJECT),
    "chains_removed": [TEXT], "chains_added": [TEXT], "clamped": [{"program": WHOLE, "text": TEXT}], "charts": Maybe([TEXT]),
}  # fmt: skip
_BROADCAST = {"message": TEXT, "releases_axes": FLAG, "modules": [WHOLE]}
SHOWN_PLAN_FILE = PLAN_FILE | {
    "buses": [{"name": TEXT, "broadcasts": Maybe([_BROADCAST]), "proven_silent": Maybe([WHOLE]), "unlisted_modules": Maybe([WHOLE]),
               "modules": [_MODULE | {"estimated_bus_time_s": Maybe(NUMBER), "changes": _CHANGES}]}],
    "axis_releases": [TEXT], "message_count": WHOLE, "estimated_bus_time_s": NUMBER, "naive_bus_time_s": NUMBER,
    "left_alone": Maybe([TEXT]), "estimated_time_s": Maybe(NUMBER),
    "estimated_phases_s": Maybe({"reading": NUMBER, "writing": NUMBER, "verifying": NUMBER}),
}  # fmt: skip


def shape_problem(value: Any, shape: Any, at: str = "") -> str | None:
    """Where and how `value` is not of `shape` (a `Kind`, [shape] or {key: shape}), in words —
    'buses[0].modules[2] has no "steps"', "buses[1].name is null, where text belongs" — or None."""
    if isinstance(shape, dict):
        if not isinstance(value, dict):
            return _wrong(value, OBJECT.words, at)
        for key, inner in shape.items():
            if key not in value:
                if isinstance(inner, Maybe):
                    continue
                return f'{at or "the plan"} has no "{key}"'
            if problem := shape_problem(value[key], inner.shape if isinstance(inner, Maybe) else inner, f"{at}.{key}".lstrip(".")):
                return problem
        return None
    if isinstance(shape, list):
        if not isinstance(value, list):
            return _wrong(value, "a list", at)
        return next((p for i, item in enumerate(value) if (p := shape_problem(item, shape[0], f"{at}[{i}]")) is not None), None)
    return None if shape.holds(value) else _wrong(value, shape.words, at)


def _wrong(value: Any, wanted: str, at: str) -> str:
    return f"{at or 'the plan'} is {_described(value)}, where {wanted} belongs"


def _described(value: Any) -> str:
    """A JSON value in a few words: null, true, 2.7, the text "2", a list, an object."""
    if value is None or isinstance(value, bool | int | float):
        text = json.dumps(value)
        return text if len(text) <= 20 else f"a number of {len(text)} characters"
    if isinstance(value, str):
        return f"the text {json.dumps(value[:20])}" + ("…" if len(value) > 20 else "")
    return "a list" if isinstance(value, list) else "an object"


@dataclass(frozen=True, slots=True)
class PlanFile:
    """A plan file as read: what it was made from, by which prc3cfg, and its modules."""

    plant: str
    plant_path: str
    plant_sha256: str
    version: str
    modules: tuple[PlannedModule, ...]
    document: dict[str, Any]  # as read: `apply --plan` holds it against what prc3cfg writes for the plan it proves


def read_plan_file(data: Any, *, shown: bool = False) -> PlanFile:
    """A parsed plan file; raises PlanFileError.

    Refused here, before the line is touched: a damaged file — a key missing, a value of
    another kind (`PLAN_FILE`; with `shown`, all that `show` shows, `SHOWN_PLAN_FILE`) — a
    module listed twice, more steps than any plan needs (`MAX_STEPS`), a message that is not
    in the bytes prc3cfg sends for it (a "don't care" byte changed), and `releases_axes` flags
    that are not what the steps' bytes say.
    """
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise PlanFileError(f'not a plan file — expected "format": "{FORMAT}"')
    if (problem := shape_problem(data, SHOWN_PLAN_FILE if shown else PLAN_FILE)) is not None:
        raise PlanFileError(f"damaged plan file: {problem} — {AGAIN}")
    modules = []
    seen: set[tuple[str, int]] = set()
    for b, bus in enumerate(data["buses"]):
        for m, module in enumerate(bus["modules"]):
            entry = _planned_module(bus["name"], module, f"buses[{b}].modules[{m}]")
            if ("read" in data) != (entry.programs_read is not None):
                raise PlanFileError(f"damaged plan file: buses[{b}].modules[{m}] {'lacks' if 'read' in data else 'has'} the \"read\" "
                                    f"of a plan made from a {'targeted' if 'read' in data else 'full'} read-back — {AGAIN}")  # fmt: skip
            if (entry.bus, entry.address) in seen:
                raise PlanFileError(f"bus {entry.bus}, module {entry.address} is listed twice — {AGAIN}")
            seen.add((entry.bus, entry.address))
            modules.append(entry)
        if shown:
            for index, step in enumerate(bus.get("broadcasts", [])):
                _message(step["message"], f"buses[{b}].broadcasts[{index}]", f"bus {bus['name']}: broadcast {index + 1}")
    fields = (data["plant"], data["plant_path"], data["plant_sha256"], data.get("prc3cfg_version", "before 0.1.0"))
    return PlanFile(*fields, tuple(modules), data)


def _planned_module(bus: str, module: dict[str, Any], at: str) -> PlannedModule:
    """A module's entry, of the shape `PLAN_FILE` gives it, at `at` ("buses[0].modules[2]")."""
    address = module["address"]
    where = f"bus {bus}, module {address}"
    steps = module["steps"]
    if len(steps) > MAX_STEPS:
        raise PlanFileError(f"{where}: {len(steps)} steps, more than any plan of one module needs ({MAX_STEPS}) — {AGAIN}")
    messages, flags = [], []
    for index, step in enumerate(steps, start=1):
        flags.append(step.get("broadcast", False))
        if flags[-1] and not all(flags):
            raise PlanFileError(f"{where}: step {index} ({step['message'][:128]}) is marked broadcast after a step that is not — "
                                f"broadcasts lead a module's steps: {AGAIN}")  # fmt: skip
        message = _message(step["message"], f"{at}.steps[{index - 1}]", f"{where}: step {index}")
        if step["releases_axes"] is not message.RELEASES_AXES:
            raise PlanFileError(
                f"{where}: step {index} ({step['message']}) says releases_axes: {json.dumps(step['releases_axes'])}, "
                f"but {message.ID:02X}h {'releases' if message.RELEASES_AXES else 'does not release'} the axes — {AGAIN}"
            )
        messages.append(message)
    if module["releases_axes"] is not any(m.RELEASES_AXES for m in messages):
        raise PlanFileError(f"{where}: releases_axes: {json.dumps(module['releases_axes'])} is not what its steps do — {AGAIN}")
    read = None
    if "read" in module:
        read = tuple(module["read"]["programs"])
        if list(read) != sorted(set(read)) or not all(1 <= n <= PROGRAM_COUNT for n in read):
            raise PlanFileError(f"damaged plan file: {at}.read.programs is not a list of program numbers 1..{PROGRAM_COUNT}, "
                                f"each once, in order — {AGAIN}")  # fmt: skip
    return PlannedModule(bus, address, module["name"], module["state_sha256"], tuple(messages), sum(flags), read)


def _message(text: str, at: str, where: str) -> codec.Message:
    """The message a step's `message` (at `at`) writes in hex, exactly as prc3cfg writes it."""
    try:
        data = bytes.fromhex(text)
    except ValueError:
        raise PlanFileError(f"damaged plan file: {at}.message is not a PRC 3 message in hex — {AGAIN}") from None
    try:
        message = codec.decode_message(data)
    except codec.Rejected as rejected:
        raise PlanFileError(f"{where} ({text[:64]}) is not a message prc3cfg sends: a module would answer it with "
                            f"{describe(rejected.code)} — {AGAIN}") from None  # fmt: skip
    if message.hex() != text:  # "don't care" bytes that are not 00h, upper-case digits
        raise PlanFileError(f"{where} ({text}) is not written as prc3cfg writes that message ({message.hex()}) — {AGAIN}")
    return message
