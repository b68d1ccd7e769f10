"""What is wrong with a plant file: a `Problem` at a place in the document, and `PlantError`.

A `Problem` names its place as a path of keys and indexes from the top of the document (`("buses", 0,
"modules", 2, "programs", 3, "speed")`); the loader turns the path into `file:line:column`. `PlantError`
carries the problems of one file, one printable line each (`shown`): every one, up to `MAX_PROBLEMS`;
`PlantError.findings` the same problems as `Finding`s, for tools.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from prc3cfg.core.text import shown
from prc3cfg.errors import UserError

Path_ = tuple[str | int, ...]
#: Problems listed for one file. A file with more is read no further than needed to know
#: that: it is not the plant file meant, or it is best fixed from the first ones.
MAX_PROBLEMS = 1000
#: Stands in a message for "first at line N", the place of `Problem.first`.
FIRST = "(first)"
#: A number written with a decimal comma: said by `messages` of a text where a number belongs
#: ("2,000") and by `document` of a number that a flow mapping's comma split (`{position: 2,000}`).
DECIMAL_COMMA = "{what} {written} has a decimal comma — write {point} with a point"


@dataclass(frozen=True, slots=True)
class Problem:
    """`message` is "what is wrong — what would be right"; `at_key` points at the key, not its value.

    `at` is a (line, column) known without a path, for what has none (a duplicate key).
    `first` is the earlier of two things that must differ; the message says where it is
    with `FIRST`. `models_fix`: what the models would have the value be (a number in m, one
    of set, reset) is a better "what to do" than this message's own, which cannot know what
    the key wants; the loader puts theirs in when they object to the same value. `modules`: the
    modules a problem of a profile's value is found in (the loader says it once, naming them all).
    """

    path: Path_
    message: str
    at_key: bool = False
    at: tuple[int, int] | None = None
    first: Path_ | None = None
    models_fix: bool = False
    modules: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class Finding:
    """One problem of a plant file at its place: line and column (1-based), or None for the whole file."""

    file: str
    line: int | None
    column: int | None
    message: str


#: The place a problem line starts with, after its file: ":line:column: ", or ": " for the whole file.
_PLACE = re.compile(r":(?:(\d+):(\d+):)? ")


class PlantError(UserError):
    """A plant file that cannot be used; `str()` is every problem, one line each, sorted by line."""

    def __init__(self, problems: Sequence[str]) -> None:
        # what the file holds: one line each, printable
        self.problems = [shown(problem) for problem in problems]
        super().__init__("\n".join(self.problems))

    def findings(self, file: str) -> list[Finding]:
        """The problems of the plant file read as `file` (the path `parse_plant` was given, as text)."""
        found, name = [], shown(file)
        for problem in self.problems:
            place = _PLACE.match(problem, len(name)) if problem.startswith(f"{name}:") else None
            if place is None:  # not "file:…": said whole, of the file
                found.append(Finding(file, None, None, problem))
            elif place.group(1) is None:
                found.append(Finding(file, None, None, problem[place.end():]))
            else:
                found.append(Finding(file, int(place.group(1)), int(place.group(2)), problem[place.end():]))
        return found
