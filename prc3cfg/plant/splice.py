"""A plant file's text with values set in it: spliced, never dumped (`adopt` rewrites a file by it).

    text = rewrite(text, wanted)   # wanted: path → value, a trie ({"buses": {0: {"modules": …}}})

The text is read once more by the loader's own reader (`document.spans`) for the exact span of
every scalar and collection. A value at a path the file has replaces the text of its scalar (with
as many decimals as it had, more only where the value needs them; quotes and case kept); a path
it does not have is a new key, inserted as text in the style of the file: into a flow mapping as
`, key: value`, into a block mapping as lines at its indentation after the entry it follows
(program numbers and fields in their usual order, `KEY_ORDER`), nested mappings flow or block as
the file writes them (`_Conventions`). A comment lined up after a value that changed length stays
in its column. Every other byte — comments, quoting, layout, line ends — stays as it was. Offsets
are those of the text after a byte order mark, which is taken off before parsing and put back
after: libyaml does not count it, the pure parser does. Values are as a plant file holds them
(`units.plant_value`): numbers, text, and mappings for a new program or an F1/F2. Does not know
what a value means nor whether the new text still loads: `adopt` checks that. Pure: text in, text out.
"""

from __future__ import annotations

import re
from collections import Counter
from decimal import Decimal
from typing import Any

from prc3cfg.core.units import QUANTITIES
from prc3cfg.plant.document import Span, spans
from prc3cfg.plant.models import FunctionOutputSpec, ProgramSpec, SystemSpec
from prc3cfg.plant.problems import Path_
from prc3cfg.plant.scalars import DECIMAL_NUMBER, core_schema

#: The order keys are written in where a key is added: a module's own keys as docs/plant-files.md's
#: plant files write them, then the models' order of system, program and F1/F2 keys.
KEY_ORDER = ("address", "name", "profiles", "unmanaged_programs", "system", "programs", "chains",
             *SystemSpec.model_fields, *ProgramSpec.model_fields, *FunctionOutputSpec.model_fields)
#: How a new mapping of each kind is written when the file has none of that kind to follow.
DEFAULT_FLOW = {"system": False, "programs": False, "program": True, "output": True}
DEFAULT_INDENT = 2
#: What may follow the last value on a line before a comment lined up with others: closing
#: brackets and commas, two spaces or more, the comment.
_ALIGNED_COMMENT = re.compile(r"[]},]*( {2,})#")
BYTE_ORDER_MARK = "\ufeff"


def rewrite(text: str, wanted: dict[Any, Any]) -> str:
    """`text` with each value of the trie `wanted` set at its path: replaced where the file has it, added
    where not."""
    return _Rewrite(text).apply(wanted)


def _kind(path: Path_) -> str | None:
    """What a mapping at `path` is within a profile or module: system, programs, program, output."""
    if path[:1] == ("profiles",):
        within = path[2:]
    elif path[:1] == ("buses",) and path[2:3] == ("modules",):
        within = path[4:]
    else:
        return None
    if within in (("system",), ("programs",)):
        return within[0]
    if len(within) == 2 and within[0] == "programs":
        return "program"
    if len(within) == 3 and within[0] == "programs" and within[2] in ("f1", "f2"):
        return "output"
    return None


def _decimals(written: str) -> int:
    return len(written.partition(".")[2])


class _Conventions:
    """How the file writes things: decimals by key, flow or block by kind of mapping, the indentation step."""

    def __init__(self, text: str, root: Span) -> None:
        self.decimals: dict[Any, Counter[int]] = {}
        self.flow: dict[str, Counter[bool]] = {}
        self.steps: Counter[int] = Counter()
        self._walk(text, root, ())

    def _walk(self, text: str, node: Span, path: Path_) -> None:
        for key, child in node.items():
            if child.written is not None:
                if child.plain and DECIMAL_NUMBER.fullmatch(child.written):
                    self.decimals.setdefault(key, Counter())[_decimals(child.written)] += 1
                continue
            if isinstance(child.children, dict):
                if (kind := _kind(path + (key,))) is not None:
                    self.flow.setdefault(kind, Counter())[child.flow] += 1
                if not node.flow and not child.flow and child.keys and node.keys:
                    step = _column(text, min(child.keys.values())) - _column(text, min(node.keys.values()))
                    self.steps[step] += 1
            self._walk(text, child, path + (key,))

    def places(self, key: Any) -> int:
        """Decimals for a new value of `key`: as the file writes most of them, else as its step needs."""
        if key in self.decimals:
            return self.decimals[key].most_common(1)[0][0]
        # a finite step: its exponent is a number
        return max(0, -int(QUANTITIES[key].step.as_tuple().exponent))

    def flow_style(self, kind: str) -> bool:
        return self.flow[kind].most_common(1)[0][0] if kind in self.flow else DEFAULT_FLOW[kind]

    @property
    def indent(self) -> int:
        positive = [(count, step) for step, count in self.steps.items() if step > 0]
        return max(positive)[1] if positive else DEFAULT_INDENT


def _line_end(text: str, index: int) -> int:
    end = text.find("\n", index)
    return len(text) if end < 0 else end


def _column(text: str, index: int) -> int:
    return index - (text.rfind("\n", 0, index) + 1)


def _rank(key: Any) -> tuple[int, Any]:
    """Program numbers in order, then keys in `KEY_ORDER`."""
    return (0, key) if isinstance(key, int) else (1, KEY_ORDER.index(key))


def _number(value: Any, places: int) -> str:
    """A value as a plant file writes it, with at least `places` decimals for a decimal one."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, int):
        return str(value)
    needed = max(0, -value.normalize().as_tuple().exponent)
    return format(value.quantize(Decimal(1).scaleb(-max(places, needed))), "f")


class _Rewrite:
    """The splices that set values in the text (after its byte order mark, if it has one): each
    (start, end, order, new text)."""

    def __init__(self, text: str) -> None:
        self.bom = BYTE_ORDER_MARK if text.startswith(BYTE_ORDER_MARK) else ""
        self.text = text[len(self.bom):]
        self.root = spans(self.text)
        self.conventions = _Conventions(self.text, self.root)
        self.newline = "\r\n" if "\r\n" in text else "\n"
        self.splices: list[tuple[int, int, int, str]] = []

    def apply(self, wanted: dict[Any, Any]) -> str:
        self._set(self.root, (), wanted)
        self._keep_comments_aligned()
        parts, at = [self.bom], 0
        for start, end, _, new in sorted(self.splices):
            parts += [self.text[at:start], new]
            at = end
        return "".join(parts) + self.text[at:]

    def _keep_comments_aligned(self) -> None:
        """A comment after a value that changed length stays in its column, where the spaces before
        it (two or more: it was lined up) allow: `12.0}      # park` → `9.5}       # park`."""
        grown: dict[int, tuple[int, int]] = {}  # a line's start → (end of the last change, growth)
        for start, end, _, new in self.splices:
            if "\n" not in new and "\n" not in self.text[start:end]:
                line = self.text.rfind("\n", 0, start) + 1
                last, growth = grown.get(line, (end, 0))
                grown[line] = (max(last, end), growth + len(new) - (end - start))
        for last, growth in grown.values():
            tail = _ALIGNED_COMMENT.match(self.text, last, _line_end(self.text, last))
            if growth and tail is not None:
                spaces = tail.end(1) - tail.start(1)
                self.splices.append((tail.start(1), tail.end(1), len(self.splices),
                                     " " * max(2, spaces - growth)))

    def _set(self, node: Span, path: Path_, wanted: dict[Any, Any]) -> None:
        missing = []
        for key, value in wanted.items():
            child = node.children.get(key) if isinstance(node.children, dict) else node.children[key]
            if child is None:
                missing.append(key)
            elif isinstance(value, dict):
                self._set(child, path + (key,), value)
            else:
                self._replace(child, value)
        if missing:
            self._insert(node, path, sorted(missing, key=_rank), wanted)

    def _replace(self, scalar: Span, value: Any) -> None:
        """A scalar's text replaced by `value`, written like it: decimals, quotes, case."""
        written = scalar.written
        assert written is not None  # `wanted` holds a value only where the file has a scalar
        if (core_schema(written)[1] if scalar.plain else written) == value:
            return  # the half of an F1/F2 that did not change
        if isinstance(value, str):
            quote = self.text[scalar.start] if not scalar.plain else ""
            new = f"{quote}{value}{quote}"
        elif isinstance(value, bool):
            new = str(value).lower()
            new = new.upper() if written.isupper() else new.capitalize() if written[:1].isupper() else new
        else:
            new = _number(value, _decimals(written) if DECIMAL_NUMBER.fullmatch(written) else 0)
        self.splices.append((scalar.start, scalar.end, len(self.splices), new))

    def _insert(self, node: Span, path: Path_, keys: list[Any], wanted: dict[Any, Any]) -> None:
        """New keys into the mapping `node` at `path`, each after the key it follows in `_rank` order."""
        groups: dict[Any, list[Any]] = {}
        for key in keys:
            before = [k for k in node.keys if _rank(k) < _rank(key)]
            groups.setdefault(max(before, key=node.keys.__getitem__) if before else None, []).append(key)
        for after, group in groups.items():
            if node.flow:
                self._insert_flow(node, path, after, group, wanted)
            else:
                self._insert_block(node, path, after, group, wanted)

    def _insert_flow(self, node: Span, path: Path_, after: Any, keys: list[Any],
                     wanted: dict[Any, Any]) -> None:
        items = ", ".join(f"{key}: {self._flow(path + (key,), wanted[key])}" for key in keys)
        if after is not None:
            self._add(node.children[after].end, f", {items}")
        elif node.keys:
            self._add(min(node.keys.values()), f"{items}, ")
        else:
            self._add(node.start + 1, items)

    def _insert_block(self, node: Span, path: Path_, after: Any, keys: list[Any],
                      wanted: dict[Any, Any]) -> None:
        first = min(node.keys, key=node.keys.__getitem__)
        column = _column(self.text, node.keys[first])
        lines = [line for key in keys for line in self._block(path + (key,), wanted[key], column)]
        line_start = node.keys[first] - column
        if after is None and not self.text[line_start:node.keys[first]].strip():
            self._add(line_start, "".join(line + self.newline for line in lines))
            return
        end = _line_end(self.text, node.children[after if after is not None else first].end)
        if end == len(self.text):  # the last line of a file that does not end in a newline
            self._add(end, "".join(self.newline + line for line in lines))
        else:
            self._add(end + 1, "".join(line + self.newline for line in lines))

    def _add(self, at: int, new: str) -> None:
        self.splices.append((at, at, len(self.splices), new))

    def _scalar(self, key: Any, value: Any) -> str:
        return value if isinstance(value, str) else _number(value, self.conventions.places(key))

    def _flow(self, path: Path_, value: Any) -> str:
        if not isinstance(value, dict):
            return self._scalar(path[-1], value)
        items = (f"{k}: {self._flow(path + (k,), value[k])}" for k in sorted(value, key=_rank))
        return "{" + ", ".join(items) + "}"

    def _block(self, path: Path_, value: Any, column: int) -> list[str]:
        pad = " " * column
        if not isinstance(value, dict) or self.conventions.flow_style(_kind(path) or ""):
            return [f"{pad}{path[-1]}: {self._flow(path, value)}"]
        inner = column + self.conventions.indent
        keys = sorted(value, key=_rank)
        return [f"{pad}{path[-1]}:",
                *(line for k in keys for line in self._block(path + (k,), value[k], inner))]
