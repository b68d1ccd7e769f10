"""The pytest plugin seeds emulated modules from a `read --json` file, with both paths taken from the
plant repository's rootdir wherever pytest runs, and says in one line which file is wrong."""

from __future__ import annotations

import json
import shutil

from emulated import DEMO

from prc3cfg.core.image import ModuleImage, Program

pytest_plugins = ["pytester"]

SEEDED_TEST = '''
from prc3cfg import api


def test_seeded(prc3cfg_emulated):
    emulated = prc3cfg_emulated("plant.yaml", images="read.json")
    held = emulated.emulators["booth-a"].module(1).image.program(7)
    assert (held.P, held.V) == (1234, 99)
    assert api.plan(emulated.plant).changes
'''

MISSING_TEST = '''
def test_missing(prc3cfg_emulated):
    prc3cfg_emulated("plant.yaml", images="nowhere.json")
'''


def plant_repository(pytester) -> None:
    pytester.makeini("[pytest]\n")
    shutil.copy(DEMO, pytester.path / "plant.yaml")
    seeded = ModuleImage.factory(1).with_programs({7: Program(P=1234, V=99)})
    (pytester.path / "read.json").write_text(json.dumps([{"bus": "booth-a", **seeded.to_json()}]))
    (pytester.path / "tests").mkdir()


def test_the_images_are_found_from_the_rootdir_wherever_pytest_runs(pytester, monkeypatch):
    plant_repository(pytester)
    (pytester.path / "tests" / "test_seeded.py").write_text(SEEDED_TEST)
    monkeypatch.chdir(pytester.path / "tests")
    result = pytester.runpytest_subprocess()
    assert result.ret == 0, result.stdout.str()
    result.assert_outcomes(passed=1)


def test_a_missing_images_file_is_named_in_one_line(pytester):
    plant_repository(pytester)
    (pytester.path / "tests" / "test_missing.py").write_text(MISSING_TEST)
    result = pytester.runpytest_subprocess()
    result.assert_outcomes(failed=1)
    assert any("nowhere.json" in line and "give the file prc3cfg read --json wrote" in line
               and line.lstrip("E ").startswith("prc3cfg.errors.UserError")
               for line in result.stdout.lines), result.stdout.str()


UNUSED_TEST = '''
import sys


def test_unused():
    print("prc3cfg imported:", sorted(name for name in sys.modules if name.startswith("prc3cfg")))
'''


def test_a_session_that_never_asks_for_the_fixture_imports_nothing_of_prc3cfg_but_the_plugin(pytester):
    """pytest loads the plugin in every session where prc3cfg is installed, and rewrites whatever of prc3cfg
    is imported then: a session that does not use it pays for the plugin module alone."""
    pytester.makeini("[pytest]\n")
    (pytester.path / "test_unused.py").write_text(UNUSED_TEST)
    result = pytester.runpytest_subprocess("-s", "-p", "no:cacheprovider")
    result.assert_outcomes(passed=1)
    plugin_alone = "['prc3cfg', 'prc3cfg.shell', 'prc3cfg.shell.pytest_plugin']"
    assert f"prc3cfg imported: {plugin_alone}" in result.stdout.str(), result.stdout.str()
