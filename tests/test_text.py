"""`prc3cfg.core.text`: what is not printable text, and how text from a file is shown.

`shown` is a table: each character a terminal, an editor or a browser would act on or hide —
control characters, line and paragraph separators, bidirectional overrides and isolates, marks
and zero-width characters — comes out as the escape Python's repr writes, nothing else changes.
"""

from __future__ import annotations

import re
import subprocess
import sys
import unicodedata

import pytest
import yaml
from emulated import DEMO, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from prc3cfg.core import text

#: (what a file holds, what prc3cfg shows of it).
SHOWN = [
    ("booth-a", "booth-a"),
    ("Kabine Süd 3", "Kabine Süd 3"),  # letters outside ASCII are text
    ("m1\x1b[1A\x1b[2K", "m1\\x1b[1A\\x1b[2K"),  # ESC: a cursor move, a line erased
    ("a\nb\rc\td\x00", "a\\nb\\rc\\td\\x00"),
    ("a\x7fb\x85c\x9b", "a\\x7fb\\x85c\\x9b"),  # DEL, NEL, CSI (C1)
    ("a\u2028b\u2029c", "a\\u2028b\\u2029c"),  # line and paragraph separators
    ("gun-\u202eredro", "gun-\\u202eredro"),  # RIGHT-TO-LEFT OVERRIDE
    ("\u202a\u202b\u202c\u202d", "\\u202a\\u202b\\u202c\\u202d"),  # embeddings, pop, LEFT-TO-RIGHT OVERRIDE
    ("\u2066\u2067\u2068\u2069", "\\u2066\\u2067\\u2068\\u2069"),  # isolates
    ("\u200e\u200f\u061c", "\\u200e\\u200f\\u061c"),  # marks: LRM, RLM, ARABIC LETTER MARK
    ("a\u200bb\u200cc\u200dd\u2060e\ufeff", "a\\u200bb\\u200cc\\u200dd\\u2060e\\ufeff"),  # zero-width, BOM
    ("soft\xadhyphen", "soft\\xadhyphen"),  # hidden unless a line breaks there
    ("tag\U000e0041", "tag\\U000e0041"),  # a TAG LATIN CAPITAL LETTER A: invisible
    ("lone \ud800", "lone \\ud800"),  # no encoding writes a lone surrogate
    ("back\\slash", "back\\slash"),
]


@pytest.mark.parametrize(("written", "expected"), SHOWN)
def test_shown_escapes_what_moves_hides_or_reorders_text(written: str, expected: str) -> None:
    assert text.shown(written) == expected
    assert text.has_control(written) == (written != expected)


def test_every_control_format_and_separator_character_is_escaped() -> None:
    """Every character of the general categories Cc, Cf, Cs, Zl and Zp of this Python's Unicode
    database is escaped, and nothing printable is: the rule is the categories, not a list."""
    unprintable = {"Cc", "Cf", "Cs", "Zl", "Zp"}
    for code in range(sys.maxunicode + 1):
        c = chr(code)
        if unicodedata.category(c) in unprintable:
            assert text.shown(c) == repr(c)[1:-1] != c, hex(code)
        elif c.isprintable():
            assert text.shown(c) == c, hex(code)


def test_every_medium_escapes_as_shown_does() -> None:
    """The GitHub and markdown escapings show a file's characters as `shown` does, first."""
    hostile = "x\u202ey\u2028z"
    assert (text.github_data(hostile) == text.github_property(hostile) == text.markdown_html(hostile)
            == "x\\u202ey\\u2028z")
    assert text.markdown(hostile) == "x&#92;u202ey&#92;u2028z"  # a backslash in markdown is an entity


#: A character a name may not hold, and what `validate` says of it (to YAML, U+2028 ends a line).
HIDDEN = {"\u202e": "control character", "\u2066": "control character", "\u200d": "control character",
          "\u2028": "a line that is not 'key: value'"}


@pytest.mark.parametrize("hidden", HIDDEN, ids=[f"U+{ord(c):04X}" for c in HIDDEN])
def test_a_plant_file_name_that_reorders_hides_or_breaks_text_is_refused_at_validate(tmp_path, hidden):
    """A module named "booth-a-\\u202etfel" shows as "booth-a-left" reversed on a screen: refused where it is
    written, in one line naming the file, line and column — from the console script, in a process of its own.
    """
    plant = tmp_path / "plant.yaml"
    plant.write_text(DEMO.read_text(encoding="utf-8").replace("name: booth-a-left",
                                                              f"name: booth-a-{hidden}tfel", 1),
                     encoding="utf-8")
    done = subprocess.run([sys.executable, "-m", "prc3cfg", "validate", str(plant)], capture_output=True,
                          timeout=120)
    assert done.returncode == 1, done.stdout
    (line,) = done.stderr.decode().splitlines()
    assert re.match(rf"error: {re.escape(str(plant))}:\d+:\d+: ", line) and HIDDEN[hidden] in line, line
    assert hidden.encode() not in done.stderr


#: A module name a plant file may hold: printable text of any kind — letters of any script, digits,
#: punctuation, symbols, spaces — in which rich, markdown or a shell could read marks of their own.
NAMES = st.text(st.characters(categories=("L", "N", "P", "S", "Zs")), min_size=1, max_size=24)


def shown_by_every_command(path, capsys, name: str) -> None:
    """The demo's first module named `name`: `validate` takes it or refuses it in one line naming where;
    taken, `show`, `show --module` and `plan` (all of which the terminal's rich draws) print it as written."""
    document = yaml.safe_load(DEMO.read_text(encoding="utf-8"))
    document["buses"][0]["modules"][0]["name"] = name
    path.write_text(yaml.safe_dump(document, allow_unicode=True, sort_keys=False), encoding="utf-8")
    checked = run_cli(capsys, "validate", path)
    if checked.code != 0:
        (line,) = checked.err.splitlines()
        assert checked.code == 1 and line.startswith(f"error: {path}:"), checked.err
        return
    for args in (("show", path), ("show", path, f"--module={name}"), ("plan", path)):
        said = run_cli(capsys, *args)
        assert said.code == 0 and name in said.out, (args, said)


@settings(max_examples=12, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=NAMES)
def test_any_module_name_validate_takes_is_shown_as_written(tmp_path, capsys, name):
    shown_by_every_command(tmp_path / "plant.yaml", capsys, name)


@pytest.mark.soak
@settings(max_examples=500,  # 0.1 s each: the profile's 2,000 would add 3 minutes to one worker's soak
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(name=NAMES)
def test_any_module_name_validate_takes_is_shown_as_written_many(tmp_path, capsys, name):
    shown_by_every_command(tmp_path / "plant.yaml", capsys, name)
