"""The shape of prc3cfg's code (issue 28): a long file or a complex function says at its top why.

- A file of `prc3cfg/` over `LONG_FILE` lines has a module docstring with the words "long because"
  (in any case), and why after them: "It is long because it is the one seam: …".
- A function or method (nested ones too, each measured alone) whose cyclomatic complexity is over
  `COMPLEX` — radon's rank D begins at 21 — has the words "complex because" in its docstring or in a
  comment between its `def` and its first statement: "Complex because it is one decision: …".
  Prefer a simpler function (a table, smaller named functions, early returns) to the words.

Complexity is counted as radon counts it (`radon cc`, radon 6), with the standard library's `ast`
alone: radon is no dependency of prc3cfg. A function starts at 1 and adds (`_DECISIONS`)
- 1 for each `if`, `elif` and conditional expression (`a if c else b`);
- 1 for each `for` and `while` loop, and 1 more for its `else`;
- 1 for each `except` clause, and 1 for a `try`'s `else` (`finally` adds nothing; nor do the
  handlers of `try`/`except*`, which radon 6 does not know);
- 1 for each operand of `and`/`or` after the first;
- 1 for each `for` of a comprehension, and 1 for each of its `if`s;
- 1 for each `case` of a `match`, but one catch-all (`case _:` or a bare capture);
- 1 for each `assert`, whatever its condition holds (radon does not look inside one).
`with`, `return`, `break`, `raise`, decorators and default values add nothing. A lambda's body
counts in the function it is written in; a function or class defined inside one counts only in
itself (radon lists no nested function; here each is measured).
"""

from __future__ import annotations

import ast
import io
import re
import tokenize
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "prc3cfg"

#: Lines a file may have without saying why it is long.
LONG_FILE = 500
#: The complexity a function may have without saying why it is complex (radon's rank C at most).
COMPLEX = 20
#: What a long file's module docstring and a complex function's docstring or top comment say.
LONG_MARK = re.compile(r"\blong because\b", re.IGNORECASE)
COMPLEX_MARK = re.compile(r"\bcomplex because\b", re.IGNORECASE)

Function = ast.FunctionDef | ast.AsyncFunctionDef


def _match_cases(node: ast.Match) -> int:
    catch_all = any(isinstance(case.pattern, ast.MatchAs) and case.pattern.pattern is None
                    for case in node.cases)
    return max(0, len(node.cases) - catch_all)


#: The decision points a node adds to its function's complexity, by its type (radon's rules).
_DECISIONS: dict[type[ast.AST], Callable[[Any], int]] = {
    ast.If: lambda node: 1,
    ast.IfExp: lambda node: 1,
    ast.For: lambda node: 1 + bool(node.orelse),
    ast.AsyncFor: lambda node: 1 + bool(node.orelse),
    ast.While: lambda node: 1 + bool(node.orelse),
    ast.Try: lambda node: len(node.handlers) + bool(node.orelse),
    ast.BoolOp: lambda node: len(node.values) - 1,
    ast.comprehension: lambda node: 1 + len(node.ifs),
    ast.Match: _match_cases,
}


def complexity(function: Function) -> int:
    """The cyclomatic complexity of `function`, as radon counts it (this module's docstring)."""
    total = 1
    stack: list[ast.AST] = list(function.body)
    while stack:
        node = stack.pop()
        if isinstance(node, ast.Assert):
            total += 1
            continue
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            continue
        if (decisions := _DECISIONS.get(type(node))) is not None:
            total += decisions(node)
        stack.extend(ast.iter_child_nodes(node))
    return total


def functions(tree: ast.AST, prefix: str = "") -> Iterator[tuple[str, Function]]:
    """Every function and method under `tree`, nested ones too, with its qualified name."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            yield prefix + node.name, node
            yield from functions(node, f"{prefix}{node.name}.")
        elif isinstance(node, ast.ClassDef):
            yield from functions(node, f"{prefix}{node.name}.")
        else:
            yield from functions(node, prefix)


def _comments(source: str) -> dict[int, str]:
    """Each comment of `source`, by its line."""
    tokens = tokenize.generate_tokens(io.StringIO(source).readline)
    return {token.start[0]: token.string for token in tokens if token.type == tokenize.COMMENT}


def _says_why_complex(function: Function, comments: dict[int, str]) -> bool:
    top = [text for line, text in comments.items() if function.lineno <= line < function.body[0].lineno]
    return any(COMPLEX_MARK.search(text) for text in [ast.get_docstring(function) or "", *top])


def _sources() -> Iterator[tuple[str, str]]:
    for path in sorted(PACKAGE.rglob("*.py")):
        yield path.relative_to(ROOT).as_posix(), path.read_text(encoding="utf-8")


def offenders() -> list[tuple[str, str]]:
    """(what, why) of every long file and complex function that does not say why."""
    found = []
    for name, source in _sources():
        tree = ast.parse(source)
        lines = len(source.splitlines())
        if lines > LONG_FILE and not LONG_MARK.search(ast.get_docstring(tree) or ""):
            found.append((name, f"{lines} lines"))
        comments = _comments(source)
        for qualname, function in functions(tree):
            if (count := complexity(function)) > COMPLEX and not _says_why_complex(function, comments):
                found.append((f"{name}::{qualname}", f"complexity {count}"))
    return found


def test_long_files_and_complex_functions_say_why() -> None:
    unexplained = [f"{what} ({why})" for what, why in offenders()]
    assert not unexplained, (
        f"over {LONG_FILE} lines or complexity {COMPLEX} without saying why — split or simplify it, "
        "or say why "
        "at its top ('long because' in the module docstring, 'complex because' in the function's): "
        f"{unexplained}")


@pytest.mark.parametrize(("source", "expected"), [
    ("def f():\n    return 1", 1),
    ("def f(a=1 if x else 2):\n    return a", 1),  # a default value is not the function's
    ("def f(x):\n    if x:\n        return 1\n    elif x > 1:\n        return 2\n    else:\n        return 3",
     3),
    ("def f(x):\n    return 1 if x else 2", 2),
    ("def f(x):\n    for i in x:\n        pass\n    else:\n        pass\n    while x:\n        break", 4),
    ("async def f(x):\n    async for i in x:\n        pass\n    async with x:\n        pass", 2),
    ("def f():\n    try:\n        pass\n    except A:\n        pass\n    except B:\n        pass\n    else:\n"
     "        pass\n    finally:\n        pass", 4),
    # radon 6 does not know try/except*
    ("def f():\n    try:\n        pass\n    except* A:\n        pass", 1),
    ("def f(a, b, c):\n    return a and b or c", 3),
    ("def f(a, b, c):\n    return a and b and c", 3),  # one BoolOp of three operands
    ("def f(x):\n    return [i for i in x if i if i > 1 for j in i]", 5),
    ("def f(x):\n    return {i: j for i, j in x}", 2),
    ("def f(x):\n    assert x and x > 1 and x < 3", 2),  # an assert is one, whatever it holds
    ("def f(x):\n    match x:\n        case 1:\n            pass\n        case [a]:\n            pass\n"
     "        case _:\n            pass", 3),
    ("def f(x):\n    match x:\n        case 1:\n            pass\n        case y:\n            pass", 2),
    ("def f(x):\n    def g():\n        if x:\n            pass\n    class C:\n        def m(self):\n"
     "            if x:\n                pass\n    return g", 1),  # nested definitions count in themselves
    ("def f(x):\n    return lambda y: y if x else 0", 2),  # a lambda's body counts where it is written
    ("def f(x):\n    with x:\n        return x", 1),
])
def test_complexity_is_counted_as_radon_counts_it(source: str, expected: int) -> None:
    (_, function), *_ = functions(ast.parse(source))
    assert complexity(function) == expected


def test_a_complex_function_says_why_in_its_docstring_or_top_comment() -> None:
    branches = "".join(f"    if x == {n}:\n        return {n}\n" for n in range(COMPLEX))
    cases = {
        "def f(x):\n" + branches: False,
        'def f(x):\n    """Complex because each value is its own answer."""\n' + branches: True,
        "def f(x):  # complex because each value is its own answer\n" + branches: True,
        "def f(x):\n    # Complex because each value is its own answer.\n" + branches: True,
        "def f(x):\n    pass\n    # complex because: a comment below the top is not at its top\n"
             + branches: False,
    }
    for source, says in cases.items():
        (_, function), *_ = functions(ast.parse(source))
        assert complexity(function) == COMPLEX + 1
        assert _says_why_complex(function, _comments(source)) is says, source


def _imports(module: str, path: Path, modules: set[str]) -> set[str]:
    """The modules of prc3cfg `path` (module `module`) imports anywhere in it — at its top, in a function,
    under TYPE_CHECKING: `from prc3cfg.core import codec` names prc3cfg.core.codec, not the package."""
    found: set[str] = set()
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names if alias.name in modules}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: from the module's package up
                base = ".".join([*package.split(".")[: len(package.split(".")) - node.level + 1],
                                 *([base] if base else [])])
            for alias in node.names:
                found |= {f"{base}.{alias.name}"} & modules or {base} & modules
    return found - {module}


def test_no_files_import_each_other_in_a_circle() -> None:
    """Issue 43: layers point down, and within one no two files need each other — also not for types only
    (a circle under TYPE_CHECKING is a circle a reader has to hold in mind all the same)."""
    import graphlib

    paths = {".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__"): path
             for path in PACKAGE.rglob("*.py")}
    graph = {module: _imports(module, path, set(paths)) for module, path in paths.items()}
    try:
        graphlib.TopologicalSorter(graph).prepare()
    except graphlib.CycleError as circle:
        raise AssertionError(f"an import circle: {' -> '.join(circle.args[1])}") from None
