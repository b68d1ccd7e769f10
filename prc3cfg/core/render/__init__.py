"""Showing prc3cfg's plans and results to people: the words and layout of everything a person reads.

One module an output, each importing only the ones below it (`words` at the bottom):
- `words`: a field's name and value in human units, two images' differences, a module's diff and step lines,
  counts, and text from a file made safe for markdown — what every output shares;
- `evidence`: what a plan read now and what it took as known from the line's record — the headline of a plan
  without changes and the line every output of a plan says it in;
- `plan_text`: a plan as the terminal shows it, and the summary and estimate every output of a plan says; what
  a plan file keeps beside a module's steps for people (`review`);
- `comment`: a plan and drift as pull-request comments in markdown, within a comment's size;
- `drift`: what `read` and drift say of modules;
- `applied`: the account of an apply, from each module's outcome (`prc3cfg.core.outcome.ModuleOutcome`), and
  the modules that must travel to their reference point;
- `show`: what `show` says of a plant file's modules.

The package's names are its modules' public ones: callers say `render.human`, `render.account`, … wherever the
words live, and `prc3cfg.core.plan_file.write` is given the package as its `Words`. Each module is imported
the first time one of its names is asked for (PEP 562, as `prc3cfg.api` does): a plan shown on a terminal
loads neither the pull-request comment nor `show`. Reasons shown here never steer an apply (the
plan's steps do). Pure: returns strings. (No module is named as one of the package's names: importing it
would bind its name on the package, hiding that name — the function `account` lives in `applied`.)
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from prc3cfg.core.lazy import lazy_names

if TYPE_CHECKING:
    from prc3cfg.core.render.applied import TRAVEL as TRAVEL
    from prc3cfg.core.render.applied import Untold as Untold
    from prc3cfg.core.render.applied import account as account
    from prc3cfg.core.render.applied import broadcasts_heard as broadcasts_heard
    from prc3cfg.core.render.applied import earlier_releases as earlier_releases
    from prc3cfg.core.render.applied import travel_list as travel_list
    from prc3cfg.core.render.comment import COMMENT_BUDGET as COMMENT_BUDGET
    from prc3cfg.core.render.comment import MARKER as MARKER
    from prc3cfg.core.render.comment import BudgetTooSmall as BudgetTooSmall
    from prc3cfg.core.render.comment import drift_markdown as drift_markdown
    from prc3cfg.core.render.comment import markdown as markdown
    from prc3cfg.core.render.drift import DRIFT_FORMAT as DRIFT_FORMAT
    from prc3cfg.core.render.drift import DRIFT_MARKER as DRIFT_MARKER
    from prc3cfg.core.render.drift import Drift as Drift
    from prc3cfg.core.render.drift import drift_json as drift_json
    from prc3cfg.core.render.drift import drift_lines as drift_lines
    from prc3cfg.core.render.drift import image_lines as image_lines
    from prc3cfg.core.render.evidence import EVERY_MODULE as EVERY_MODULE
    from prc3cfg.core.render.evidence import factory_line as factory_line
    from prc3cfg.core.render.evidence import headline_names_oldest as headline_names_oldest
    from prc3cfg.core.render.evidence import no_changes as no_changes
    from prc3cfg.core.render.evidence import oldest_taken as oldest_taken
    from prc3cfg.core.render.evidence import reading_line as reading_line
    from prc3cfg.core.render.plan_text import AXIS_HEADING as AXIS_HEADING
    from prc3cfg.core.render.plan_text import CHART as CHART
    from prc3cfg.core.render.plan_text import CHARTS as CHARTS
    from prc3cfg.core.render.plan_text import LEGEND as LEGEND
    from prc3cfg.core.render.plan_text import PHASES as PHASES
    from prc3cfg.core.render.plan_text import REVIEW_AS_WRITTEN as REVIEW_AS_WRITTEN
    from prc3cfg.core.render.plan_text import SAID as SAID
    from prc3cfg.core.render.plan_text import changes_json as changes_json
    from prc3cfg.core.render.plan_text import clamped_line as clamped_line
    from prc3cfg.core.render.plan_text import estimate as estimate
    from prc3cfg.core.render.plan_text import faulted_summary as faulted_summary
    from prc3cfg.core.render.plan_text import human as human
    from prc3cfg.core.render.plan_text import line_part as line_part
    from prc3cfg.core.render.plan_text import line_proof as line_proof
    from prc3cfg.core.render.plan_text import review as review
    from prc3cfg.core.render.plan_text import review_line as review_line
    from prc3cfg.core.render.plan_text import summary_line as summary_line
    from prc3cfg.core.render.plan_text import timing as timing
    from prc3cfg.core.render.show import ModuleRow as ModuleRow
    from prc3cfg.core.render.show import Settings as Settings
    from prc3cfg.core.render.show import Shown as Shown
    from prc3cfg.core.render.show import Table as Table
    from prc3cfg.core.render.show import chain_text as chain_text
    from prc3cfg.core.render.show import modules_table as modules_table
    from prc3cfg.core.render.show import shown_module as shown_module
    from prc3cfg.core.render.words import AXIS_WARNING as AXIS_WARNING
    from prc3cfg.core.render.words import CLAMPED as CLAMPED
    from prc3cfg.core.render.words import JUMPS as JUMPS
    from prc3cfg.core.render.words import LIST_WIDTH as LIST_WIDTH
    from prc3cfg.core.render.words import RELEASE_NAMES_BUDGET as RELEASE_NAMES_BUDGET
    from prc3cfg.core.render.words import FieldChange as FieldChange
    from prc3cfg.core.render.words import ModuleDiff as ModuleDiff
    from prc3cfg.core.render.words import cell as cell
    from prc3cfg.core.render.words import chain_changes as chain_changes
    from prc3cfg.core.render.words import clamped_changes as clamped_changes
    from prc3cfg.core.render.words import code as code
    from prc3cfg.core.render.words import differences as differences
    from prc3cfg.core.render.words import drift_changes as drift_changes
    from prc3cfg.core.render.words import fenced as fenced
    from prc3cfg.core.render.words import field_changes as field_changes
    from prc3cfg.core.render.words import field_name as field_name
    from prc3cfg.core.render.words import format_value as format_value
    from prc3cfg.core.render.words import hanging as hanging
    from prc3cfg.core.render.words import header_line as header_line
    from prc3cfg.core.render.words import jumps as jumps
    from prc3cfg.core.render.words import listed as listed
    from prc3cfg.core.render.words import module_diff as module_diff
    from prc3cfg.core.render.words import module_lines as module_lines
    from prc3cfg.core.render.words import plural as plural
    from prc3cfg.core.render.words import release_summary as release_summary
    from prc3cfg.core.render.words import some_of as some_of
    from prc3cfg.core.render.words import step_line as step_line
    from prc3cfg.core.render.words import unchanged_line as unchanged_line

#: Where each name of the package lives (a test checks it against the imports above).
_HOMES: dict[str, tuple[str, ...]] = {
    "prc3cfg.core.render.applied": ("TRAVEL", "Untold", "account", "broadcasts_heard",
                                    "earlier_releases", "travel_list"),
    "prc3cfg.core.render.comment": ("COMMENT_BUDGET", "MARKER", "BudgetTooSmall", "drift_markdown",
                                     "markdown"),
    "prc3cfg.core.render.drift": ("DRIFT_FORMAT", "DRIFT_MARKER", "Drift", "drift_json", "drift_lines",
                                  "image_lines"),
    "prc3cfg.core.render.evidence": ("EVERY_MODULE", "factory_line", "headline_names_oldest", "no_changes",
                                     "oldest_taken", "reading_line"),
    "prc3cfg.core.render.plan_text": ("AXIS_HEADING", "CHART", "CHARTS", "LEGEND", "PHASES",
                                      "REVIEW_AS_WRITTEN", "SAID", "changes_json", "clamped_line", "estimate",
                                      "faulted_summary", "human", "line_part", "line_proof", "review",
                                      "review_line", "summary_line", "timing"),
    "prc3cfg.core.render.show": ("ModuleRow", "Settings", "Shown", "Table", "chain_text", "modules_table",
                                 "shown_module"),
    "prc3cfg.core.render.words": ("AXIS_WARNING", "CLAMPED", "JUMPS", "LIST_WIDTH", "RELEASE_NAMES_BUDGET",
                                  "FieldChange", "ModuleDiff", "cell", "chain_changes", "clamped_changes",
                                  "code", "differences", "drift_changes", "fenced", "field_changes",
                                  "field_name", "format_value", "hanging", "header_line", "jumps", "listed",
                                  "module_diff", "module_lines", "plural", "release_summary", "some_of",
                                  "step_line", "unchanged_line"),
}

__getattr__, __dir__ = lazy_names(globals(), _HOMES)
