"""A plan and drift as pull-request comments (`markdown`, `drift_markdown`): within a comment's size
(`COMMENT_BUDGET`, `--max-chars`), the summary, warnings and table always, each module's details — with a
stroke chart per changed chain — while they fit, and a last line that says how many were left out. Every text
from a file is escaped for markdown (`cell`, `code`). Pure: returns strings.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any

from prc3cfg.core import text as escape
from prc3cfg.core.plant_plan import ModuleChange, PlantPlan
from prc3cfg.core.render.drift import DRIFT_MARKER
from prc3cfg.core.render.evidence import factory_line, headline_names_oldest, reading_line
from prc3cfg.core.render.plan_text import (
    as_reviewed,
    as_written,
    broadcast_lines,
    changes_of,
    clamped_line,
    faulted_summary,
    line_proof,
    outline,
    review_line,
    step_lines,
)
from prc3cfg.core.render.words import cell, code, fenced, module_lines, modules_in, plural
from prc3cfg.errors import UserError

#: Marks the pull-request comment a plan is posted as, so that CI updates it instead of adding one.
MARKER = "<!-- prc3cfg-plan -->"
#: What a GitHub comment holds, with room to spare (65,536 characters).
COMMENT_BUDGET = 65_000


class BudgetTooSmall(UserError):
    """`--max-chars` below what a comment never leaves out; `needed` is the least it takes."""

    def __init__(self, max_chars: int, what: str, needed: int) -> None:
        super().__init__(f"--max-chars {max_chars:,} cannot hold {what} ({needed:,} characters, never "
                         "left out) — "
                         f"give --max-chars {needed} or more")
        self.needed = needed


def _budgeted(head: str, parts: Iterable[str], count: int, closing: Callable[[int, int], str], max_chars: int,
              what: str) -> str:
    """`head`, then each of the `count` `parts` while it fits in `max_chars` characters with the
    `closing` line that says how many were left out (none when all are shown; it may name the
    budget): the comment as printed, its last line end counted. `BudgetTooSmall` where `head` and
    the closing of all left out do not fit, with the least budget that holds them.

    Before each part, what is taken and the closing of the parts from it on fit (for the first part,
    the check below; for each next, the previous part's), so the comment never exceeds the budget."""
    if count and len(head) + len(closing(count, max_chars)) > max_chars:
        needed = len(head)
        # the closing may name the budget: its own digits
        while (more := len(head) + len(closing(count, needed))) > needed:
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
             full_plan: str = "the plan file", faults: Sequence[str] = (), frames: bool = False) -> str:
    """A plan (or a plan file's document) as a pull-request comment of at most `max_chars` characters
    as printed (its last line end counted): the marker, the summary, every axis-release warning, how
    many programs are clamped, what was not read, what is left as it is and the table of changed
    modules always — `BudgetTooSmall` where they do not fit; then each module's details (with a stroke
    chart per changed chain, for a live plan) while they fit, and a last line saying how many were
    left out and where the full plan is. `frames`: each step's bytes in hex too."""
    document, live = outline(plan, notes)
    changed = [(bus, m) for bus, m in modules_in(document) if m["steps"]]
    head = [MARKER, f"### prc3cfg plan — {code(document['plant'])}", "",
            *faulted_summary(document, faults, cell), "",
            *_callouts(document, live, claimed=isinstance(plan, dict),
                       oldest=not headline_names_oldest(document, faults)), *_changed_table(changed)]
    for bus in document["buses"]:
        if lines := broadcast_lines(bus, frames):
            head += [*fenced(lines[:-1]), ""]

    def closing(left: int, budget: int) -> str:
        return (f"\n_The details of {plural(left, 'module')} are left out to keep this comment under "
                f"{budget:,} characters: the full plan is {full_plan}._\n")

    return _budgeted("\n".join(head).rstrip("\n") + "\n",
                     (_details(bus, m, live, frames) for bus, m in changed), len(changed), closing,
                     max_chars, "the plan's summary, warnings and table of changed modules")


def _callouts(document: dict[str, Any], live: dict[tuple[str, int], ModuleChange], *,
              claimed: bool, oldest: bool) -> list[str]:
    """A comment's quoted paragraphs under its summary, each only when it has something to say: what was
    not read (`oldest`: with the oldest value taken), the axis-release warning, the clamped programs, what is
    left as it is, each line's proof."""
    out = [f"> {line}", ""] if (line := reading_line(document, cell, claimed=claimed, oldest=oldest)) else []
    out += [f"> {line}", ""] if (line := factory_line(document)) else []
    out += [f"> {line}", ""] if (line := review_line(document, cell)) else []
    if document["axis_releases"]:
        out += ["> [!WARNING]",
                "> These modules release their axes: **travel to reference point required after apply** — "
                + ", ".join(code(name) for name in document["axis_releases"]), ""]
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
                   f"{m.get('estimated_bus_time_s', 0.0):.3f} s | {axes} |")
    return [*out, ""]


def _details(bus: str, m: dict[str, Any], live: dict[tuple[str, int], ModuleChange], frames: bool) -> str:
    changes = changes_of(bus, m, live)
    diff = as_reviewed(m, module_lines(changes))
    return "\n".join([
        f"<details><summary>{escape.markdown_html(bus)} / {escape.markdown_html(m['name'])} (address "
        f"{m['address']})"
        + (" ⚠ releases axes" if m["releases_axes"] else "") + "</summary>",
        "",
        *fenced(diff, "diff"),
        "",
        *fenced(step_lines(m, frames)),
        # pictures of words that are only the file's: not drawn
        *(changes.get("charts", []) if as_written(m) else []),
        "</details>",
        "",
        "",
    ])


def drift_markdown(document: dict[str, Any], *, max_chars: int = COMMENT_BUDGET,
                   full_drift: str = "the drift file") -> str:
    """Drift as a pull-request comment of at most `max_chars` characters: the marker, the summary,
    then each module's differences while they fit, and how many were left out. Every text from the
    plant file or the modules is escaped (`cell`): nothing in it is live."""
    drifted, modules = document["drifted"], document["modules"]
    summary = (f"**Drift:** {len(drifted)} of {plural(modules, 'module')} "
               f"hold{'s' if len(drifted) == 1 else ''} something other "
               "than the plant file says (file → module)." if drifted
               else "**No drift:** every module holds what the plant file says.")
    head = "\n".join([DRIFT_MARKER, f"### prc3cfg drift — {code(document['plant'])}", "", summary, "", ""])
    parts = ("\n".join([f"- **{cell(found['bus'])} / {cell(found['name'])}** (address {found['address']})",
                        *(f"  - {cell(text)}" for text in found["differences"]), ""]) for found in drifted)

    def closing(left: int, _budget: int) -> str:
        return f"\n… and {plural(left, 'more module')} that drifted: see {full_drift}.\n"

    return _budgeted(head, parts, len(drifted), closing, max_chars, "the drift's summary")
