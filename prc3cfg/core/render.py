"""Showing plans to people: the diff in human units, chains as chains, axis warnings.

Owns the words and layout of `plan` output — human (Terraform-like), markdown for pull
request comments (within a comment's size, with a stroke chart per changed chain), and the
`changes` list of the JSON output — and of what `read`, drift and the account of an apply
say of each module (`image_lines`, `drift_lines`, `account`, `travel_list`), and what `show` says of a
plant file's modules (`modules_table`, `shown_module`: words and rows; the CLI draws). Reasons shown here never
steer an apply (the plan's steps do). A module's diff (`ModuleDiff`: its fields, its jumps,
the programs it clamps) is worked out by comparing the two images field by field, once
per output and module, as the module is shown (kept for all 240 modules of a large plant, the
diffs would hold 20 MB). The units are `prc3cfg.core.units`. Pure: returns strings.

Every text a plan or plan file brings (names, the base, notes, a field's words) is shown escaped for
its medium by `prc3cfg.core.text` — `shown` in every output, `markdown` in a comment — and a plan
file's stroke charts only in the shape prc3cfg writes them (`CHART`): a plan file is data that
anyone may have edited.

It is long because it is the one home of the words people read of a module: a field's name and
value in human units (`field_name`, `format_value`), two images' differences (`differences`,
`drift_changes`), a comment's escaping and budget (`cell`, `code`, `COMMENT_BUDGET`) serve the plan's
three outputs, drift, the account of an apply and `show` alike; split by output, each module would
import the others' pieces. Plans come first; `# --` rulers mark the other two parts: `read`, drift
and the account, then `show`.
"""

from __future__ import annotations

import functools
import re
import shlex
from collections.abc import Callable, Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol

from prc3cfg.core import plan_file
from prc3cfg.core import text as escape
from prc3cfg.core.axes import Release
from prc3cfg.core.chains import jumps_as_chains
from prc3cfg.core.device import widest_range
from prc3cfg.core.image import PROGRAM_FIELDS, PROGRAM_NUMBERS, SYSTEM_KEYS, ModuleImage, Program, SystemParameters
from prc3cfg.core.motion import MotionError, paired_chains
from prc3cfg.core.outcome import ModuleOutcome, to_travel
from prc3cfg.core.planner import Action
from prc3cfg.core.plant_plan import LineProof, ModuleChange, PlantPlan
from prc3cfg.core.plot import AFTER, BEFORE, mermaid
from prc3cfg.core.text import address_ranges
from prc3cfg.core.units import BY_SYMBOL, FUNCTION_OUTPUTS, PROGRAM_QUANTITIES, SYSTEM_QUANTITIES, human_text
from prc3cfg.core.what_to_read import to_the_minute
from prc3cfg.errors import UserError

AXIS_WARNING = "releases the axes: travel to reference point required after apply"
CLAMPED = "clamped by the module itself when its system parameters change"
#: The program fields a diff compares: A is shown as jumps (`chain_changes`).
_DIFF_FIELDS = tuple(f for f in PROGRAM_FIELDS if f != "A")


@functools.cache
def field_name(symbol: str) -> str:
    """The plant-file key in words: S1 → "upper reversing point", Vr → "relative speed"."""
    return BY_SYMBOL[symbol].key.replace("_", " ") if symbol in BY_SYMBOL else symbol


@functools.lru_cache(maxsize=4096)
def format_value(symbol: str, device: int) -> str:
    """A device value in human units: "1.050 m", "set at 0.010 m"; raw when no module holds it
    (`device.widest_range`: a damaged or foreign module's read-back is shown, never decoded)."""
    low, high = widest_range(symbol)
    if not low <= device <= high:
        return f"{device} (raw, outside {low}..{high})"
    return human_text(symbol, device)


@dataclass(frozen=True, slots=True)
class FieldChange:
    """One differing field, and how people read it: "position 1.050 m → 0.600 m"."""

    program: int | None  # None: a system parameter
    symbol: str
    before: int
    after: int
    text: str

    @classmethod
    def of(cls, program: int | None, symbol: str, before: int, after: int) -> FieldChange:
        text = f"{field_name(symbol)} {format_value(symbol, before)} → {format_value(symbol, after)}"
        return cls(program, symbol, before, after, text)

    def to_json(self) -> dict[str, Any]:
        return {"program": self.program, "field": self.symbol, "before": self.before, "after": self.after, "text": self.text}


def field_changes(actual: ModuleImage, desired: ModuleImage) -> list[FieldChange]:
    """Every differing system parameter and program field (A excluded: see `chain_changes`), in
    message order; a program missing from either image (not read, not managed) has none."""
    system = [FieldChange.of(None, key, getattr(actual.system, key), getattr(desired.system, key))
              for key in SYSTEM_KEYS if getattr(actual.system, key) != getattr(desired.system, key)]
    return system + _program_changes(actual.programs, desired.programs, PROGRAM_NUMBERS)


def _program_changes(before: tuple[Program | None, ...], after: tuple[Program | None, ...],
                     numbers: Iterable[int]) -> list[FieldChange]:
    """The differing fields (A excluded) of the programs `numbers` that both images hold."""
    changes = []
    for number in numbers:
        old, new = before[number - 1], after[number - 1]
        if old is not None and new is not None and old != new:
            changes += [FieldChange.of(number, key, getattr(old, key), getattr(new, key))
                        for key in _DIFF_FIELDS if getattr(old, key) != getattr(new, key)]
    return changes


def jumps(image: ModuleImage, within: set[int]) -> set[str]:
    """The jumps among the programs in `within` as people read them: chains, loops, single jumps."""
    chain_list, nexts = jumps_as_chains({n: image.known(n) for n in within})
    lines = {f"jump {n} → {a}" for n, a in nexts.items()}
    for chain in chain_list:
        if isinstance(chain, dict):  # a loop: back to its first program
            lines.add("chain " + " → ".join(map(str, [*chain["programs"], chain["programs"][0]])))
        else:
            lines.add("chain " + " → ".join(map(str, chain)) + " → stop")
    return lines


def chain_changes(actual: ModuleImage, desired: ModuleImage) -> tuple[list[str], list[str]]:
    """(jumps removed, jumps added) among the managed programs."""
    managed = {n for n, p in enumerate(desired.programs, start=1) if p is not None}
    if all(actual.known(n).A == desired.known(n).A for n in managed):
        return [], []  # the same jump addresses, the same jumps (`jumps` reads A alone): most plans change none
    before, after = jumps(actual, managed), jumps(desired, managed)
    return sorted(before - after), sorted(after - before)


def clamped_changes(change: ModuleChange) -> list[FieldChange]:
    """What the module's own clamping does to programs the plant does not manage (§4.2)."""
    unmanaged = [n for n, p in enumerate(change.desired.programs, start=1) if p is None]
    return _program_changes(change.actual.programs, change.plan.predicted.programs, unmanaged)


#: A drifted jump's `field` (`drift_changes`): a chain or a jump in words, not a field of a program.
JUMPS = "jumps"


def drift_changes(said: ModuleImage, held: ModuleImage) -> list[dict[str, Any]]:
    """Where a module holds something else than the plant file says, as a change made on the floor —
    "what the file says → what the module holds", the direction `adopt` shows it in: each a field as a
    plan file's `changes` give it (`FieldChange.to_json`: program, field symbol, before and after in device
    units), or a jump (`JUMPS`: before, after a chain in words, null where there is none); `text` the sentence."""
    fields = [f.to_json() | {"text": f"{'system' if f.program is None else f'program {f.program}'} {f.text}"}
              for f in field_changes(said, held)]  # fmt: skip
    in_module, in_file = chain_changes(held, said)
    return (fields + [{"program": None, "field": JUMPS, "before": None, "after": c, "text": f"{c}: in the module only"} for c in in_module]
            + [{"program": None, "field": JUMPS, "before": c, "after": None, "text": f"{c}: in the plant file only"} for c in in_file])  # fmt: skip


def differences(have: ModuleImage, want: ModuleImage) -> list[str]:
    """Where a module holds something else than the plant file says, "what it holds → what it should"."""
    fields = [f"{'system' if f.program is None else f'program {f.program}'} {f.text}" for f in field_changes(have, want)]
    removed, added = chain_changes(have, want)
    return fields + [f"has {c}" for c in removed] + [f"lacks {c}" for c in added]


@dataclass(frozen=True, slots=True)
class ModuleDiff:
    """What one module's plan changes, as every output shows it: the differing fields (their
    texts made once: a plan of 240 changed modules has 60,000), each changed program's `Action`,
    the jumps removed and added, and what the module's clamping does to programs the plant does
    not manage."""

    fields: tuple[FieldChange, ...]
    actions: dict[int, Action]
    chains_removed: tuple[str, ...]
    chains_added: tuple[str, ...]
    clamped: tuple[FieldChange, ...]


def module_diff(change: ModuleChange) -> ModuleDiff:
    """The diff of one module, for the human, markdown and JSON outputs of a plan."""
    fields = field_changes(change.actual, change.desired)
    removed, added = chain_changes(change.actual, change.desired)
    return ModuleDiff(
        fields=tuple(fields),
        actions=Action.of_programs(change.actual, change.desired, {f.program for f in fields if f.program is not None}),
        chains_removed=tuple(removed),
        chains_added=tuple(added),
        clamped=tuple(clamped_changes(change)),
    )


def module_lines(changes: dict[str, Any]) -> list[str]:
    """The diff of one module, one change per line, from its `changes` (`changes_json`, or a plan file's)."""
    lines: list[str] = []
    system = [f["text"] for f in changes["fields"] if f["program"] is None]
    if system:
        lines.append(f"{Action.UPDATE} system: {', '.join(system)}")
    programs: dict[int, list[str]] = {}
    for f in changes["fields"]:
        if f["program"] is not None:
            programs.setdefault(f["program"], []).append(f["text"])
    symbols = changes.get("symbols", {})
    lines += [f"{symbols.get(str(number), Action.UPDATE)} program {number}: {', '.join(texts)}"
              for number, texts in programs.items()]  # fmt: skip
    lines += [f"{Action.DELETE} {c}" for c in changes["chains_removed"]] + [f"{Action.CREATE} {c}" for c in changes["chains_added"]]
    clamped: dict[int, list[str]] = {}
    for f in changes["clamped"]:
        clamped.setdefault(f["program"], []).append(f["text"])
    lines += [f"{Action.UPDATE} program {n} (not managed, kept): {', '.join(texts)} — {CLAMPED}" for n, texts in clamped.items()]
    return lines


def plural(count: int, one: str, many: str | None = None) -> str:
    """ "1 module", "2 modules", "1 bus", "3 buses"."""
    return f"{count} {one if count == 1 else many or one + 's'}"


#: Characters of module names the axis question lists before "and N more": about two lines of a terminal.
RELEASE_NAMES_BUDGET = 150


def some_of(names: Sequence[str], budget: int = RELEASE_NAMES_BUDGET) -> str:
    """Names joined by commas while they fit in `budget` characters, the rest counted: "a, b and 28 more"
    (the first name always shown) — a list that stays a few lines however many modules it names."""
    shown: list[str] = []
    for index, name in enumerate(names):
        rest = len(names) - index
        if shown and len(", ".join([*shown, name])) + (len(f" and {rest - 1} more") if rest > 1 else 0) > budget:
            return f"{', '.join(shown)} and {rest} more"
        shown.append(name)
    return ", ".join(shown)


def release_summary(names: Sequence[str]) -> list[str]:
    """What the axis question says before it asks, in a few lines whatever the count: how many modules
    release their axes and which (`some_of`), and what that means for production."""
    count = len(names)
    return [
        f"⚠ {plural(count, 'module')} will release {'its' if count == 1 else 'their'} axes (10h/20h): {some_of(names)}",
        f"  {'It loses its' if count == 1 else 'Each loses its'} reference point and must travel to it before production.",
    ]


def header_line(bus: str, address: int, name: str, steps: int, broadcasts: int, seconds: float, releases: bool) -> str:
    """A module's line in a plan: "~ bus booth-a, module 1 (left): 4 steps, 0.178 s  ⚠ …"."""
    head = f"{Action.of_module(steps)} bus {bus}, module {address} ({name})"
    if not steps:
        return f"{head}: no changes"
    received = f" ({broadcasts} by broadcast)" if broadcasts else ""
    warn = f"  ⚠ {AXIS_WARNING}" if releases else ""
    return f"{head}: {plural(steps, 'step')}{received}, {seconds:.3f} s{warn}"


def step_line(index: int, message_hex: str | None, summary: str, releases: bool, broadcast: bool) -> str:
    """One step: number, the message as sent (`--frames`: its bytes in hex; None: left out), what it does,
    and what it means for the axes."""
    frame = "" if message_hex is None else f"{message_hex:<24} "
    return (f"{index:>3}. {frame}{summary}" + ("  (broadcast)" if broadcast else "")
            + ("  ⚠ RELEASES AXES" if releases else ""))  # fmt: skip


def changes_json(change: ModuleChange, *, charts: bool = True) -> dict[str, Any]:
    """What people read of one module's change: its fields, the symbol of each changed program,
    its jumps, what the module's clamping does, the axis warning (a plan file keeps it beside the steps),
    and unless told not to (the terminal shows none) the stroke charts of its changed chains: working
    out the motions takes most of the time of rendering 8 × 30 modules whose chains change."""
    diff = module_diff(change)
    return {
        "fields": [f.to_json() for f in diff.fields],
        "symbols": {str(number): action.value for number, action in diff.actions.items()},
        "chains_removed": list(diff.chains_removed),
        "chains_added": list(diff.chains_added),
        "clamped": [{**f.to_json(), "reason": CLAMPED} for f in diff.clamped],
        "warning": AXIS_WARNING if change.releases_axes else None,
    } | ({"charts": _charts(change)} if charts else {})


def review(change: ModuleChange) -> dict[str, Any]:
    """What a plan file holds beside a module's steps for people to read (`prc3cfg.core.plan_file.write`,
    which is given this module as its `Words`): the module's `changes` and its axis `warning`."""
    return {"changes": changes_json(change), "warning": AXIS_WARNING if change.releases_axes else None}


def _outline(plan: PlantPlan | dict[str, Any], notes: Iterable[str]) -> tuple[dict[str, Any], dict[tuple[str, int], ModuleChange]]:
    """What the human and markdown outputs are made from, every text in it `shown`: a plan file's
    document, or a live plan's without its read-backs' hashes (neither output shows one) and without the
    modules' `changes`, each worked out by `_changes` as its module is shown (all of them at once, for
    8 × 30 modules with every program changed, hold 35 MB), with the changes by (bus, address) — the
    bus's name as the document has it."""
    if isinstance(plan, dict):
        return _plain_texts(plan), {}
    document = plan_file.to_json(plan, hashes=False) | {"left_alone": list(notes)}
    return _plain_names(document), {(escape.shown(c.bus), c.address): c for c in plan.changes}


def _plain_names(document: dict[str, Any]) -> dict[str, Any]:
    """A live plan's document with the texts files gave it `shown`: its names, its base, its notes (the words of
    its steps are prc3cfg's own; a plan file's are not: `_plain_texts`)."""
    document["plant"] = escape.shown(document["plant"])
    for key in ("axis_releases", "left_alone"):
        document[key] = [escape.shown(text) for text in document[key]]
    if isinstance(said := document.get("read"), dict):
        document["read"] = _plain_texts(said)
    for bus in document["buses"]:
        bus["name"] = escape.shown(bus["name"])
        for module in bus["modules"]:
            module["name"] = escape.shown(module["name"])
    return document


#: A stroke chart as `plot.mermaid` writes it, or the line that says how many more there are: what a
#: plan file's `charts` may hold to be shown (anything else in a fenced block could close it).
CHART = re.compile(
    r"```mermaid\n%%\{init: \{\"themeVariables\": \{\"xyChart\": \{\"plotColorPalette\": "
    rf"\"({AFTER}|{BEFORE}, {AFTER}|{BEFORE})\"\}}\}}\}}\}}%%\n"
    r"xychart-beta\n    title \"[0-9a-z →·:.,() ]*\"\n    x-axis \"time \(s\)\" 0 --> [0-9.]+\n"
    r"    y-axis \"position \(m\)\" 0 --> [0-9.]+\n(    line \[[0-9., -]*\]\n){1,2}```"
    r"|\n_[0-9]+ more chains? changed: `prc3cfg show PLANT --module [^`\n]* --plot FILE\.svg` draws them all\._|"
)


def _plain_texts(value: Any) -> Any:
    """`value` with every text in it `shown`, and of `charts` only what `CHART` matches."""
    if isinstance(value, str):
        return escape.shown(value)
    if isinstance(value, list):
        return [_plain_texts(item) for item in value]
    if isinstance(value, dict):
        return {key: [c for c in item if isinstance(c, str) and CHART.fullmatch(c)]
                if key == "charts" and isinstance(item, list) else _plain_texts(item) for key, item in value.items()}  # fmt: skip
    return value


def _changes(bus: str, module: dict[str, Any], live: dict[tuple[str, int], ModuleChange], *, charts: bool = True) -> dict[str, Any]:
    """A module's `changes` (`changes_json`): the plan file's, or worked out now from the live plan (without
    its `charts` when not asked for)."""
    return changes_json(live[(bus, module["address"])], charts=charts) if live else module["changes"]


def _modules(document: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    return [(bus["name"], module) for bus in document["buses"] for module in bus["modules"]]


def _header(bus: str, module: dict[str, Any]) -> str:
    steps = module["steps"]
    return header_line(bus, module["address"], module["name"], len(steps), sum(bool(s.get("broadcast")) for s in steps),
                       module.get("estimated_bus_time_s", 0.0), module["releases_axes"])  # fmt: skip


def _step_lines(module: dict[str, Any], frames: bool) -> list[str]:
    return [step_line(i, s["message"] if frames else None, s["summary"], s["releases_axes"], bool(s.get("broadcast")))
            for i, s in enumerate(module["steps"], start=1)]  # fmt: skip


def line_proof(bus: dict[str, Any], shown: Callable[[str], str] = escape.shown) -> str | None:
    """What the probes of a bus's line found at the addresses its plant file does not list, in one line
    (the bus's name `shown` as the medium needs)."""
    if bus.get("unlisted_modules"):
        return (f"⚠ bus {shown(bus['name'])}: a module answers at {address_ranges(bus['unlisted_modules'])}, which the plant file does not "
                "list — the line has modules the plant does not know, so it gets no broadcast: add them to the plant file, "
                "or drop only_these_modules")  # fmt: skip
    if bus.get("proven_silent"):
        return f"bus {shown(bus['name'])}: {address_ranges(bus['proven_silent'])} answered no probe — the broadcasts reach the plan's modules only"
    return None


def _broadcast_lines(bus: dict[str, Any], frames: bool) -> list[str]:
    """A bus's broadcasts, once: one step for all of its modules — and what proved nobody else hears them."""
    steps = bus.get("broadcasts", [])
    proof = line_proof(bus)
    if not steps:
        return [proof, ""] if proof else []
    head = (f"~ bus {bus['name']}: {plural(len(steps), 'broadcast')} to all {len(steps[0]['modules'])} modules "
            "(address 0), each verified by reading back")  # fmt: skip
    return [head, *(f"    {step_line(i, s['message'] if frames else None, s['summary'], s['releases_axes'], True)}"
                    for i, s in enumerate(steps, 1)),
            *([f"    {proof}"] if proof else []), ""]


#: The phases of an apply as the operator reads them (`PlantPlan.phases`).
PHASES = {"reading": "reading back", "writing": "writing", "verifying": "verifying"}


def summary_line(document: dict[str, Any], shown: Callable[[str], str] = escape.shown) -> str:
    """The plan's headline: what changes and what it costs — or that nothing does, and on what evidence
    (`no_changes`), its texts `shown` as the medium needs."""
    modules = _modules(document)
    changed = sum(1 for _, m in modules if m["steps"])
    if not changed:
        return no_changes(document.get("evidence"), shown)
    releases = len(document["axis_releases"])
    return (
        f"Plan: {changed} of {plural(len(modules), 'module')} change{'s' if changed == 1 else ''}, "
        f"{plural(document['message_count'], 'message')}, " + estimate(document)
        + (f"; ⚠ {plural(releases, 'module')} release{'s' if releases == 1 else ''} the axes" if releases else "")
    )


#: The headline of a plan without changes that read every value it covers in that run.
EVERY_MODULE = "No changes: every module matches the plant file."


def no_changes(evidence: dict[str, Any] | None, shown: Callable[[str], str] = escape.shown) -> str:
    """The headline of a plan without changes, naming its evidence (`plan_file.evidence`): "every module
    matches the plant file" only when every value it covers was read in that run; else "No changes to
    what was read now (the system blocks of 6 modules) or to what prc3cfg last read or verified (82
    programs of 4 modules; oldest value taken from the record: line/m4's programs, as apply of /p/a.yaml by ana@pc
    read or verified them since 2026-11-26 03:27 UTC)"."""
    if evidence is None:  # a plan file written before plans said what they rest on
        return "No changes (the plan file does not say what was read, or taken from the line's record)."
    if evidence["complete"]:
        return EVERY_MODULE
    now, record, oldest = evidence["read_now"], evidence["from_record"], evidence["oldest"]
    read = f"the system blocks of {plural(now['system_blocks'], 'module')}"
    read += f" and {plural(now['programs'], 'program')}" if now["programs"] else ""
    rests = f"{plural(record['programs'], 'program')} of {plural(record['modules'], 'module')}"
    rests += f"; {oldest_taken(oldest, shown)}" if oldest is not None else ""
    return f"No changes to what was read now ({read}) or to what prc3cfg last read or verified ({rests})."


def factory_line(document: dict[str, Any]) -> str | None:
    """What an apply planned from the factory's programs without reading them, in one line (None: nothing):
    on a factory-fresh module (`what_to_read.factory_fresh`) the programs the plant file manages are
    written over, not read first — and every one of them is read back after the writes."""
    said = (document.get("evidence") or {}).get("from_factory")
    if not isinstance(said, dict) or not said.get("programs"):
        return None
    return (f"Not read before writing: {plural(said['programs'], 'program')} of {plural(said['modules'], 'module')} whose system "
            "parameters read as the factory's — planned as the factory's, not read before writing; the verification reads every "
            "one of them back after the writes, and repairs what another tool changed there")  # fmt: skip


def oldest_taken(oldest: dict[str, Any], shown: Callable[[str], str] = escape.shown, *, whose: bool = True) -> str:
    """The oldest evidence a plan relied on (`evidence.oldest`), in words: "oldest value taken from the record:
    line/m4's programs, as apply of /p/a.yaml by ana@pc read or verified them since 2026-11-26 03:27 UTC"
    (without `whose`: "…: line/m4's programs, since 2026-11-26 03:27 UTC")."""
    since = to_the_minute(oldest["since"]) or shown(oldest["since"])
    by = f" as {shown(oldest['by'])} read or verified them" if whose else ""
    return f"oldest value taken from the record: {shown(oldest['module'])}'s programs,{by} since {since}"


def clamped_line(document: dict[str, Any], live: dict[tuple[str, int], ModuleChange]) -> str | None:
    """How many programs the plant does not manage the modules' own clamping changes, and on how many modules,
    in one line — said by every output whatever it leaves out of the details; None where there are none."""
    if live:
        counts = [len({f.program for f in clamped_changes(change)}) for change in live.values()]
    else:
        counts = [len({f["program"] for f in m.get("changes", {}).get("clamped", [])}) for _, m in _modules(document)]
    programs, modules = sum(counts), sum(1 for count in counts if count)
    if not programs:
        return None
    return (f"⚠ {plural(programs, 'program')} the plant does not manage {'is' if programs == 1 else 'are'} clamped by "
            f"{plural(modules, 'module')} as {'its' if modules == 1 else 'their'} system parameters change "
            "(unmanaged_programs: keep) — each module's diff lists them")  # fmt: skip


def estimate(document: dict[str, Any]) -> str:
    """The time an apply of the plan takes, the total first, then by phase, with the writes' bus time
    beside the naive download's: "estimated time 9.6 s: reading back 4.1 s, writing 1.1 s (bus time
    1.099 s, naive download 1.149 s), verifying 4.4 s" (a plan file without phases: the bus times)."""
    bus_times = f"bus time {document['estimated_bus_time_s']:.3f} s, naive download {document['naive_bus_time_s']:.3f} s"
    phases = document.get("estimated_phases_s")
    if not isinstance(phases, dict):
        return f"estimated {bus_times}"
    total = document.get("estimated_time_s", sum(phases[phase] for phase in PHASES))  # a plan file may lack either
    return (f"estimated time {total:.1f} s: {PHASES['reading']} {phases['reading']:.1f} s, "
            f"{PHASES['writing']} {phases['writing']:.1f} s ({bus_times}), {PHASES['verifying']} {phases['verifying']:.1f} s")  # fmt: skip


def reading_line(document: dict[str, Any], shown: Callable[[str], str] = escape.shown, *, claimed: bool = False) -> str | None:
    """What a targeted plan read now and what it took as known from the line's record, in one line,
    its texts `shown` as the medium needs; None for a full read. "Read now: the system parameters of
    30 modules and 60 programs; taken as known from the line's record …, not read: 900 programs of 30
    modules, as apply of /p/a.yaml by ana@pc (since …) read or verified them; read in full: line/m2
    (program 3 is not as on record) — what no read sees: …". `claimed`: the document is a plan file's,
    whose words of whose verification was taken and of what was read in full and why are its own claim
    (`prc3cfg.core.plan_file`): said after "the plan file says", never as prc3cfg's."""
    said = document.get("read")
    if not isinstance(said, dict):
        return None
    modules = _modules(document)
    programs = sum(len(m["read"]["programs"]) for _, m in modules)
    read = f"the system parameters of {plural(len(modules), 'module')} and {plural(programs, 'program')}" if modules else "nothing"
    whose, not_read = _not_read(said, modules, shown)
    other = f"read in full: {', '.join(shown(name) for name in said['not_as_verified'])}" if said["not_as_verified"] else ""
    claims = "; ".join(words for words in (whose, other) if words) if claimed else ""
    if whose and not claimed:
        not_read[0] += f", as {whose}"
    if not_read and isinstance(oldest := (document.get("evidence") or {}).get("oldest"), dict):
        not_read[0] += f" ({oldest_taken(oldest, shown, whose=False)})"
    parts = [f"Read now: {read}"]
    parts += [f"taken as known from {shown(said['base'])}, not read: {' and '.join(not_read)}"] if not_read else []
    parts += [other] if other and not claimed else []
    parts += [f"the plan file says: {claims} (apply --plan proves whose, not why)"] if claims else []
    return "; ".join(parts) + (" — a program not read that another tool changed on a module whose system parameters did not "
                               "change is not seen: plan --refresh-only (or --full-read) reads everything" if not_read else "")  # fmt: skip


#: How a module's diff is shown where its review text is not the text its digest was written for: as the file's words.
SAID = "the plan file says: "
#: What `show` says of a plan file whose every module's review is the text its digest was written for.
REVIEW_AS_WRITTEN = "Review: the review text is as the plan was made (each module's review_sha256 matches it) — apply --plan proves the steps"


def review_line(document: dict[str, Any], shown: Callable[[str], str] = escape.shown) -> str | None:
    """What `show` says of a plan file's review text, judged by `plan_file.to_show` (each module's `review`):
    that it is the text its digests were written for — or which modules' review was changed since, or has no
    digest, whose words are then shown as the file's (`SAID`), the steps being what `apply --plan` proves.
    None for a document nobody judged (a live plan's)."""
    judged = [(bus, m) for bus, m in _modules(document) if "review" in m]
    if not judged:
        return None
    changed = [f"{shown(bus)}/{shown(m['name'])}" for bus, m in judged if m["review"] == plan_file.Review.CHANGED]
    undigested = [f"{shown(bus)}/{shown(m['name'])}" for bus, m in judged if m["review"] == plan_file.Review.NO_DIGEST]
    if not changed and not undigested:
        return REVIEW_AS_WRITTEN
    parts = [f"⚠ the review text of {some_of(changed)} was changed after the plan was made"] if changed else []
    parts += [f"⚠ {some_of(undigested)}: no review digest (made by an older prc3cfg)"] if undigested else []
    return "; ".join(parts) + (f" — its diff is shown as the file's words (\"{SAID.strip()}\"); the steps are what apply --plan proves: read "
                               "the steps (apply --plan refuses this file: plan again)")  # fmt: skip


def _as_written(module: dict[str, Any]) -> bool:
    """Whether a module's review is the text its digest was written for (a live plan's: prc3cfg's own, now)."""
    return bool(module.get("review", plan_file.Review.AS_WRITTEN) == plan_file.Review.AS_WRITTEN)


def _as_reviewed(module: dict[str, Any], lines: list[str]) -> list[str]:
    """A module's diff lines, each after `SAID` where its review is not the text its digest was written for."""
    return lines if _as_written(module) else [SAID + line for line in lines]


def _not_read(said: dict[str, Any], modules: list[tuple[str, dict[str, Any]]], shown: Callable[[str], str]) -> tuple[str, list[str]]:
    """Whose reads or verifications the programs not read rest on ("" when none was taken), and what was not
    read: "79 programs of 6 modules", "2 modules (line/a, line/b)"."""
    skipped = sum(len(m["read"]["programs_not_read"]) for _, m in modules)
    if not skipped:
        whose, parts = "", []
    else:
        sources = sorted({shown(source) for source in said.get("taken", {}).values()})
        whose = f"{'; '.join(sources[:3])}{' and others' if len(sources) > 3 else ''} read or verified them" if sources else ""
        parts = [f"{plural(skipped, 'program')} of {plural(sum(1 for _, m in modules if m['read']['programs_not_read']), 'module')}"]
    unread = [shown(name) for name in said["modules_not_read"]]
    parts += [f"{plural(len(unread), 'module')} ({', '.join(unread[:5])}{', …' if len(unread) > 5 else ''})"] if unread else []
    return whose, parts


def timing(estimated: dict[str, float], took: dict[str, float]) -> str:
    """An apply's time, estimated against taken, in total and by phase, in one line: "Time: 6.4 s
    (estimated 6.0 s) — reading back 5.0 s (4.9 s), writing 0.7 s (0.6 s), verifying 0.7 s (0.5 s)"."""
    phases = ", ".join(f"{words} {took[phase]:.1f} s ({estimated[phase]:.1f} s)" for phase, words in PHASES.items())
    return f"Time: {sum(took.values()):.1f} s (estimated {sum(estimated.values()):.1f} s) — {phases}"


def faulted_summary(document: dict[str, Any], faults: Sequence[str], shown: Callable[[str], str] = escape.shown) -> list[str]:
    """The summary, with the modules a write found in a fault state (`faults`: "bus/module is in E21 (…)",
    kept in the records until a write to it is acknowledged): a plan with nothing to write for them does
    not say all is well — its headline names the fault."""
    said = [f"⚠ {shown(fault)} — a read cannot tell whether it still is: clear the fault on the module" for fault in faults]
    if faults and not any(m["steps"] for _, m in _modules(document)):
        return [f"No changes to write, but {plural(len(faults), 'module')} reported a fault state:", *said]
    return [summary_line(document, shown), *said]


def human(plan: PlantPlan | dict[str, Any], *, notes: Iterable[str] = (), shown: Collection[str] = (),
          faults: Sequence[str] = (), frames: bool = False) -> str:  # fmt: skip
    """A plan (or a plan file's document) as the terminal shows it: per module its diff and steps,
    each bus's broadcasts once, the reference-travel warning, what stays as it is, the summary. The
    buses `shown` already (`line_part`, as their writes began) are named, not shown again. `frames`:
    each step's bytes in hex too (the plan file always keeps them)."""
    document, live = _outline(plan, notes)
    out = [f"Plant {document['plant']}", ""]
    for bus in document["buses"]:
        out += _broadcast_lines(bus, frames) if bus["name"] not in shown else [f"bus {bus['name']}: its plan is shown above, as its writes began", ""]
    out += _module_sections(document, live, frames, shown)
    if document["axis_releases"]:
        out.append("⚠ Travel to reference point required after apply on: " + ", ".join(document["axis_releases"]))
    out += [line for line in [clamped_line(document, live)] if line]
    out += faulted_summary(document, faults)
    out += [line for line in [reading_line(document, claimed=isinstance(plan, dict)), factory_line(document), review_line(document)] if line]
    out += [f"Left as it is: {note}" for note in document.get("left_alone", [])]
    if any(module["steps"] for _, module in _modules(document)):
        out.append(LEGEND)
    return "\n".join(out)


def line_part(plan: PlantPlan, frames: bool = False) -> str:
    """One line's plan (`plan` holds its modules only), shown as its writes begin while the other lines
    are still read (`apply --auto-approve --allow-axis-release`): its broadcasts, its modules, its axis releases."""
    document, live = _outline(plan, ())
    out = [f"Writing bus {', '.join(bus['name'] for bus in document['buses'])} now, as planned:", ""]
    for bus in document["buses"]:
        out += _broadcast_lines(bus, frames)
    out += _module_sections(document, live, frames)
    if document["axis_releases"]:
        out.append("⚠ Travel to reference point required after apply on: " + ", ".join(document["axis_releases"]))
    return "\n".join(out)


def _module_sections(document: dict[str, Any], live: dict[tuple[str, int], ModuleChange], frames: bool,
                     shown: Collection[str] = ()) -> list[str]:  # fmt: skip
    """Each module's diff and steps (a line for one without changes), those of the buses `shown` left out."""
    out = []
    for bus, module in _modules(document):
        if bus in shown:
            continue
        if not module["steps"]:
            out.append(_header(bus, module))
            continue
        diff = _as_reviewed(module, module_lines(_changes(bus, module, live, charts=False)))
        lines = [_header(bus, module), *diff, "steps:", *_step_lines(module, frames)]
        out.append("\n    ".join(lines) + "\n")  # one string a module: the lines of 240 would take more
    return out


#: What the marks of a plan mean (`Action`) — one vocabulary for a change, in every output that shows one.
LEGEND = (f"Marks: {Action.UPDATE} changed · {Action.CREATE} set up from factory defaults (a jump: made) · "
          f"{Action.DELETE} put back to factory defaults (a jump: no longer made) · ⚠ releases the axes")


#: Marks the pull-request comment a plan is posted as, so that CI updates it instead of adding one.
MARKER = "<!-- prc3cfg-plan -->"
#: What a GitHub comment holds, with room to spare (65,536 characters).
COMMENT_BUDGET = 65_000
#: Stroke charts (mermaid, about 1 KB each) a module's details show at most.
CHARTS = 3


def cell(text: str) -> str:
    """Text from a file for a markdown table cell or paragraph: shown as written, nothing in it live (`text.markdown`)."""
    return escape.markdown(text)


def code(text: str) -> str:
    """Text as a markdown code span outside a table: shown exactly as written (control characters
    `shown`) — inside one, an entity or a backslash would show as typed. Its fence is longer than any
    run of backticks in it."""
    text = escape.shown(text)
    fence = "`" * (max(map(len, re.findall("`+", text)), default=0) + 1)
    pad = " " if text[:1] == "`" or text[-1:] == "`" else ""
    return f"{fence}{pad}{text}{pad}{fence}"


def fenced(lines: Sequence[str], info: str = "") -> list[str]:
    """`lines` as a markdown fenced block: its fence longer than any run of backticks in them, so no line closes it."""
    fence = "`" * max(3, max((len(run) + 1 for line in lines for run in re.findall("`+", line)), default=0))
    return [fence + info, *lines, fence]


class BudgetTooSmall(UserError):
    """`--max-chars` below what a comment never leaves out; `needed` is the least it takes."""

    def __init__(self, max_chars: int, what: str, needed: int) -> None:
        super().__init__(f"--max-chars {max_chars:,} cannot hold {what} ({needed:,} characters, never left out) — "
                         f"give --max-chars {needed} or more")  # fmt: skip
        self.needed = needed


def _budgeted(head: str, parts: Iterable[str], count: int, closing: Callable[[int, int], str], max_chars: int, what: str) -> str:
    """`head`, then each of the `count` `parts` while it fits in `max_chars` characters with the
    `closing` line that says how many were left out (none when all are shown; it may name the
    budget): the comment as printed, its last line end counted. `BudgetTooSmall` where `head` and
    the closing of all left out do not fit, with the least budget that holds them.

    Before each part, what is taken and the closing of the parts from it on fit (for the first part,
    the check below; for each next, the previous part's), so the comment never exceeds the budget."""
    if count and len(head) + len(closing(count, max_chars)) > max_chars:
        needed = len(head)
        while (more := len(head) + len(closing(count, needed))) > needed:  # the closing may name the budget: its own digits
            needed = more
        raise BudgetTooSmall(max_chars, what, needed)
    if len(head) > max_chars:
        raise BudgetTooSmall(max_chars, what, len(head))
    text = head
    for shown, part in enumerate(parts):
        after = count - shown - 1
        if len(text) + len(part) + (len(closing(after, max_chars)) if after else 0) > max_chars:
            return text + closing(count - shown, max_chars)
        text += part
    return text


def markdown(plan: PlantPlan | dict[str, Any], *, max_chars: int = COMMENT_BUDGET, notes: Iterable[str] = (),
             full_plan: str = "the plan file", faults: Sequence[str] = (), frames: bool = False) -> str:  # fmt: skip
    """A plan (or a plan file's document) as a pull-request comment of at most `max_chars` characters
    as printed (its last line end counted): the marker, the summary, every axis-release warning, how
    many programs are clamped, what was not read, what is left as it is and the table of changed
    modules always — `BudgetTooSmall` where they do not fit; then each module's details (with a stroke
    chart per changed chain, for a live plan) while they fit, and a last line saying how many were
    left out and where the full plan is. `frames`: each step's bytes in hex too."""
    document, live = _outline(plan, notes)
    changed = [(bus, m) for bus, m in _modules(document) if m["steps"]]
    head = [MARKER, f"### prc3cfg plan — {code(document['plant'])}", "", *faulted_summary(document, faults, cell), "",
            *_callouts(document, live, claimed=isinstance(plan, dict)), *_changed_table(changed)]  # fmt: skip
    for bus in document["buses"]:
        if lines := _broadcast_lines(bus, frames):
            head += [*fenced(lines[:-1]), ""]

    def closing(left: int, budget: int) -> str:
        return (f"\n_The details of {plural(left, 'module')} are left out to keep this comment under "
                f"{budget:,} characters: the full plan is {full_plan}._\n")  # fmt: skip

    return _budgeted("\n".join(head).rstrip("\n") + "\n", (_details(bus, m, live, frames) for bus, m in changed), len(changed), closing,
                     max_chars, "the plan's summary, warnings and table of changed modules")  # fmt: skip


def _callouts(document: dict[str, Any], live: dict[tuple[str, int], ModuleChange], *, claimed: bool) -> list[str]:
    """A comment's quoted paragraphs under its summary, each only when it has something to say: what was
    not read, the axis-release warning, the clamped programs, what is left as it is, each line's proof."""
    out = [f"> {line}", ""] if (line := reading_line(document, cell, claimed=claimed)) else []
    out += [f"> {line}", ""] if (line := factory_line(document)) else []
    out += [f"> {line}", ""] if (line := review_line(document, cell)) else []
    if document["axis_releases"]:
        out += ["> [!WARNING]", "> These modules release their axes: **travel to reference point required after apply** — "
                + ", ".join(code(name) for name in document["axis_releases"]), ""]  # fmt: skip
    out += [f"> {line}", ""] if (line := clamped_line(document, live)) else []
    left_alone = document.get("left_alone", [])
    out += [f"> Left as it is: {cell(note)}" for note in left_alone] + ([""] if left_alone else [])
    proofs = [proof for bus in document["buses"] if (proof := line_proof(bus, cell))]
    return out + [f"> {proof}" for proof in proofs] + ([""] if proofs else [])


def _changed_table(changed: list[tuple[str, dict[str, Any]]]) -> list[str]:
    """The table of changed modules (none without one): bus, module, address, steps, bus time, axes."""
    if not changed:
        return []
    out = ["| bus | module | address | steps | bus time | axes |", "|---|---|---:|---:|---:|---|"]
    for bus, m in changed:
        axes = "⚠ released: travel to reference point required" if m["releases_axes"] else ""
        out.append(f"| {cell(bus)} | {cell(m['name'])} | {m['address']} | {len(m['steps'])} | "
                   f"{m.get('estimated_bus_time_s', 0.0):.3f} s | {axes} |")  # fmt: skip
    return [*out, ""]


def _details(bus: str, m: dict[str, Any], live: dict[tuple[str, int], ModuleChange], frames: bool) -> str:
    changes = _changes(bus, m, live)
    diff = _as_reviewed(m, module_lines(changes))
    return "\n".join([
        f"<details><summary>{escape.markdown_html(bus)} / {escape.markdown_html(m['name'])} (address {m['address']})"
        + (" ⚠ releases axes" if m["releases_axes"] else "") + "</summary>",
        "",
        *fenced(diff, "diff"),
        "",
        *fenced(_step_lines(m, frames)),
        *(changes.get("charts", []) if _as_written(m) else []),  # pictures of words that are only the file's: not drawn
        "</details>",
        "",
        "",
    ])  # fmt: skip


def _charts(m: ModuleChange) -> list[str]:
    """The stroke of each changed chain, before and after, as GitHub draws it (`plot.mermaid`)."""
    try:
        pairs = paired_chains(m.as_known(m.actual), m.as_known(m.plan.predicted), changed_only=True)
    except MotionError:  # a damaged read-back: the diff above still shows it
        return []
    charts = ["", *(mermaid(before, after) for before, after in pairs[:CHARTS])]
    if len(pairs) > CHARTS:
        command = code(f"prc3cfg show PLANT --module {shlex.quote(m.name)} --plot FILE.svg")
        charts.append(f"\n_{plural(len(pairs) - CHARTS, 'more chain')} changed: {command} draws them all._")
    return charts if pairs else []


# -- what `read`, drift and the account of an apply say of modules ----------------------------


def image_lines(bus: str, name: str, image: ModuleImage) -> list[str]:
    """A module as `prc3cfg read` shows it: where it is, its system parameters, each program read."""
    lines = [f"bus {bus}, module {image.address} ({name})",
             "  system: " + ", ".join(f"{field_name(k)} {format_value(k, v)}" for k, v in image.system.to_json().items())]  # fmt: skip
    for number, program in enumerate(image.programs, start=1):
        if program is not None:
            values = ", ".join(f"{field_name(k)} {format_value(k, v)}" for k, v in program.to_json().items() if k != "A")
            lines.append(f"  program {number}: {values}" + (f", next {program.A}" if program.A else ""))
    return lines


@dataclass(frozen=True)
class Drift:
    """A module that holds something other than the plant file says (Teach In, work on the
    floor): each difference one line in human units, what the file says → what the module holds,
    "program 3 position 1.200 m → 1.150 m" (as `adopt` shows it)."""

    bus: str
    address: int
    name: str
    differences: tuple[str, ...]
    #: the same differences as fields, before and after (`drift_changes`)
    changes: tuple[dict[str, Any], ...] = ()


def drift_lines(drifts: Sequence[Drift], modules: int) -> list[str]:
    """Drift as drift, not as a plan: each module that drifted, its differences, and how many of the
    `modules` read drifted."""
    lines = []
    for found in drifts:
        lines.append(f"~ bus {found.bus}, module {found.address} ({found.name}) drifted from the plant file (file → module):")
        lines.extend(f"    {text}" for text in found.differences)
    if drifts:
        lines.append(f"Drift: {len(drifts)} of {plural(modules, 'module')} hold{'s' if len(drifts) == 1 else ''} "
                     "something other than the plant file says.")  # fmt: skip
    else:
        lines.append("No drift: every module holds what the plant file says.")
    return lines


#: Marks the pull-request comment drift is posted as (`plan --refresh-only --markdown`).
DRIFT_MARKER = "<!-- prc3cfg-drift -->"
DRIFT_FORMAT = "prc3cfg-drift/1"


def drift_json(plant: str, drifts: Sequence[Drift], modules: int) -> dict[str, Any]:
    """Drift as a document (`plan --refresh-only --json`, `--out`): the plant, how many modules were
    read, and each module that drifted with its differences (file → module): in human units, and as
    `changes` of a field from before to after (`drift_changes`)."""
    return {"format": DRIFT_FORMAT, "plant": plant, "modules": modules,
            "drifted": [{"bus": d.bus, "address": d.address, "name": d.name, "differences": list(d.differences),
                         "changes": list(d.changes)} for d in drifts]}  # fmt: skip


def drift_markdown(document: dict[str, Any], *, max_chars: int = COMMENT_BUDGET, full_drift: str = "the drift file") -> str:
    """Drift as a pull-request comment of at most `max_chars` characters: the marker, the summary,
    then each module's differences while they fit, and how many were left out. Every text from the
    plant file or the modules is escaped (`cell`): nothing in it is live."""
    drifted, modules = document["drifted"], document["modules"]
    summary = (f"**Drift:** {len(drifted)} of {plural(modules, 'module')} hold{'s' if len(drifted) == 1 else ''} something other "
               "than the plant file says (file → module)." if drifted else "**No drift:** every module holds what the plant file says.")  # fmt: skip
    head = "\n".join([DRIFT_MARKER, f"### prc3cfg drift — {code(document['plant'])}", "", summary, "", ""])
    parts = ("\n".join([f"- **{cell(found['bus'])} / {cell(found['name'])}** (address {found['address']})",
                        *(f"  - {cell(text)}" for text in found["differences"]), ""]) for found in drifted)  # fmt: skip

    def closing(left: int, _budget: int) -> str:
        return f"\n… and {plural(left, 'more module')} that drifted: see {full_drift}.\n"

    return _budgeted(head, parts, len(drifted), closing, max_chars, "the drift's summary")


def account(run: ModuleOutcome) -> str | None:
    """What was and was not written to one module, and what a read-back says it holds now (None: a
    module not in the plan that was not looked at — nothing to say)."""
    head = f"bus {run.bus}, module {run.address} ({run.name})"
    if run.verified and not run.steps:
        if not run.watched:
            return None
        return f"✓ {head}: not in the plan; its system parameters read back as they were (a release went out on a line without error detection)"
    if run.verified:
        repaired = f", after {run.repairs} repair round{'s' if run.repairs != 1 else ''}" if run.repairs else ""
        received = f" and {run.broadcasts} broadcast{'s' if run.broadcasts != 1 else ''} received" if run.broadcasts else ""
        return f"✓ {head}: {len(run.written)} message{'s' if len(run.written) != 1 else ''} written{received}, verified{repaired}"
    lines = [f"✗ {head}: {run.failure}"]
    if not run.sent:
        lines.append("    nothing was sent to it")
    else:
        lines.append("    written: " + ("; ".join(s.summary for s in run.written) or "nothing acknowledged"))
        if run.unacknowledged:
            lines.append("    sent, not acknowledged: " + "; ".join(s.summary for s in run.unacknowledged))
        if run.unsent:
            lines.append("    not sent: " + "; ".join(s.summary for s in run.unsent))
    if run.final is None:
        lines.append("    not read back: what the module holds is not known")
    elif run.unchanged:
        lines.append("    read back: unchanged, as before the apply")
    else:
        lines.append("    read back, it differs from the plant file: " + "; ".join(differences(run.final, run.desired)))
    return "\n".join(lines)


#: What the account says of modules whose axes were, or may have been, released.
TRAVEL = "⚠ Travel to reference point required before production on:"


#: How wide the lines of the travel list are, its indent included.
TRAVEL_WIDTH = 100


def travel_list(runs: Sequence[ModuleOutcome]) -> str | None:
    """The modules whose axes were — or may have been — released: they must travel to their reference point.
    The heading, then each bus's modules on lines of their own, indented, wrapped between modules at
    `TRAVEL_WIDTH` (30 modules on a line are no 300-character line)."""
    released = to_travel(runs)
    if not released:
        return None
    lines = [TRAVEL]
    for bus in dict.fromkeys(r.bus for r in released):
        names = [f"{r.bus}/{r.name}" + (" (possibly: its 10h/20h went out unacknowledged)" if r.released is Release.POSSIBLY else "")
                 for r in released if r.bus == bus]  # fmt: skip
        line = "   "
        for n, name in enumerate(names):
            piece = f" {name}" + ("," if n < len(names) - 1 else "")
            if len(line) + len(piece) > TRAVEL_WIDTH and line.strip():
                lines.append(line)
                line = "   "
            line += piece
        lines.append(line)
    return "\n".join(lines)


class Untold(Protocol):
    """What the account reads of an axis release an earlier apply sent and never told of — it was
    killed after its 10h/20h (`prc3cfg.shell.releases.Pending`)."""

    @property
    def bus(self) -> str: ...
    @property
    def name(self) -> str: ...
    @property
    def command(self) -> str: ...
    @property
    def pid(self) -> int: ...
    @property
    def time(self) -> str: ...
    @property
    def journal(self) -> str | None: ...
    @property
    def owner(self) -> str | None: ...


def earlier_releases(records: Iterable[Untold]) -> list[str]:
    """The modules whose axes an earlier apply may have released and ended before saying so: they must travel too
    — another user's record told as their claim; every field escaped, as the file says it (`escape.shown`)."""
    shown = escape.shown
    return [f"{TRAVEL} {shown(r.bus)}/{shown(r.name)} (possibly: " + ("" if r.owner is None else f"{r.owner}'s record says ")
            + f"an earlier prc3cfg {shown(r.command)}, pid {r.pid} at {shown(r.time)}, sent a 10h/20h and ended before its account"
            + (f"; journal {shown(r.journal)})" if r.journal else ")") for r in records]  # fmt: skip


def broadcasts_heard(proofs: Iterable[LineProof], runs: Sequence[ModuleOutcome]) -> list[str]:
    """After an apply, each line that took a broadcast where the probes had found every address the
    plant file does not list silent: only the plan's modules heard it."""
    return [f"Bus {proof.bus}: broadcast after {address_ranges(proof.silent)} answered no probe — only the plan's modules heard it"
            for proof in proofs if proof.silent and any(run.bus == proof.bus and run.broadcasts for run in runs)]  # fmt: skip


# -- what `show` says of a plant file's modules -------------------------------------------------


@dataclass(frozen=True, slots=True)
class Table:
    """A table as `show` lays it out: its title, its columns, and its rows in sections (a line
    between two sections); the terminal draws it."""

    title: str
    columns: tuple[str, ...]
    sections: tuple[tuple[tuple[str, ...], ...], ...]


@dataclass(frozen=True, slots=True)
class ModuleRow:
    """A module as `show PLANT` lists it: where it is, the profiles it takes, the programs it lists."""

    bus: str
    address: int
    name: str
    profiles: tuple[str, ...]
    programs: tuple[int, ...]
    unmanaged_programs: str


def modules_table(plant: str, modules: Iterable[ModuleRow]) -> Table:
    """The modules of a plant, one row each ("-" for no profile, no program listed)."""
    rows = tuple((m.bus, str(m.address), m.name, ", ".join(m.profiles) or "-", ", ".join(map(str, m.programs)) or "-",
                  m.unmanaged_programs) for m in modules)  # fmt: skip
    return Table(f"plant {plant}", ("bus", "address", "module", "profiles", "programs", "unmanaged"), (rows,))


@dataclass(frozen=True, slots=True)
class Settings:
    """What `show PLANT --module NAME` is given of a module: who and where it is, what it should hold
    in device units (`programs`: the listed ones), and where each value came from ("default",
    "profile NAME", "module") — `sources` by plant-file key (system parameters, `unmanaged_programs`,
    `chains`), `program_sources` by program and key (`jump` for A). `chains`: each chain's programs
    and whether it loops."""

    name: str
    bus: str
    address: int
    profiles: tuple[str, ...]
    unmanaged_programs: str
    system: SystemParameters
    programs: Mapping[int, Program]
    sources: Mapping[str, str]
    program_sources: Mapping[int, Mapping[str, str]]
    chains: tuple[tuple[tuple[int, ...], bool], ...]


class Shown(NamedTuple):
    """A module as `show PLANT --module NAME` shows it: its heading — before the name, the name (the
    terminal sets it off), after it — then lines and tables, in order."""

    heading: tuple[str, str, str]
    blocks: list[str | Table]


def _setting(key: str, symbol: str, device: int, source: str) -> tuple[str, str, str, str]:
    """A value's row: its key and symbol, in human units, as the device holds it, where it came from."""
    return f"{key} ({symbol})", human_text(symbol, device), str(device), source


def shown_module(settings: Settings) -> Shown:
    """A module's effective configuration: each value in human units and device units, and where it came from."""
    where = f" — bus {settings.bus}, address {settings.address}, profiles: {', '.join(settings.profiles) or 'none'}"
    unmanaged = f"unmanaged_programs: {settings.unmanaged_programs} ({settings.sources['unmanaged_programs']})"
    system = tuple(_setting(q.key, q.symbol, getattr(settings.system, q.symbol), settings.sources[q.key]) for q in SYSTEM_QUANTITIES)
    sections = []
    for number, program in settings.programs.items():
        sources = settings.program_sources[number]
        rows = [_setting(q.key, q.symbol, getattr(program, q.symbol), sources[q.key]) for q in PROGRAM_QUANTITIES]
        rows += [_setting(symbol.lower(), symbol, getattr(program, symbol), sources[symbol.lower()]) for symbol in FUNCTION_OUTPUTS]
        rows.append(("jump (A)", f"program {program.A}" if program.A else "stop", str(program.A), sources["jump"]))
        sections.append(tuple((str(number) if i == 0 else "", *row) for i, row in enumerate(rows)))
    blocks: list[str | Table] = [
        unmanaged,
        Table("system", ("key", "value", "device", "from"), (system,)),
        Table("programs", ("#", "key", "value", "device", "from"), tuple(sections)),
    ]
    if settings.chains:
        blocks.append(f"chains ({settings.sources['chains']}): {'; '.join(chain_text(*chain) for chain in settings.chains)}")
    return Shown(("module ", settings.name, where), blocks)


def chain_text(programs: Sequence[int], loop: bool) -> str:
    """A chain as a plant file's reader follows it: "1 → 2 → 1 (loop)", "10 → 11 → stop"."""
    steps = [*map(str, programs), str(programs[0]) if loop else "stop"]
    return " → ".join(steps) + (" (loop)" if loop else "")
