"""The words every output of prc3cfg shares: a field's name and value in human units (`field_name`,
`format_value`), two images' differences field by field (`field_changes`, `differences`, `drift_changes`) and
a module's diff (`ModuleDiff`, `module_lines`), a plan document's modules (`modules_in`), a plan's module and
step lines (`header_line`, `step_line`, `unchanged_line`), lists of modules by bus (`listed`), a line broken
for a terminal's width (`hanging`), counts (`plural`, `some_of`), the axis question's summary, and text from a
file made safe for markdown (`cell`, `code`, `fenced`). The units are `prc3cfg.core.units`. Pure: returns
strings."""

from __future__ import annotations

import functools
import re
import textwrap
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from prc3cfg.core import text as escape
from prc3cfg.core.chains import jumps_as_chains
from prc3cfg.core.device import widest_range
from prc3cfg.core.image import PROGRAM_FIELDS, PROGRAM_NUMBERS, SYSTEM_KEYS, ModuleImage, Program
from prc3cfg.core.planner import Action
from prc3cfg.core.plant_plan import ModuleChange
from prc3cfg.core.units import BY_SYMBOL, human_text

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
        return {"program": self.program, "field": self.symbol, "before": self.before, "after": self.after,
                "text": self.text}


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
        # the same jump addresses, the same jumps (`jumps` reads A alone): most plans change none
        return [], []
    before, after = jumps(actual, managed), jumps(desired, managed)
    return sorted(before - after), sorted(after - before)


def clamped_changes(change: ModuleChange) -> list[FieldChange]:
    """What the module's own clamping does to programs the plant does not manage (§4.2)."""
    unmanaged = [n for n, p in enumerate(change.desired.programs, start=1) if p is None]
    return _program_changes(change.actual.programs, change.plan.predicted.programs, unmanaged)


#: A drifted jump's `field` (`drift_changes`): a chain or a jump in words, not a field of a program.
JUMPS = "jumps"


def drift_changes(said: ModuleImage, held: ModuleImage) -> list[dict[str, Any]]:
    """Where a module holds something else than the plant file says, as a change made on the floor — "what the
    file says → what the module holds", the direction `adopt` shows it in: each a field as a plan file's
    `changes` give it (`FieldChange.to_json`: program, field symbol, before and after in device units), or a
    jump (`JUMPS`: before, after a chain in words, null where there is none); `text` the sentence."""
    fields = [f.to_json() | {"text": f"{'system' if f.program is None else f'program {f.program}'} {f.text}"}
              for f in field_changes(said, held)]
    in_module, in_file = chain_changes(held, said)
    return (fields + [{"program": None, "field": JUMPS, "before": None, "after": c,
                       "text": f"{c}: in the module only"} for c in in_module]
            + [{"program": None, "field": JUMPS, "before": c, "after": None,
                "text": f"{c}: in the plant file only"} for c in in_file])


def differences(have: ModuleImage, want: ModuleImage) -> list[str]:
    """Where a module holds something else than the plant file says, "what it holds → what it should"."""
    fields = [f"{'system' if f.program is None else f'program {f.program}'} {f.text}"
              for f in field_changes(have, want)]
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
        actions=Action.of_programs(change.actual, change.desired,
                                   {f.program for f in fields if f.program is not None}),
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
              for number, texts in programs.items()]
    lines += [f"{Action.DELETE} {c}" for c in changes["chains_removed"]]
    lines += [f"{Action.CREATE} {c}" for c in changes["chains_added"]]
    clamped: dict[int, list[str]] = {}
    for f in changes["clamped"]:
        clamped.setdefault(f["program"], []).append(f["text"])
    lines += [f"{Action.UPDATE} program {n} (not managed, kept): {', '.join(texts)} — {CLAMPED}"
              for n, texts in clamped.items()]
    return lines


def modules_in(document: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    return [(bus["name"], module) for bus in document["buses"] for module in bus["modules"]]


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
        if (shown and len(", ".join([*shown, name]))
            + (len(f" and {rest - 1} more") if rest > 1 else 0) > budget):
            return f"{', '.join(shown)} and {rest} more"
        shown.append(name)
    return ", ".join(shown)


def release_summary(names: Sequence[str]) -> list[str]:
    """What the axis question says before it asks, in a few lines whatever the count: how many modules
    release their axes and which (`some_of`), and what that means for production."""
    count = len(names)
    return [
        f"⚠ {plural(count, 'module')} will release {'its' if count == 1 else 'their'} axes (10h/20h): "
        f"{some_of(names)}",
        f"  {'It loses its' if count == 1 else 'Each loses its'} reference point and must travel to it "
        "before production.",
    ]


#: How wide a list of modules is, its indent included: 30 modules of a line are not one line of hundreds of
#: characters.
LIST_WIDTH = 100


def listed(heading: str, groups: Iterable[Sequence[str]]) -> list[str]:
    """`heading`, then each group's names (a bus's modules) on lines of their own, indented, wrapped between
    names within `LIST_WIDTH`."""
    return [heading, *(line for names in groups for line in _packed(names, "    ", "    ", LIST_WIDTH))]


def _packed(items: Sequence[str], first: str, then: str, width: int) -> list[str]:
    """`items` joined by ", " on lines within `width` where they fit (room kept for the comma that ends a
    line), the first line begun with `first`, the others with `then`; an item wider than a line alone on one:
    `listed`'s names and `hanging`'s fields."""
    lines: list[str] = []
    for n, item in enumerate(items):
        if lines and len(lines[-1]) + 2 + len(item) + (n < len(items) - 1) <= width:
            lines[-1] += f", {item}"
        else:
            if lines:
                lines[-1] += ","
            lines.append((then if lines else first) + item)
    return lines


def hanging(line: str, width: int) -> list[str]:
    """`line` as a terminal `width` columns wide shows it best: whole where it fits; else broken after its
    commas, so that each field of a diff, each item of a list, stays whole where it fits a line (and is broken
    at its spaces where not), each line after the first indented to where the text after the first ": "
    begins (two columns in from the line's own indent where that is past half the width). A terminal would
    break it at its edge, mid-word, and go on at its first column. `width` 0: whole."""
    if len(line) <= width or width <= 0:
        return [line]
    indent = len(line) - len(line.lstrip())
    colon = line.find(": ", indent)
    hang = " " * (colon + 2 if 0 <= colon and colon + 2 <= width // 2 else min(indent + 2, width // 2))
    lines = []
    for text in _packed(line.split(", "), "", hang, width):
        # its indent given as one: textwrap drops it before a word too long for its line
        own = text[:len(text) - len(text.lstrip())]
        lines += textwrap.wrap(text.lstrip(), width, initial_indent=own, subsequent_indent=hang,
                               break_long_words=False, break_on_hyphens=False)
    return lines


def header_line(bus: str, address: int, name: str, steps: int, broadcasts: int, seconds: float,
                releases: bool) -> str:
    """A changed module's line in a plan: "~ bus booth-a, module 1 (left): 4 steps, 0.178 s  ⚠ …"."""
    head = f"{Action.of_module(steps)} bus {bus}, module {address} ({name})"
    received = f" ({broadcasts} by broadcast)" if broadcasts else ""
    warn = f"  ⚠ {AXIS_WARNING}" if releases else ""
    return f"{head}: {plural(steps, 'step')}{received}, {seconds:.3f} s{warn}"


def unchanged_line(bus: str, addresses: Sequence[int]) -> str:
    """The modules of a bus that a plan leaves as they are: "  bus a: no changes at addresses 1–4, 6"."""
    return f"{Action.NO_OP} bus {bus}: no changes at {escape.address_ranges(addresses)}"


def step_line(index: int, message_hex: str | None, summary: str, releases: bool, broadcast: bool) -> str:
    """One step: number, the message as sent (`--frames`: its bytes in hex; None: left out), what it does,
    and what it means for the axes."""
    frame = "" if message_hex is None else f"{message_hex:<24} "
    return (f"{index:>3}. {frame}{summary}" + ("  (broadcast)" if broadcast else "")
            + ("  ⚠ RELEASES AXES" if releases else ""))


def cell(text: str) -> str:
    """Text from a file for a markdown table cell or paragraph: shown as written, nothing in it live
    (`text.markdown`)."""
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
    """`lines` as a markdown fenced block: its fence longer than any run of backticks in them, so no line
    closes it."""
    fence = "`" * max(3, max((len(run) + 1 for line in lines for run in re.findall("`+", line)), default=0))
    return [fence + info, *lines, fence]
