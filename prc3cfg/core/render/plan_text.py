"""A plan as the terminal shows it (`human`, `line_part`) and the words around it that every output of a plan
says: the headline (`summary_line`; its evidence is `evidence`'s), the review (`review_line`), the clamped
programs, each bus's broadcasts and line proof, the estimate and the time taken;
and what a plan file keeps beside a module's steps for people (`changes_json`, `review`, which
`prc3cfg.core.plan_file.write` is given).

A plan is shown from its document (`outline`: a plan file's, or a live plan's), each module's diff worked out
as it is shown (`changes_of`: kept for all 240 modules of a large plant, the diffs would hold 20 MB). Every
text a plan or plan file brings (names, the base, notes, a field's words) is shown escaped
(`prc3cfg.core.text`), and a plan file's stroke charts only in the shape prc3cfg writes them (`CHART`): a plan
file is data anyone may have edited. Reasons shown here never steer an apply (the plan's steps do). Pure:
returns strings.
"""

from __future__ import annotations

import re
import shlex
from collections.abc import Callable, Collection, Iterable, Sequence
from typing import Any

from prc3cfg.core import plan_file
from prc3cfg.core import text as escape
from prc3cfg.core.motion import MotionError, paired_chains
from prc3cfg.core.planner import Action
from prc3cfg.core.plant_plan import ModuleChange, PlantPlan
from prc3cfg.core.plot import AFTER, BEFORE, mermaid
from prc3cfg.core.render.evidence import factory_line, headline_names_oldest, no_changes, reading_line
from prc3cfg.core.render.words import (
    AXIS_WARNING,
    CLAMPED,
    clamped_changes,
    code,
    header_line,
    listed,
    module_diff,
    module_lines,
    modules_in,
    plural,
    some_of,
    step_line,
    unchanged_line,
)
from prc3cfg.core.text import address_ranges


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


def outline(plan: PlantPlan | dict[str, Any],
            notes: Iterable[str]) -> tuple[dict[str, Any], dict[tuple[str, int], ModuleChange]]:
    """What the human and markdown outputs are made from, every text in it `shown`: a plan file's
    document, or a live plan's without its read-backs' hashes (neither output shows one) and without the
    modules' `changes`, each worked out by `changes_of` as its module is shown (all of them at once, for
    8 × 30 modules with every program changed, hold 35 MB), with the changes by (bus, address) — the
    bus's name as the document has it."""
    if isinstance(plan, dict):
        return _plain_texts(plan), {}
    document = plan_file.to_json(plan, hashes=False) | {"left_alone": list(notes)}
    return _plain_names(document), {(escape.shown(c.bus), c.address): c for c in plan.changes}


def _plain_names(document: dict[str, Any]) -> dict[str, Any]:
    """A live plan's document with the texts files gave it `shown`: its names, its base, its notes (the words
    of its steps are prc3cfg's own; a plan file's are not: `_plain_texts`)."""
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
    r"|\n_[0-9]+ more chains? changed: `prc3cfg show PLANT --module [^`\n]* --plot FILE\.svg` draws "
    r"them all\._|"
)


def _plain_texts(value: Any) -> Any:
    """`value` with every text in it `shown`, and of `charts` only what `CHART` matches."""
    if isinstance(value, str):
        return escape.shown(value)
    if isinstance(value, list):
        return [_plain_texts(item) for item in value]
    if isinstance(value, dict):
        return {key: [c for c in item if isinstance(c, str) and CHART.fullmatch(c)]
                if key == "charts" and isinstance(item, list) else _plain_texts(item)
                for key, item in value.items()}
    return value


def changes_of(bus: str, module: dict[str, Any], live: dict[tuple[str, int], ModuleChange], *,
               charts: bool = True) -> dict[str, Any]:
    """A module's `changes` (`changes_json`): the plan file's, or worked out now from the live plan (without
    its `charts` when not asked for)."""
    return changes_json(live[(bus, module["address"])], charts=charts) if live else module["changes"]


def _header(bus: str, module: dict[str, Any]) -> str:
    steps = module["steps"]
    return header_line(bus, module["address"], module["name"], len(steps),
                       sum(bool(s.get("broadcast")) for s in steps),
                       module.get("estimated_bus_time_s", 0.0), module["releases_axes"])


def step_lines(module: dict[str, Any], frames: bool) -> list[str]:
    return [step_line(i, s["message"] if frames else None, s["summary"], s["releases_axes"],
                      bool(s.get("broadcast")))
            for i, s in enumerate(module["steps"], start=1)]


def line_proof(bus: dict[str, Any], shown: Callable[[str], str] = escape.shown) -> str | None:
    """What the probes of a bus's line found at the addresses its plant file does not list, in one line
    (the bus's name `shown` as the medium needs)."""
    if bus.get("unlisted_modules"):
        return (f"⚠ bus {shown(bus['name'])}: a module answers at "
                f"{address_ranges(bus['unlisted_modules'])}, which the plant file does not "
                "list — the line has modules the plant does not know, so it gets no broadcast: add them to "
                "the plant file, "
                "or drop only_these_modules")
    if bus.get("proven_silent"):
        return (f"bus {shown(bus['name'])}: {address_ranges(bus['proven_silent'])} answered no probe — the "
                "broadcasts reach the plan's modules only")
    return None


def broadcast_lines(bus: dict[str, Any], frames: bool) -> list[str]:
    """A bus's broadcasts, once: one step for all of its modules — and what proved nobody else hears them."""
    steps = bus.get("broadcasts", [])
    proof = line_proof(bus)
    if not steps:
        return [proof, ""] if proof else []
    head = (f"~ bus {bus['name']}: {plural(len(steps), 'broadcast')} to all {len(steps[0]['modules'])} "
            "modules (address 0), each verified by reading back")
    lines = (step_line(i, s["message"] if frames else None, s["summary"], s["releases_axes"], True)
             for i, s in enumerate(steps, 1))
    return [head, *(f"    {line}" for line in lines),
            *([f"    {proof}"] if proof else []), ""]


#: The phases of an apply as the operator reads them (`PlantPlan.phases`).
PHASES = {"reading": "reading back", "writing": "writing", "verifying": "verifying"}


def summary_line(document: dict[str, Any], shown: Callable[[str], str] = escape.shown) -> str:
    """The plan's headline: what changes and what it costs — or that nothing does, and on what evidence
    (`no_changes`), its texts `shown` as the medium needs."""
    modules = modules_in(document)
    changed = sum(1 for _, m in modules if m["steps"])
    if not changed:
        return no_changes(document.get("evidence"), shown)
    releases = len(document["axis_releases"])
    return (
        f"Plan: {changed} of {plural(len(modules), 'module')} change{'s' if changed == 1 else ''}, "
        f"{plural(document['message_count'], 'message')}, " + estimate(document)
        + (f"; ⚠ {plural(releases, 'module')} release{'s' if releases == 1 else ''} the axes" if releases
           else "")
    )


def clamped_line(document: dict[str, Any], live: dict[tuple[str, int], ModuleChange]) -> str | None:
    """How many programs the plant does not manage the modules' own clamping changes, and on how many modules,
    in one line — said by every output whatever it leaves out of the details; None where there are none."""
    if live:
        counts = [len({f.program for f in clamped_changes(change)}) for change in live.values()]
    else:
        counts = [len({f["program"] for f in m.get("changes", {}).get("clamped", [])})
                  for _, m in modules_in(document)]
    programs, modules = sum(counts), sum(1 for count in counts if count)
    if not programs:
        return None
    return (f"⚠ {plural(programs, 'program')} the plant does not manage {'is' if programs == 1 else 'are'} "
            "clamped by "
            f"{plural(modules, 'module')} as {'its' if modules == 1 else 'their'} system parameters change "
            "(unmanaged_programs: keep) — each module's diff lists them")


def estimate(document: dict[str, Any]) -> str:
    """The time an apply of the plan takes, the total first, then by phase, with the writes' bus time
    beside the naive download's: "estimated time 9.6 s: reading back 4.1 s, writing 1.1 s (bus time
    1.099 s, naive download 1.149 s), verifying 4.4 s" (a plan file without phases: the bus times)."""
    bus_times = (f"bus time {document['estimated_bus_time_s']:.3f} s, naive download "
                 f"{document['naive_bus_time_s']:.3f} s")
    phases = document.get("estimated_phases_s")
    if not isinstance(phases, dict):
        return f"estimated {bus_times}"
    # a plan file may lack either
    total = document.get("estimated_time_s", sum(phases[phase] for phase in PHASES))
    return (f"estimated time {total:.1f} s: {PHASES['reading']} {phases['reading']:.1f} s, "
            f"{PHASES['writing']} {phases['writing']:.1f} s ({bus_times}), {PHASES['verifying']} "
            f"{phases['verifying']:.1f} s")


#: How a module's diff is shown where its review text is not the text its digest was written for: as the
#: file's words.
SAID = "the plan file says: "
#: What `show` says of a plan file whose every module's review is the text its digest was written for.
REVIEW_AS_WRITTEN = ("Review: the review text is as the plan was made (each module's review_sha256 matches "
                     "it) — apply --plan proves the steps")


def review_line(document: dict[str, Any], shown: Callable[[str], str] = escape.shown) -> str | None:
    """What `show` says of a plan file's review text, judged by `plan_file.to_show` (each module's `review`):
    that it is the text its digests were written for — or which modules' review was changed since, or has no
    digest, whose words are then shown as the file's (`SAID`), the steps being what `apply --plan` proves.
    None for a document nobody judged (a live plan's)."""
    judged = [(bus, m) for bus, m in modules_in(document) if "review" in m]
    if not judged:
        return None
    changed = [f"{shown(bus)}/{shown(m['name'])}" for bus, m in judged
               if m["review"] == plan_file.Review.CHANGED]
    undigested = [f"{shown(bus)}/{shown(m['name'])}" for bus, m in judged
                  if m["review"] == plan_file.Review.NO_DIGEST]
    if not changed and not undigested:
        return REVIEW_AS_WRITTEN
    parts = ([f"⚠ the review text of {some_of(changed)} was changed after the plan was made"] if changed
             else [])
    parts += [f"⚠ {some_of(undigested)}: no review digest (made by an older prc3cfg)"] if undigested else []
    return ("; ".join(parts)
            + (f" — its diff is shown as the file's words (\"{SAID.strip()}\"); the steps are what apply "
               "--plan proves: read "
                               "the steps (apply --plan refuses this file: plan again)"))


def as_written(module: dict[str, Any]) -> bool:
    """Whether a module's review is the text its digest was written for (a live plan's: prc3cfg's own,
    now)."""
    return bool(module.get("review", plan_file.Review.AS_WRITTEN) == plan_file.Review.AS_WRITTEN)


def as_reviewed(module: dict[str, Any], lines: list[str]) -> list[str]:
    """A module's diff lines, each after `SAID` where its review is not the text its digest was written
    for."""
    return lines if as_written(module) else [SAID + line for line in lines]


def timing(estimated: dict[str, float], took: dict[str, float]) -> str:
    """An apply's time, estimated against taken, in total and by phase, in one line: "Time: 6.4 s
    (estimated 6.0 s) — reading back 5.0 s (4.9 s), writing 0.7 s (0.6 s), verifying 0.7 s (0.5 s)"."""
    phases = ", ".join(f"{words} {took[phase]:.1f} s ({estimated[phase]:.1f} s)"
                       for phase, words in PHASES.items())
    return f"Time: {sum(took.values()):.1f} s (estimated {sum(estimated.values()):.1f} s) — {phases}"


def faulted_summary(document: dict[str, Any], faults: Sequence[str],
                    shown: Callable[[str], str] = escape.shown) -> list[str]:
    """The summary, with the modules a write found in a fault state (`faults`: "bus/module is in E21 (…)",
    kept in the records until a write to it is acknowledged): a plan with nothing to write for them does
    not say all is well — its headline names the fault."""
    said = [f"⚠ {shown(fault)} — a read cannot tell whether it still is: clear the fault on the module"
            for fault in faults]
    if faults and not any(m["steps"] for _, m in modules_in(document)):
        return [f"No changes to write, but {plural(len(faults), 'module')} reported a fault state:", *said]
    return [summary_line(document, shown), *said]


def human(plan: PlantPlan | dict[str, Any], *, notes: Iterable[str] = (), shown: Collection[str] = (),
          faults: Sequence[str] = (), frames: bool = False) -> str:
    """A plan (or a plan file's document) as the terminal shows it: per module its diff and steps,
    each bus's broadcasts once, the reference-travel warning, what stays as it is, the summary. The
    buses `shown` already (`line_part`, as their writes began) are named, not shown again. `frames`:
    each step's bytes in hex too (the plan file always keeps them)."""
    document, live = outline(plan, notes)
    out = [f"Plant {document['plant']}", ""]
    for bus in document["buses"]:
        out += (broadcast_lines(bus, frames) if bus["name"] not in shown
                else [f"bus {bus['name']}: its plan is shown above, as its writes began", ""])
    out += _module_sections(document, live, frames, shown) + _releases(document, shown)
    out += [line for line in [clamped_line(document, live)] if line]
    out += faulted_summary(document, faults)
    out += [line for line in [reading_line(document, claimed=isinstance(plan, dict),
                                           oldest=not headline_names_oldest(document, faults)),
                              factory_line(document), review_line(document)] if line]
    out += [f"Left as it is: {note}" for note in document.get("left_alone", [])]
    if any(module["steps"] for _, module in modules_in(document)):
        out.append(LEGEND)
    return "\n".join(out)


def line_part(plan: PlantPlan, frames: bool = False) -> str:
    """One line's plan (`plan` holds its modules only), shown as its writes begin while the other lines are
    still read (`apply --auto-approve --allow-axis-release`): its broadcasts, its modules, its axis releases.
    """
    document, live = outline(plan, ())
    out = [f"Writing bus {', '.join(bus['name'] for bus in document['buses'])} now, as planned:", ""]
    for bus in document["buses"]:
        out += broadcast_lines(bus, frames)
    out += _module_sections(document, live, frames) + _releases(document)
    return "\n".join(out)


#: The heading of a plan's list of the modules whose axes it releases.
AXIS_HEADING = "⚠ Travel to reference point required after apply on:"


def _releases(document: dict[str, Any], shown: Collection[str] = ()) -> list[str]:
    """The modules whose axes the plan releases, each bus's on lines of their own (`listed`) — but for the
    buses `shown` already, whose `line_part` listed them."""
    groups = [names for bus in document["buses"] if bus["name"] not in shown
              and (names := [f"{bus['name']}/{m['name']}" for m in bus["modules"] if m["releases_axes"]])]
    return listed(AXIS_HEADING, groups) if groups else []


def _module_sections(document: dict[str, Any], live: dict[tuple[str, int], ModuleChange], frames: bool,
                     shown: Collection[str] = ()) -> list[str]:
    """Each bus's changed modules, their diff and steps, then one line naming those without changes (a change
    to one module of 30 is not one section among 29 lines); the buses `shown` left out."""
    out = []
    for bus in document["buses"]:
        if (name := bus["name"]) in shown:
            continue
        for module in bus["modules"]:
            if module["steps"]:
                diff = as_reviewed(module, module_lines(changes_of(name, module, live, charts=False)))
                lines = [_header(name, module), *diff, "steps:", *step_lines(module, frames)]
                out.append("\n    ".join(lines) + "\n")  # a string a module: the lines of 240 would take more
        if unchanged := [module["address"] for module in bus["modules"] if not module["steps"]]:
            out.append(unchanged_line(name, unchanged))
    return out


#: What the marks of a plan mean (`Action`) — one vocabulary for a change, in every output that shows one.
LEGEND = (f"Marks: {Action.UPDATE} changed · {Action.CREATE} set up from factory defaults (a jump: made) · "
          f"{Action.DELETE} put back to factory defaults (a jump: no longer made) · ⚠ releases the axes")


#: Stroke charts (mermaid, about 1 KB each) a module's details show at most.
CHARTS = 3


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
