"""The shape of the tests themselves (issue 42): what keeps the fast tier honest on a busy machine.

- No test asserts a wall-clock time from above. A clock read in a test (`time.monotonic()`,
  `perf_counter()`, `time.time()`, and every name computed from one in the same function) may be
  asserted only as a lower bound — `took >= line_time`, which a busy machine only makes truer; an
  upper bound or a tolerance either side (`abs(took - 0.05) <= 0.005`) fails on a loaded 2-core
  machine, and belongs in bench/ (as bench/doctor_bench.py measures doctor's turnarounds). An assert in
  a `while` loop is a wait's guard (`time.monotonic() < deadline` while polling for what a process
  traced: it bounds how long the test waits for a hung process, a minute or more), not a claim on speed.
- A program outside Python is found through tests/tools.py (`needs`, `require`, `which`), whose
  skips give the command that installs it, and docs/testing.md lists each with that command.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from tools import INSTALL

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent

#: The clocks of the `time` module a test could read the wall with.
CLOCKS = {"monotonic", "monotonic_ns", "perf_counter", "perf_counter_ns", "time", "time_ns"}

#: Programs every Linux that runs the root-only tests has (util-linux's setpriv, passwd's useradd): no install
#: command to give.
SYSTEM = {"setpriv", "useradd"}


def _reads_clock(node: ast.AST, clocked: set[str]) -> bool:
    """Whether `node` reads a clock: calls time.monotonic() and the like, or uses a name computed from one."""
    for sub in ast.walk(node):
        if isinstance(sub, ast.Call):
            func = sub.func
            if (isinstance(func, ast.Attribute) and func.attr in CLOCKS
                and isinstance(func.value, ast.Name) and func.value.id == "time"):
                return True
            if isinstance(func, ast.Name) and func.id in CLOCKS - {"time"}:  # `from time import monotonic`
                return True
        if isinstance(sub, ast.Name) and sub.id in clocked:
            return True
    return False


def _clocked_names(function: ast.AST) -> set[str]:
    """The names a function assigns from a clock, directly or through other such names."""
    clocked: set[str] = set()
    while True:
        before = len(clocked)
        for node in ast.walk(function):
            assigned = (isinstance(node, ast.Assign | ast.AnnAssign | ast.AugAssign | ast.NamedExpr)
                        and node.value is not None)
            if assigned and _reads_clock(node.value, clocked):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                clocked |= {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
        if len(clocked) == before:
            return clocked


def _a_lower_bound(test: ast.expr, clocked: set[str]) -> bool:
    """`clock >= x`, `clock > x`, `x <= clock` or `x < clock`, the other side reading no clock."""
    if not (isinstance(test, ast.Compare) and len(test.ops) == 1):
        return False
    left, right = test.left, test.comparators[0]
    if isinstance(test.ops[0], ast.GtE | ast.Gt):
        return _reads_clock(left, clocked) and not _reads_clock(right, clocked)
    if isinstance(test.ops[0], ast.LtE | ast.Lt):
        return _reads_clock(right, clocked) and not _reads_clock(left, clocked)
    return False


def wall_clock_assertions(source: str) -> Iterator[int]:
    """The lines of `source` whose assert bounds a clock reading other than from below."""
    tree = ast.parse(source)
    functions = [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)]
    for function in functions:
        clocked = _clocked_names(function)
        waits = {id(n) for loop in ast.walk(function) if isinstance(loop, ast.While) for n in ast.walk(loop)}
        for node in ast.walk(function):
            if isinstance(node, ast.Assert) and id(node) not in waits and _reads_clock(node.test, clocked):
                parts = (node.test.values if isinstance(node.test, ast.BoolOp) and isinstance(node.test.op,
                                                                                             ast.And)
                         else [node.test])
                if not all(_a_lower_bound(p, clocked) or not _reads_clock(p, clocked) for p in parts):
                    yield node.lineno


@pytest.mark.parametrize(
    ("source", "lines"),
    [
        ("def t():\n    started = time.monotonic()\n    work()\n    took = time.monotonic() - started\n    "
         "assert took >= 0.3\n", []),
        ("def t():\n    started = time.monotonic()\n    took = time.monotonic() - started\n    assert "
         "took < 0.3\n", [4]),
        ("def t():\n    started = time.perf_counter()\n    assert abs(time.perf_counter() - started - 0.05) "
         "<= 0.005\n", [3]),
        ("def t():\n    t0 = time.time()\n    t1 = t0 + 1\n    assert 0.2 <= t1 - t0 and t1 - "
         "t0 <= 2\n", [4]),
        ("def t():\n    took = monotonic()\n    assert 1 < took and ok\n", []),
        ("def t():\n    deadline = time.monotonic() + 60\n    while busy():\n        assert "
         "time.monotonic() < deadline\n", []),
        # no clock read here: a figure computed elsewhere
        ("def t():\n    assert abs(median - 0.05) <= 0.005\n", []),
    ],
)
def test_the_check_finds_a_clock_asserted_from_above(source: str, lines: list[int]) -> None:
    assert list(wall_clock_assertions(source)) == lines


#: A clock reading (a name assigned from one, through another name, or the call itself) and an expression
#: without one.
CLOCKED = ["took", "time.monotonic() - started", "elapsed", "(time.perf_counter() - t0) * 1000"]
PLAIN = ["0.3", "line_time", "cost.message_time(1, message)", "2 * expected"]
OPERATORS = {"<": "upper", "<=": "upper", ">": "lower", ">=": "lower", "==": "both", "!=": "both"}


def a_test_asserting(left: str, operator: str, right: str, inside_a_wait: bool) -> str:
    body = f"assert {left} {operator} {right}"
    if inside_a_wait:
        body = f"while busy():\n        {body}"
    return ("def t():\n    started = t0 = time.monotonic()\n    took = time.monotonic() - started\n    "
            f"elapsed = took\n    {body}\n")


def flagged_as_it_should_be(left: str, operator: str, right: str, inside_a_wait: bool) -> None:
    """Flagged exactly when a clock is compared other than as a lower bound (outside a wait's loop)."""
    clocked = (left in CLOCKED, right in CLOCKED)
    lower = (OPERATORS[operator], clocked) in (("lower", (True, False)), ("upper", (False, True)))
    expected = [5] if any(clocked) and not lower and not inside_a_wait else []
    assert list(wall_clock_assertions(a_test_asserting(left, operator, right, inside_a_wait))) == expected


@settings(max_examples=30)
@given(st.sampled_from(CLOCKED + PLAIN), st.sampled_from(sorted(OPERATORS)), st.sampled_from(CLOCKED + PLAIN),
       st.booleans())
def test_the_check_flags_exactly_a_clock_compared_other_than_from_below(left, operator, right,
                                                                        inside_a_wait) -> None:
    flagged_as_it_should_be(left, operator, right, inside_a_wait)


@pytest.mark.soak
@settings()  # the profile's examples: every combination (8 × 6 × 8 × 2) many times over
@given(st.sampled_from(CLOCKED + PLAIN), st.sampled_from(sorted(OPERATORS)), st.sampled_from(CLOCKED + PLAIN),
       st.booleans())
def test_the_check_flags_exactly_a_clock_compared_other_than_from_below_soak(left, operator, right,
                                                                             inside_a_wait) -> None:
    flagged_as_it_should_be(left, operator, right, inside_a_wait)


def test_no_test_asserts_a_wall_clock_time_from_above() -> None:
    found = [f"{path.relative_to(ROOT)}:{line}" for path in sorted(TESTS.rglob("*.py"))
             for line in wall_clock_assertions(path.read_text())]
    assert found == [], ("a wall-clock time asserted from above (a busy machine fails it): assert a lower "
                         "bound, or measure it in bench/")


def test_programs_outside_python_are_found_through_tools() -> None:
    """Each with its install command in its skip: `shutil.which` of any other program is tools.py's alone."""
    found = []
    for path in sorted(TESTS.rglob("*.py")):
        if path.name == "tools.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr == "which"
                    and isinstance(node.func.value, ast.Name) and node.func.value.id == "shutil"):
                named = node.args[0].value if node.args and isinstance(node.args[0], ast.Constant) else None
                if named not in SYSTEM:
                    found.append(f"{path.relative_to(ROOT)}:{node.lineno}: shutil.which({named!r})")
    assert found == [], "find it with tools.which/needs/require, its install command in tools.INSTALL"


def test_docs_testing_lists_every_program_with_its_install_command() -> None:
    text = (ROOT / "docs" / "testing.md").read_text()
    for program, command in INSTALL.items():
        assert f"`{program}`" in text, program
        assert command in text, command


def test_ci_runs_the_readme_s_test_command_verbatim_and_prints_its_wall_and_cpu_time() -> None:
    """What a maintainer runs (the README's `python -m pytest` line) is what CI runs, timed by bash's `time`
    with a TIMEFORMAT that prints the wall time (%R) and the CPU time (%U user, %S system) of it and its
    workers."""
    commands = [line for line in (ROOT / "README.md").read_text().splitlines()
                if "python -m pip install" in line and "pytest" in line]
    assert commands, "the README gives the fast tier's command on a line of its own"
    script = (ROOT / ".ci" / "run").read_text()
    (timed,) = [line for line in script.splitlines() if line.startswith("time { ")]
    assert timed.removeprefix("time { ").removesuffix("; }") in commands
    (timeformat,) = [line for line in script.splitlines() if line.startswith("TIMEFORMAT=")]
    assert all(f in timeformat for f in ("%R", "%U", "%S")) and "fast tier" in timeformat
    # before the soak tier
    assert script.index("TIMEFORMAT=") < script.index(timed) < script.index("python -m pytest -m soak")
