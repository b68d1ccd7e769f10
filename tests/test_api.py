"""The API's examples run as written: its docstring's, docs/api.md's, and docs/api.md's plugin test
in a plant repository made of nothing but the built wheel; its values; and links handed to it
already open — the in-memory pair as a real port would be."""

from __future__ import annotations

import contextlib
import difflib
import os
import re
import shutil
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import pytest
import yaml
from emulated import DEMO, emulated_plant, run_cli
from pair import PairPort

import prc3cfg.api
from prc3cfg.core.device import ModuleState
from prc3cfg.core.framing import get_framing
from prc3cfg.shell.emulator.server import Emulator
from prc3cfg.shell.link.client import Link
from prc3cfg.shell.testing import EmulatedPlant

ROOT = Path(__file__).resolve().parents[1]
API_DOC = (ROOT / "docs" / "api.md").read_text()


def doc_block(heading: str) -> str:
    """The first ```python block under a heading of docs/api.md."""
    section = API_DOC.split(f"## {heading}\n", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_the_api_docstring_example_runs(tmp_path, monkeypatch, capsys):
    example = textwrap.dedent(prc3cfg.api.__doc__.split("\n", 1)[1].split("\n(a test runs")[0])
    with emulated_plant(tmp_path):
        monkeypatch.chdir(tmp_path)  # the example's "plant.yaml"
        exec(compile(example, "api.__doc__", "exec"), {})
    assert "travel to reference point: ['booth-a-left'" in capsys.readouterr().out


def test_the_documented_api_example_runs_and_tells_what_it_released(tmp_path, monkeypatch, capsys):
    """It shows the releases and says so (`told`): the commands after it warn of no release nobody was told
    of."""
    (tmp_path / "plants").mkdir()
    shutil.copy(DEMO, tmp_path / "plants" / "demo-line.yaml")  # emulator:// buses, state beside it
    monkeypatch.chdir(tmp_path)
    exec(compile(doc_block("Python API"), "docs/api.md", "exec"), {})
    assert "6 modules to change" in capsys.readouterr().out
    after = run_cli(capsys, "plan", "plants/demo-line.yaml")
    assert after.code == 0 and "may be released" not in after.err, after.err


@pytest.mark.xdist_group("wheel")
def test_the_readme_plugin_test_passes_in_a_plant_repository_made_from_the_wheel(tmp_path, wheel):
    """Install the wheel (with pytest) into a new virtual environment, make a plant repository of
    the demo plant and docs/api.md's test, and run pytest there."""
    assert "prc3cfg/py.typed" in zipfile.ZipFile(wheel).namelist()  # type checkers read the API's annotations
    venv = tmp_path / "venv"
    # no pip in it (ensurepip's unpacking and compiling of pip was a third of the test), this Python's pip
    # installing into it; --no-compile: each module is compiled when the run below imports it, not all of
    # pydantic's and pytest's
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", venv], check=True)
    python = venv / "bin" / "python"
    install = [sys.executable, "-m", "pip", "--python", python, "install", "-q", "--no-compile", wheel,
               "pytest"]
    installed = subprocess.run(install, capture_output=True, text=True)
    assert installed.returncode == 0, installed.stderr
    repository = tmp_path / "plant-repo"
    repository.mkdir()
    shutil.copy(DEMO, repository / "plant.yaml")
    (repository / "test_plant.py").write_text(doc_block("Testing a plant repository"))
    env = {key: value for key, value in os.environ.items()
           if key != "PYTHONPATH"} | {"PRC3CFG_LOCK_DIR": str(tmp_path / "locks")}
    ran = subprocess.run([python, "-m", "pytest", "-q", "-p", "no:cacheprovider"], cwd=repository,
                         capture_output=True, text=True, env=env)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert "1 passed" in ran.stdout
    schema = subprocess.run([venv / "bin" / "prc3cfg", "schema"], capture_output=True, text=True)
    assert schema.returncode == 0 and '"title": "PRC 3 plant"' in schema.stdout


def test_drift_and_adopt_are_api_values(tmp_path):
    """`plan --refresh-only` and `adopt` are the API's: a teach-in shows as drift, adopting it
    rewrites exactly that value, and the file written plans to no changes."""
    with emulated_plant(tmp_path) as emulated:
        prc3cfg.api.apply(emulated.plant, gates=prc3cfg.api.Gates(allow_axis_release=True))
        assert prc3cfg.api.drift(emulated.plant) == []
        bus, module = emulated.plant.modules()[0]
        emulated.emulators[bus.name].teach_in(module.address, 1, 1234)
        said = "program 1 position 2.100 m → 1.234 m"  # says → holds, as adopt
        assert prc3cfg.api.drift(emulated.plant) == [prc3cfg.api.Drift(
            bus.name, module.address, module.name, (said,), ({"program": 1, "field": "P", "before": 2100,
                                                              "after": 1234, "text": said},))]
        adoption = prc3cfg.api.adopt(emulated.plant)
        assert [value.text for value in adoption.adopted] == [
            f"+ {bus.name}/{module.name}: program 1 position 2.100 m → 1.234 m (new in the module: profile "
            "reciprocator keeps its value)"]
        added = [line for line in difflib.ndiff(adoption.before.splitlines(), adoption.after.splitlines())
                 if line[0] in "+-"]
        assert [line.split() for line in added] == [["+", "programs:"], ["+", "1:"],
                                                    ["+", "position:", "1.234"]]
        assert emulated.path.read_text() == adoption.before  # not written yet
        prc3cfg.api.write_adoption(adoption)
        assert emulated.path.read_text() == adoption.after
        assert not prc3cfg.api.plan(prc3cfg.api.load(emulated.path)).changes


def test_an_adoption_is_not_written_over_a_file_edited_meanwhile(tmp_path):
    with emulated_plant(tmp_path) as emulated:
        prc3cfg.api.apply(emulated.plant, gates=prc3cfg.api.Gates(allow_axis_release=True))
        bus, module = emulated.plant.modules()[0]
        emulated.emulators[bus.name].teach_in(module.address, 1, 1234)
        adoption = prc3cfg.api.adopt(emulated.plant)
        emulated.path.write_text(adoption.before + "# edited\n")
        with pytest.raises(prc3cfg.api.UserError, match="changed while adopting — it was not written"):
            prc3cfg.api.write_adoption(adoption)
        assert emulated.path.read_text().endswith("# edited\n")


def test_import_plant_gives_a_plant_file_that_plans_to_no_changes(tmp_path):
    with emulated_plant(tmp_path) as emulated:
        bus = emulated.plant.buses[0]
        text, count = prc3cfg.api.import_plant({"b": prc3cfg.api.BareLine(bus.port, timeout=0.1)},
                                               plant_name="again")
        assert count == len(bus.modules)
        (tmp_path / "imported.yaml").write_text(text)
        imported = prc3cfg.api.load(tmp_path / "imported.yaml")
        assert imported.name == "again" and [b.name for b in imported.buses] == ["b"]
        assert not prc3cfg.api.plan(imported).changes


def paired(tmp_path: Path, stack: contextlib.ExitStack) -> tuple[EmulatedPlant, dict[str, Link]]:
    """The demo plant with ports no link is opened from (TCP ports nothing listens at: an open would
    fail at once), and for each bus a `Link` over the in-memory pair to an emulator of its modules."""
    document = yaml.safe_load(DEMO.read_text())
    for number, bus in enumerate(document["buses"]):
        bus["port"] = f"socket://127.0.0.1:{9 + number}"
    path = tmp_path / "plant.yaml"
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    plant = prc3cfg.api.load(path)
    emulators = {bus.name: stack.enter_context(Emulator({m.address: ModuleState.factory(m.address)
                                                         for m in bus.modules}, framing=bus.framing,
                                                        zvz=bus.zvz, turnaround=bus.turnaround))
                 for bus in plant.buses}
    links = {bus.name: Link(PairPort(emulators[bus.name]), get_framing(bus.framing), bus=bus.name,
                            line=bus.line, timeout=bus.timeout,
                            zvz=bus.zvz) for bus in plant.buses}
    return EmulatedPlant(path, plant, emulators), links


def test_plan_and_apply_through_the_api_over_links_handed_to_it(tmp_path):
    """napalm's driver contract: the API takes links already open — here each a real `Link` over the
    in-memory pair, the same door a real port goes through. No URL is opened, yet the plan reads, the
    apply writes, verifies and keeps its records, and each link is handed back as it was lent."""
    with contextlib.ExitStack() as stack:
        emulated, links = paired(tmp_path, stack)
        plant = emulated.plant
        used: list[Link] = []
        planned = prc3cfg.api.plan(plant, options=prc3cfg.api.LineOptions(used=used.extend), links=links)
        assert {c.bus for c in planned.changes} == {bus.name for bus in plant.buses}
        # the links it used, told to the caller: nothing filled into the options
        assert used == list(links.values())
        result = prc3cfg.api.apply(plant, gates=prc3cfg.api.Gates(allow_axis_release=True), links=links)
        assert result.verified and len(result.runs) == len(planned.changes) and emulated.matches_plant()
        journal = [line for line in result.journal.read_text().splitlines() if '"event": "exchange"' in line]
        # every line's exchanges journalled
        assert all(any(f'"bus": "{bus.name}"' in line for line in journal) for bus in plant.buses)
        prc3cfg.api.told(result)
        assert not prc3cfg.api.plan(plant, links=links).changes
        assert not prc3cfg.api.drift(plant, links=links)
        assert all(link.observer is None and link.announce is None and link.cancel is None
                   for link in links.values())


def test_links_handed_to_the_api_are_one_per_bus_each_for_its_bus(tmp_path):
    with contextlib.ExitStack() as stack:
        emulated, links = paired(tmp_path, stack)
        plant = emulated.plant
        first, second = (bus.name for bus in plant.buses)
        with pytest.raises(prc3cfg.api.UserError,
                           match=f"no link given for bus {second} — give an open link for every bus"):
            prc3cfg.api.read(plant, links={first: links[first]})
        with pytest.raises(prc3cfg.api.UserError,
                           match=f"the link given for bus {first} speaks for bus {second}"):
            prc3cfg.api.plan(plant, links={first: links[second], second: links[first]})
        assert not any(link.exchanges for link in links.values())  # refused before a frame left


def test_a_scan_through_the_api_over_a_link_handed_to_it(tmp_path):
    """A bare line's scan over a link already open (the in-memory pair): the port is locked, never opened."""
    port = "socket://127.0.0.1:9"  # nothing listens: an open would fail at once
    with Emulator({3: ModuleState.factory(3), 7: ModuleState.factory(7)}) as emulator:
        # a short wait at each silent address
        link = Link(PairPort(emulator), get_framing("crc16"), bus=port, timeout=0.02)
        found = prc3cfg.api.scan(prc3cfg.api.BareLine(port), link=link)
    assert sorted(found) == [3, 7] and found[7].system == ModuleState.factory(7).image.system
    assert link.observer is None and link.cancel is None
