"""Adopting what the modules hold into the plant file: the Teach-In round trip (issue 13).

Teach In changes positions on the floor (manual §2.6, prc3-protocol.md §6), and the plant
file then says otherwise. `adopt` works out the plant file that describes what the modules
hold, changing only the values that drifted, in the layer they came from:

    adoption = adopt(plant, images, text)   # images: api.read's; text: the plant file as loaded
    adoption.adopted                        # each value adopted, `Adopted.text` says it
    adoption.text                           # the plant file, rewritten (not written anywhere)

What is adopted: every field of every managed program of the chosen modules (those in
`images`) that holds something other than the plant file says — position above all, and
speed, relative speed, dwell, F1 and F2 alike — and the system parameters; with `programs`,
only those programs (and no system parameter). A program that `unmanaged_programs: reset`
leaves unlisted and that no longer holds factory defaults is listed, with all it holds.

Where each value goes is where its effective value came from (`profiles.Sourced`):
- the module: changed in place;
- a profile: changed in the profile when every module that takes the value from it was read
  and holds the same new value; otherwise an override on each module that drifted;
- the factory default: an override on the module.

Refused in one line, with nothing adopted: a jump address (A) that drifted — jumps are
`chains` (which come whole from one layer) and `next:`, so they are edited by hand; and a
value the plant file cannot hold — a position above the module's upper reversing point, a
speed outside min_speed..max_speed, anything outside its range — naming module and program.

How the file is rewritten: spliced, never dumped. The text is read once more by the loader's
own reader (`document.spans`) for the exact span of every scalar and collection, a changed value
replaces the text of its scalar (with as many decimals as it had, more only where the value
needs them; quotes and case kept), and a new override is inserted as text in the style of
the file: into a flow mapping as `, key: value`, into a block mapping as lines at its
indentation after the entry it follows (program numbers and fields in their usual order),
nested mappings flow or block as the file writes them (`_Conventions`). Every other byte —
comments, quoting, layout, line ends — stays as it was. Offsets are those of the text after a
byte order mark, which is taken off before parsing and put back after: libyaml does not count
it, the pure parser does. The new text is then loaded as a plant (`parse_plant` of the text, as
if it were the file) and must describe exactly what the modules hold — the adopted values in
the chosen modules, every other module, bus and setting as before — or nothing is adopted
(`AdoptRefused`: a bug of the rewriter, said as one). Pure: text and images in, text out.
"""

from __future__ import annotations

import hashlib
import re
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from decimal import Decimal
from typing import Any

from prc3cfg.core.device import value_range
from prc3cfg.core.image import SYSTEM_KEYS, ModuleImage, SystemParameters, default_program
from prc3cfg.core.render import FieldChange, differences, field_name, format_value
from prc3cfg.core.units import BY_SYMBOL, PROGRAM_QUANTITIES, QUANTITIES, plant_value
from prc3cfg.errors import UserError
from prc3cfg.plant import Bus, Module, Plant
from prc3cfg.plant.document import DECIMAL_NUMBER, Span, core_schema, spans
from prc3cfg.plant.loader import parse_plant
from prc3cfg.plant.models import FunctionOutputSpec, ProgramSpec, SystemSpec
from prc3cfg.plant.problems import Path_, PlantError
from prc3cfg.plant.profiles import DEFAULT, MODULE, Sourced

Key = tuple[str, int]  # (bus name, module address)
#: Program fields as a plant file names them (A is `chains` and `next`, never adopted).
FIELD_KEYS = {q.symbol: q.key for q in PROGRAM_QUANTITIES} | {"F1": "f1", "F2": "f2"}
#: The order keys are written in where adopt adds one: a module's own keys as the README's
#: plant files write them, then the models' order of system, program and F1/F2 keys.
KEY_ORDER = ("address", "name", "profiles", "unmanaged_programs", "system", "programs", "chains",
             *SystemSpec.model_fields, *ProgramSpec.model_fields, *FunctionOutputSpec.model_fields)  # fmt: skip
#: How a new mapping of each kind is written when the file has none of that kind to follow.
DEFAULT_FLOW = {"system": False, "programs": False, "program": True, "output": True}
DEFAULT_INDENT = 2
#: What may follow the last value on a line before a comment lined up with others: closing
#: brackets and commas, two spaces or more, the comment.
_ALIGNED_COMMENT = re.compile(r"[]},]*( {2,})#")
#: How `profiles` names a profile as a source: "profile NAME".
PROFILE = "profile "
BYTE_ORDER_MARK = "\ufeff"


@dataclass(frozen=True, slots=True)
class Adopted:
    """One value written into the plant file.

    `modules`: "bus/name" of each module whose drift it is; `what`: "program 3 position
    1.200 m → 1.150 m", "system max speed …", or for a program newly listed "program 7
    position 0.900 m, speed 0.050 m/s"; `layer`: where it is written, "module" or "profile
    NAME"; `override`: a new key in the module, for a value that came from `source` (a
    profile, or "default").
    """

    modules: tuple[str, ...]
    what: str
    layer: str
    override: bool
    source: str

    @property
    def text(self) -> str:
        """One line: "~ booth-a/booth-a-right: program 1 position 2.000 m → 1.987 m (in the module)"."""
        if self.layer != MODULE:
            return f"~ {self.layer}: {self.what} (every module that takes it from there holds it: {', '.join(self.modules)})"
        if not self.override:
            return f"~ {self.modules[0]}: {self.what} (in the module)"
        why = "the plant file left it at its default" if self.source == DEFAULT else f"{self.source} keeps its value"
        return f"+ {self.modules[0]}: {self.what} (new in the module: {why})"


@dataclass(frozen=True, slots=True)
class AdoptedText:
    """What `adopt` found: the values adopted, in the order of their modules in the file, and the new text."""

    adopted: tuple[Adopted, ...]
    text: str


class AdoptRefused(UserError):
    """A drift the plant file cannot take as it is: nothing was adopted."""


@dataclass(frozen=True, slots=True)
class _Drift:
    """A value a module holds other than the plant file says."""

    name: str                # "bus/module"
    path: Path_              # the module in the file
    within: Path_            # in a layer: ("programs", 3, "position"), ("system", "max_speed"), ("programs", 7)
    value: Any               # in human units: a number, {action, distance}, or a whole program
    what: str
    sourced: Sourced | None  # None: a program no layer lists

    @property
    def profile(self) -> Path_ | None:
        """Where the value is in its profile, if it came from one."""
        return self.sourced.path if self.sourced is not None and self.sourced.source.startswith(PROFILE) else None


def adopt(plant: Plant, images: dict[Key, ModuleImage], text: str, programs: Iterable[int] | None = None) -> AdoptedText:
    """The plant file `text` (of `plant`, as loaded) rewritten to describe what the modules in
    `images` hold — only `programs` of them, if given; `AdoptRefused` for what it cannot say."""
    if hashlib.sha256(text.encode("utf-8")).hexdigest() != plant.sha256:
        raise UserError(f"{plant.path}: the plant file changed since it was loaded — nothing was adopted: adopt again")
    scope = None if programs is None else frozenset(programs)
    chosen = [(bus, module, path) for bus, module, path in _modules(plant) if (bus.name, module.address) in images]
    if scope is not None and not any(scope.intersection(module.managed_programs()) for _, module, _ in chosen):
        raise UserError(f"program {', '.join(map(str, sorted(scope)))}: no chosen module manages "
                        f"{'it' if len(scope) == 1 else 'any of them'} — name a program the plant file lists")  # fmt: skip
    drifts = [d for bus, module, path in chosen for d in _drifts(bus, module, path, images[(bus.name, module.address)], scope)]
    wanted: dict[Any, Any] = {}
    adopted = []
    for target, found in _placed(plant, drifts).items():
        first = found[0]
        _want(wanted, target, first.value)
        source = DEFAULT if first.sourced is None else first.sourced.source
        layer = MODULE if target[0] == "buses" else source
        adopted.append(Adopted(tuple(d.name for d in found), first.what, layer, layer == MODULE and source != MODULE, source))
    if not wanted:
        return AdoptedText((), text)
    rewritten = _Rewrite(text).apply(wanted)
    _check_rewritten(plant, {key: _adopted_image(module, images.get(key), scope) for key, module in _keyed(plant)}, rewritten)
    return AdoptedText(tuple(adopted), rewritten)


def _keyed(plant: Plant) -> Iterator[tuple[Key, Module]]:
    return (((bus.name, module.address), module) for bus, module in plant.modules())


def _adopted_image(module: Module, have: ModuleImage | None, scope: frozenset[int] | None) -> ModuleImage:
    """What the plant file says of `module` once what it holds (`have`, if it was read) is adopted
    within `scope`: its managed programs as held, and its system parameters too without a scope."""
    desired = module.desired_image()
    if have is None:
        return desired
    numbers = [n for n in module.managed_programs() if (scope is None or n in scope) and have.program(n) is not None]
    return replace(desired.with_programs({n: have.known(n) for n in numbers}), system=have.system if scope is None else desired.system)


def _check_rewritten(plant: Plant, adopted: dict[Key, ModuleImage], text: str) -> None:
    """`AdoptRefused` unless `text`, loaded as the plant file, has the same buses, modules and
    settings as `plant`, and each module's image is the one `adopted` names."""
    try:
        after = parse_plant(plant.path, text.encode("utf-8"))
    except PlantError as error:
        raise _rewriter_bug(plant, f"it would not load: {error.problems[0]}") from None
    same = [bus.model_dump(exclude={"modules"}) for bus in plant.buses] == [bus.model_dump(exclude={"modules"}) for bus in after.buses]
    if after.name != plant.name or not same or [(k, m.name) for k, m in _keyed(plant)] != [(k, m.name) for k, m in _keyed(after)]:
        raise _rewriter_bug(plant, "its plant, buses or modules would differ")
    for (bus, address), module in _keyed(after):
        if (said := module.desired_image()) != (held := adopted[(bus, address)]):
            found = "; ".join(differences(held, said)) or "the programs it manages"
            raise _rewriter_bug(plant, f"bus {bus}, module {address} ({module.name}): {found} (held → written)")


def _rewriter_bug(plant: Plant, what: str) -> AdoptRefused:
    return AdoptRefused(f"{plant.path}: the rewritten plant file would not describe what the modules hold — {what}; "
                        "nothing was adopted: this is a bug in prc3cfg, please report it with the plant file")


def _modules(plant: Plant) -> Iterator[tuple[Bus, Module, Path_]]:
    """Every module with its path in the file (the loader keeps the file's order)."""
    for b, bus in enumerate(plant.buses):
        for m, module in enumerate(bus.modules):
            yield bus, module, ("buses", b, "modules", m)


# -- what drifted -------------------------------------------------------------------------


def _drifts(bus: Bus, module: Module, path: Path_, have: ModuleImage, scope: frozenset[int] | None) -> list[_Drift]:
    """What `module` holds (`have`) other than the plant file says, within `scope`; refused when
    it cannot be adopted (a jump, a value a plant file cannot hold)."""
    name, where = f"{bus.name}/{module.name}", f"bus {bus.name}, module {module.address} ({module.name})"
    desired, settings = module.desired_image(), module.settings
    numbers = [n for n in module.managed_programs() if (scope is None or n in scope) and have.program(n) is not None]
    for number in numbers:
        jumps, said_jumps = have.known(number).A, desired.known(number).A
        if jumps != said_jumps:
            raise AdoptRefused(f"{where}: program {number} jumps to {jumps or 'no program'} on the module where the plant "
                               f"file says {said_jumps or 'no program'} — adopt leaves jumps (chains, next:) alone: edit them "
                               "in the plant file by hand, or apply it to set the jump back, then adopt again")  # fmt: skip
    system = have.system if scope is None else desired.system
    _check(_adopted_image(module, have, scope), numbers, where)
    drifts = [_Drift(name, path, ("system", BY_SYMBOL[c.symbol].key), plant_value(c.symbol, c.after), f"system {c.text}",
                     settings.system[BY_SYMBOL[c.symbol].key]) for c in _changes(desired.system, system, SYSTEM_KEYS)]  # fmt: skip
    for number in numbers:
        held = have.program(number)
        if number in settings.programs:
            drifts += [_Drift(name, path, ("programs", number, FIELD_KEYS[c.symbol]), plant_value(c.symbol, c.after),
                              f"program {number} {c.text}", settings.programs[number][FIELD_KEYS[c.symbol]])
                       for c in _changes(desired.program(number), held, FIELD_KEYS)]  # fmt: skip
        elif held != default_program(system):  # unlisted under reset: listed now, with all it holds
            symbols = [s for s in FIELD_KEYS if s in ("P", "V") or getattr(held, s)]
            said = ", ".join(f"{field_name(s)} {format_value(s, getattr(held, s))}" for s in symbols)
            value = {FIELD_KEYS[s]: plant_value(s, getattr(held, s)) for s in symbols}
            drifts.append(_Drift(name, path, ("programs", number), value, f"program {number} {said}", None))
    return drifts


def _changes(said: Any, held: Any, symbols: Iterable[str]) -> list[FieldChange]:
    """The fields `symbols` of two programs, or of two sets of system parameters, that differ."""
    return [FieldChange.of(None, s, getattr(said, s), getattr(held, s)) for s in symbols if getattr(said, s) != getattr(held, s)]


def _check(after: ModuleImage, numbers: list[int], where: str) -> None:
    """`AdoptRefused` for a value of `after` — the module as the plant file would describe it —
    that a plant file cannot hold: the device's own checks (prc3-protocol.md §4.5)."""
    system = after.system
    for key in SYSTEM_KEYS:
        _in_range(key, getattr(system, key), system, f"{where}: system")
    if system.S4 < system.S5:
        raise AdoptRefused(f"{where}: system max speed {format_value('S4', system.S4)} is below min speed "
                           f"{format_value('S5', system.S5)} — a plant file cannot say that: "
                           "set the module's system parameters right, then adopt again")  # fmt: skip
    for number in numbers:
        for symbol in FIELD_KEYS:
            _in_range(symbol, getattr(after.program(number), symbol), system, f"{where}: program {number}")


def _in_range(symbol: str, device: int, system: SystemParameters, where: str) -> None:
    low, high, _, _ = value_range(symbol, system)
    if not low <= device <= high:
        said = (f"{format_value(symbol, device)}, outside {format_value(symbol, low)}..{format_value(symbol, high)}"
                if symbol in ("P", "V") else f"{device} (device units), outside {low}..{high}")
        raise AdoptRefused(f"{where} holds {field_name(symbol)} {said} — a plant file cannot say that: set it right on "
                           "the module (teach it again), then adopt again")  # fmt: skip


# -- where each drift goes ----------------------------------------------------------------


def _placed(plant: Plant, drifts: list[_Drift]) -> dict[Path_, list[_Drift]]:
    """Each place to write, with the drifts written there: a profile's value when every module
    that takes it from there drifted to one new value, else the module (in place or an override)."""
    users = Counter(v.path for _, module, _ in _modules(plant) for v in _values(module) if v.source.startswith(PROFILE))
    alike: dict[Path_, list[_Drift]] = {}
    for drift in drifts:
        if drift.profile is not None:
            alike.setdefault(drift.profile, []).append(drift)
    placed: dict[Path_, list[_Drift]] = {}
    for drift in drifts:
        place, profile = drift.path + drift.within, drift.profile
        if profile is not None and (shared := alike[profile]) and len(shared) == users[profile] and all(d.value == drift.value for d in shared):
            place = profile
        placed.setdefault(place, []).append(drift)
    return placed


def _values(module: Module) -> Iterator[Sourced]:
    """The module's effective system parameters and program fields, each with its source."""
    settings = module.settings
    yield from settings.system.values()
    for fields in settings.programs.values():
        yield from (fields[key] for key in FIELD_KEYS.values())


def _want(trie: dict[Any, Any], path: Path_, value: Any) -> None:
    """`trie[path[0]][path[1]]… = value`."""
    for part in path[:-1]:
        trie = trie.setdefault(part, {})
    trie[path[-1]] = value


# -- the file as text: its nodes' spans, its conventions, the splices ---------------------


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
                    self.steps[_column(text, min(child.keys.values())) - _column(text, min(node.keys.values()))] += 1
            self._walk(text, child, path + (key,))

    def places(self, key: Any) -> int:
        """Decimals for a new value of `key`: as the file writes most of them, else as its step needs."""
        if key in self.decimals:
            return self.decimals[key].most_common(1)[0][0]
        return max(0, -int(QUANTITIES[key].step.as_tuple().exponent))  # a finite step: its exponent is a number

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
                self.splices.append((tail.start(1), tail.end(1), len(self.splices), " " * max(2, spaces - growth)))

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

    def _insert_flow(self, node: Span, path: Path_, after: Any, keys: list[Any], wanted: dict[Any, Any]) -> None:
        items = ", ".join(f"{key}: {self._flow(path + (key,), wanted[key])}" for key in keys)
        if after is not None:
            self._add(node.children[after].end, f", {items}")
        elif node.keys:
            self._add(min(node.keys.values()), f"{items}, ")
        else:
            self._add(node.start + 1, items)

    def _insert_block(self, node: Span, path: Path_, after: Any, keys: list[Any], wanted: dict[Any, Any]) -> None:
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
        return "{" + ", ".join(f"{k}: {self._flow(path + (k,), value[k])}" for k in sorted(value, key=_rank)) + "}"

    def _block(self, path: Path_, value: Any, column: int) -> list[str]:
        pad = " " * column
        if not isinstance(value, dict) or self.conventions.flow_style(_kind(path) or ""):
            return [f"{pad}{path[-1]}: {self._flow(path, value)}"]
        inner = column + self.conventions.indent
        return [f"{pad}{path[-1]}:", *(line for k in sorted(value, key=_rank) for line in self._block(path + (k,), value[k], inner))]
