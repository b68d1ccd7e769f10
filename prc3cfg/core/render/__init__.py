"""Showing prc3cfg's plans and results to people: the words and layout of everything a person reads.

One module an output, each importing only the ones below it (`words` at the bottom):
- `words`: a field's name and value in human units, two images' differences, a module's diff and step lines,
  counts, and text from a file made safe for markdown — what every output shares;
- `plan_text`: a plan as the terminal shows it, and the headline, evidence and estimate every output of a plan
  says; what a plan file keeps beside a module's steps for people (`review`);
- `markdown`: a plan and drift as pull-request comments, within a comment's size;
- `drift`: what `read` and drift say of modules;
- `account`: the account of an apply, from each module's outcome (`prc3cfg.core.outcome.ModuleOutcome`), and
  the modules that must travel to their reference point;
- `show`: what `show` says of a plant file's modules.

The package's names are its modules' public ones: callers say `render.human`, `render.account`, … wherever the
words live, and `prc3cfg.core.plan_file.write` is given the package as its `Words`. Reasons shown here never
steer an apply (the plan's steps do). Pure: returns strings.
"""

from prc3cfg.core.render.account import (
                                         TRAVEL,
                                         TRAVEL_WIDTH,
                                         Untold,
                                         account,
                                         broadcasts_heard,
                                         earlier_releases,
                                         travel_list,
)
from prc3cfg.core.render.drift import DRIFT_FORMAT, DRIFT_MARKER, Drift, drift_json, drift_lines, image_lines
from prc3cfg.core.render.markdown import COMMENT_BUDGET, MARKER, BudgetTooSmall, drift_markdown, markdown
from prc3cfg.core.render.plan_text import (
                                         CHART,
                                         CHARTS,
                                         EVERY_MODULE,
                                         LEGEND,
                                         PHASES,
                                         REVIEW_AS_WRITTEN,
                                         SAID,
                                         changes_json,
                                         clamped_line,
                                         estimate,
                                         factory_line,
                                         faulted_summary,
                                         human,
                                         line_part,
                                         line_proof,
                                         no_changes,
                                         oldest_taken,
                                         reading_line,
                                         review,
                                         review_line,
                                         summary_line,
                                         timing,
)
from prc3cfg.core.render.show import (
                                         ModuleRow,
                                         Settings,
                                         Shown,
                                         Table,
                                         chain_text,
                                         modules_table,
                                         shown_module,
)
from prc3cfg.core.render.words import (
                                         AXIS_WARNING,
                                         CLAMPED,
                                         JUMPS,
                                         RELEASE_NAMES_BUDGET,
                                         FieldChange,
                                         ModuleDiff,
                                         cell,
                                         chain_changes,
                                         clamped_changes,
                                         code,
                                         differences,
                                         drift_changes,
                                         fenced,
                                         field_changes,
                                         field_name,
                                         format_value,
                                         header_line,
                                         jumps,
                                         module_diff,
                                         module_lines,
                                         plural,
                                         release_summary,
                                         some_of,
                                         step_line,
)

__all__ = [
    "AXIS_WARNING", "CHART", "CHARTS", "CLAMPED", "COMMENT_BUDGET", "DRIFT_FORMAT", "DRIFT_MARKER",
    "EVERY_MODULE", "JUMPS", "LEGEND", "MARKER", "PHASES", "RELEASE_NAMES_BUDGET", "REVIEW_AS_WRITTEN",
    "SAID", "TRAVEL", "TRAVEL_WIDTH", "BudgetTooSmall", "Drift", "FieldChange", "ModuleDiff", "ModuleRow",
    "Settings", "Shown", "Table", "Untold", "account", "broadcasts_heard", "cell", "chain_changes",
    "chain_text", "changes_json", "clamped_changes", "clamped_line", "code", "differences", "drift_changes",
    "drift_json", "drift_lines", "drift_markdown", "earlier_releases", "estimate", "factory_line",
    "faulted_summary", "fenced", "field_changes", "field_name", "format_value", "header_line", "human",
    "image_lines", "jumps", "line_part", "line_proof", "markdown", "module_diff", "module_lines",
    "modules_table", "no_changes", "oldest_taken", "plural", "reading_line", "release_summary", "review",
    "review_line", "shown_module", "some_of", "step_line", "summary_line", "timing", "travel_list",
]
