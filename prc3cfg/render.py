"""Showing plans to people: the diff in human units, chains as chains, axis warnings.

Owns the words and layout of `plan` output — human (Terraform-like), markdown for pull
request comments, and the `changes` list of the JSON output. Reasons shown here never
steer an apply (the plan's steps do). A module's diff (`ModuleDiff`: its fields, its jumps,
the programs it clamps) is worked out once, by comparing the two images field by field, and
every output of the same plan is made from it (`module_diff` keeps the diffs of the last
`_KEPT_DIFFS` modules). The units are `prc3cfg.plant.units`. Pure: returns strings.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable
from dataclasses import dataclass

from prc3cfg.image import PROGRAM_FIELDS, PROGRAM_NUMBERS, SYSTEM_KEYS, ModuleImage, Program, default_program
from prc3cfg.importer import jumps_as_chains
from prc3cfg.plant.units import BY_SYMBOL, format_function_output
from prc3cfg.plantplan import ModuleChange, PlantPlan

AXIS_WARNING = "releases the axes: travel to reference point required after apply"
CLAMPED = "clamped by the module itself when its system parameters change"
#: The program fields a diff compares: A is shown as jumps (`chain_changes`).
_DIFF_FIELDS = tuple(f for f in PROGRAM_FIELDS if f != "A")
#: Modules whose diff `module_diff` keeps: every module of a plant of 8 buses × 30 modules and more.
_KEPT_DIFFS = 1024


def field_name(symbol: str) -> str:
    """The plant-file key in words: S1 → "upper reversing point", Vr → "relative speed"."""
    return BY_SYMBOL[symbol].key.replace("_", " ") if symbol in BY_SYMBOL else symbol


#: Device ranges of the fields whose range does not depend on the system parameters;
#: a read-back outside them (a damaged or foreign module) is shown raw, never decoded.
_RANGES = {**{q.symbol: (q.lo, q.hi) for q in BY_SYMBOL.values()}, "F1": (0, 1999), "F2": (0, 1999)}


@functools.lru_cache(maxsize=4096)
def format_value(symbol: str, device: int) -> str:
    """A device value in human units: "1.050 m", "set at 0.010 m"; raw when it is out of range."""
    low, high = _RANGES[symbol]
    if not low <= device <= high:
        return f"{device} (raw, outside {low}..{high})"
    if symbol in ("F1", "F2"):
        return format_function_output(device)
    return BY_SYMBOL[symbol].format(device)


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

    def to_json(self) -> dict:
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
    chain_list, nexts = jumps_as_chains({n: image.programs[n - 1] for n in within})
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
    before, after = jumps(actual, managed), jumps(desired, managed)
    return sorted(before - after), sorted(after - before)


def program_symbols(actual: ModuleImage, desired: ModuleImage, numbers: Iterable[int]) -> dict[int, str]:
    """`+` a program set up from factory defaults, `-` one put back to them, `~` otherwise."""
    was, will = default_program(actual.system), default_program(desired.system)
    return {n: "+" if actual.programs[n - 1] == was else "-" if desired.programs[n - 1] == will else "~" for n in numbers}


def clamped_changes(change: ModuleChange) -> list[FieldChange]:
    """What the module's own clamping does to programs the plant does not manage (§4.2)."""
    unmanaged = [n for n, p in enumerate(change.desired.programs, start=1) if p is None]
    return _program_changes(change.actual.programs, change.plan.predicted.programs, unmanaged)


def differences(have: ModuleImage, want: ModuleImage) -> list[str]:
    """Where a module holds something else than the plant file says, "what it holds → what it should"."""
    fields = [f"{'system' if f.program is None else f'program {f.program}'} {f.text}" for f in field_changes(have, want)]
    removed, added = chain_changes(have, want)
    return fields + [f"has {c}" for c in removed] + [f"lacks {c}" for c in added]


@dataclass(frozen=True, slots=True)
class ModuleDiff:
    """What one module's plan changes, as every output shows it: the differing fields (their
    texts made once: a plan of 240 changed modules has 60,000), each changed program's symbol
    (`program_symbols`), the jumps removed and added, and what the module's clamping does to
    programs the plant does not manage."""

    fields: tuple[FieldChange, ...]
    symbols: dict[int, str]
    chains_removed: tuple[str, ...]
    chains_added: tuple[str, ...]
    clamped: tuple[FieldChange, ...]


@functools.lru_cache(maxsize=_KEPT_DIFFS)
def module_diff(change: ModuleChange) -> ModuleDiff:
    """The diff of one module, worked out once for the human, markdown and JSON outputs of a plan."""
    fields = field_changes(change.actual, change.desired)
    removed, added = chain_changes(change.actual, change.desired)
    return ModuleDiff(
        fields=tuple(fields),
        symbols=program_symbols(change.actual, change.desired, {f.program for f in fields if f.program is not None}),
        chains_removed=tuple(removed),
        chains_added=tuple(added),
        clamped=tuple(clamped_changes(change)),
    )


def module_lines(change: ModuleChange) -> list[str]:
    """The diff of one module, one change per line, indented under its header."""
    diff = module_diff(change)
    lines: list[str] = []
    system = [f.text for f in diff.fields if f.program is None]
    if system:
        lines.append(f"~ system: {', '.join(system)}")
    programs: dict[int, list[str]] = {}
    for f in diff.fields:
        if f.program is not None:
            programs.setdefault(f.program, []).append(f.text)
    lines += [f"{diff.symbols[number]} program {number}: {', '.join(texts)}" for number, texts in programs.items()]
    lines += [f"- {c}" for c in diff.chains_removed] + [f"+ {c}" for c in diff.chains_added]
    clamped: dict[int, list[str]] = {}
    for f in diff.clamped:
        clamped.setdefault(f.program, []).append(f.text)
    lines += [f"~ program {n} (not managed, kept): {', '.join(texts)} — {CLAMPED}" for n, texts in clamped.items()]
    return lines


def module_header(change: ModuleChange) -> str:
    head = f"bus {change.bus}, module {change.address} ({change.name})"
    if not change.steps:
        return f"  {head}: no changes"
    warn = f"  ⚠ {AXIS_WARNING}" if change.releases_axes else ""
    return f"~ {head}: {len(change.steps)} steps, {change.plan.bus_time:.3f} s{warn}"


def step_lines(change: ModuleChange) -> list[str]:
    return [
        f"{i:>3}. {step.message.hex():<24} {step.summary}" + ("  ⚠ RELEASES AXES" if step.releases_axes else "")
        for i, step in enumerate(change.steps, start=1)
    ]


def summary_line(plan: PlantPlan) -> str:
    changed = len(plan.changes)
    if not changed:
        return "No changes: every module matches the plant file."
    releases = len(plan.axis_releases)
    return (
        f"Plan: {changed} of {len(plan.modules)} modules change, {plan.message_count} messages, "
        f"estimated bus time {plan.bus_time:.3f} s (naive download {plan.naive_bus_time:.3f} s)"
        + (f"; ⚠ {releases} module{'s' if releases != 1 else ''} release the axes" if releases else "")
    )


def human(plan: PlantPlan, *, steps: bool = True) -> str:
    out = [f"Plant {plan.plant}", ""]
    for change in plan.modules:
        if not change.steps:
            out.append(module_header(change))
            continue
        lines = [module_header(change), *module_lines(change), *(["steps:", *step_lines(change)] if steps else [])]
        out.append("\n    ".join(lines) + "\n")  # one string a module: the lines of 240 would take more
    if plan.axis_releases:
        out.append("⚠ Travel to reference point required after apply on: " + ", ".join(
            f"{m.bus}/{m.name}" for m in plan.axis_releases))  # fmt: skip
    out.append(summary_line(plan))
    return "\n".join(out)


def markdown(plan: PlantPlan) -> str:
    out = [f"### prc3cfg plan — `{plan.plant}`", "", summary_line(plan), ""]
    if plan.axis_releases:
        out += [
            "> [!WARNING]",
            "> These modules release their axes: **travel to reference point required after apply** — "
            + ", ".join(f"`{m.bus}/{m.name}`" for m in plan.axis_releases),
            "",
        ]
    if plan.changes:
        out += ["| bus | module | address | steps | bus time | axes |", "|---|---|---:|---:|---:|---|"]
        for m in plan.changes:
            axes = "⚠ released: travel to reference point required" if m.releases_axes else ""
            out.append(f"| {m.bus} | {m.name} | {m.address} | {len(m.steps)} | {m.plan.bus_time:.3f} s | {axes} |")
        out.append("")
        for m in plan.changes:
            out += [
                f"<details><summary>{m.bus} / {m.name} (address {m.address})"
                + (" ⚠ releases axes" if m.releases_axes else "") + "</summary>",
                "",
                "```diff",
                *module_lines(m),
                "```",
                "",
                "```",
                *step_lines(m),
                "```",
                "</details>",
                "",
            ]
    return "\n".join(out)


def changes_json(change: ModuleChange) -> dict:
    diff = module_diff(change)
    return {
        "fields": [f.to_json() for f in diff.fields],
        "chains_removed": list(diff.chains_removed),
        "chains_added": list(diff.chains_added),
        "clamped": [{**f.to_json(), "reason": CLAMPED} for f in diff.clamped],
        "warning": AXIS_WARNING if change.releases_axes else None,
    }
