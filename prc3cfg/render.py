"""Showing plans to people: the diff in human units, chains as chains, axis warnings.

Owns the words and layout of `plan` output — human (Terraform-like), markdown for pull
request comments, and the `changes` list of the JSON output. Reasons shown here never
steer an apply (the plan's steps do). The structural diff is deepdiff's; the units are
`prc3cfg.plant.units`. Pure: returns strings.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from prc3cfg.image import ModuleImage, default_program
from prc3cfg.importer import jumps_as_chains
from prc3cfg.plant.units import BY_SYMBOL, format_function_output
from prc3cfg.plantplan import ModuleChange, PlantPlan

AXIS_WARNING = "releases the axes: travel to reference point required after apply"
CLAMPED = "clamped by the module itself when its system parameters change"
_PATH = re.compile(r"root\['(system|programs)'\](?:\[(\d+)\])?(?:\['(\w+)'\])?")


def field_name(symbol: str) -> str:
    """The plant-file key in words: S1 → "upper reversing point", Vr → "relative speed"."""
    return BY_SYMBOL[symbol].key.replace("_", " ") if symbol in BY_SYMBOL else symbol


#: Device ranges of the fields whose range does not depend on the system parameters;
#: a read-back outside them (a damaged or foreign module) is shown raw, never decoded.
_RANGES = {**{q.symbol: (q.lo, q.hi) for q in BY_SYMBOL.values()}, "F1": (0, 1999), "F2": (0, 1999)}


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
    program: int | None  # None: a system parameter
    symbol: str
    before: int
    after: int

    def text(self) -> str:
        return f"{field_name(self.symbol)} {format_value(self.symbol, self.before)} → {format_value(self.symbol, self.after)}"

    def to_json(self) -> dict:
        return {"program": self.program, "field": self.symbol, "before": self.before, "after": self.after}


def field_changes(actual: ModuleImage, desired: ModuleImage) -> list[FieldChange]:
    """Every differing system parameter and program field (A excluded: see `chain_changes`)."""
    from deepdiff import DeepDiff  # imported here: it loads numpy, which every command would pay for

    diff = DeepDiff(actual.to_json(), desired.to_json(), ignore_order=False)
    changes = []
    for path, change in diff.get("values_changed", {}).items():
        match = _PATH.fullmatch(path)
        if match is None or match.group(3) == "A":
            continue
        section, index, key = match.groups()
        program = None if section == "system" else int(index) + 1
        changes.append(FieldChange(program, key, change["old_value"], change["new_value"]))
    return sorted(changes, key=lambda c: (c.program or 0, list(BY_SYMBOL).index(c.symbol) if c.symbol in BY_SYMBOL else 99))


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


def program_symbol(actual: ModuleImage, desired: ModuleImage, number: int) -> str:
    """`+` a program set up from factory defaults, `-` one put back to them, `~` otherwise."""
    if actual.programs[number - 1] == default_program(actual.system):
        return "+"
    if desired.programs[number - 1] == default_program(desired.system):
        return "-"
    return "~"


def clamped_changes(change: ModuleChange) -> list[FieldChange]:
    """What the module's own clamping does to programs the plant does not manage (§4.2)."""
    unmanaged = change.actual.with_programs(
        {n: None for n, p in enumerate(change.desired.programs, start=1) if p is not None}
    )
    predicted = change.plan.predicted.with_programs(
        {n: None for n, p in enumerate(change.desired.programs, start=1) if p is not None}
    )
    return [f for f in field_changes(unmanaged, predicted) if f.program is not None]


def differences(have: ModuleImage, want: ModuleImage) -> list[str]:
    """Where a module holds something else than the plant file says, "what it holds → what it should"."""
    fields = [f"{'system' if f.program is None else f'program {f.program}'} {f.text()}" for f in field_changes(have, want)]
    removed, added = chain_changes(have, want)
    return fields + [f"has {c}" for c in removed] + [f"lacks {c}" for c in added]


def module_lines(change: ModuleChange) -> list[str]:
    """The diff of one module, one change per line, indented under its header."""
    lines: list[str] = []
    fields = field_changes(change.actual, change.desired)
    system = [f.text() for f in fields if f.program is None]
    if system:
        lines.append(f"~ system: {', '.join(system)}")
    programs: dict[int, list[str]] = {}
    for f in fields:
        if f.program is not None:
            programs.setdefault(f.program, []).append(f.text())
    for number, texts in sorted(programs.items()):
        lines.append(f"{program_symbol(change.actual, change.desired, number)} program {number}: {', '.join(texts)}")
    removed, added = chain_changes(change.actual, change.desired)
    lines += [f"- {c}" for c in removed] + [f"+ {c}" for c in added]
    clamped: dict[int, list[str]] = {}
    for f in clamped_changes(change):
        clamped.setdefault(f.program, []).append(f.text())
    lines += [f"~ program {n} (not managed, kept): {', '.join(texts)} — {CLAMPED}" for n, texts in sorted(clamped.items())]
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
        out.append(module_header(change))
        if change.steps:
            out += [f"    {line}" for line in module_lines(change)]
            if steps:
                out += ["    steps:"] + [f"    {line}" for line in step_lines(change)]
            out.append("")
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
    removed, added = chain_changes(change.actual, change.desired)
    return {
        "fields": [f.to_json() | {"text": f.text()} for f in field_changes(change.actual, change.desired)],
        "chains_removed": removed,
        "chains_added": added,
        "clamped": [f.to_json() | {"text": f.text(), "reason": CLAMPED} for f in clamped_changes(change)],
        "warning": AXIS_WARNING if change.releases_axes else None,
    }
