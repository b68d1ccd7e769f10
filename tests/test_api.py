"""The API's examples run as written: its docstring's, the README's, and the README's plugin test
in a plant repository made of nothing but the built wheel."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import pytest
from emulated import DEMO, emulated_plant

import prc3cfg.api

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def readme_block(heading: str) -> str:
    """The first ```python block under a README heading."""
    section = README.split(f"## {heading}\n", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


@pytest.fixture(autouse=True)
def private_locks(tmp_path, monkeypatch):
    monkeypatch.setenv("PRC3CFG_LOCK_DIR", str(tmp_path / "locks"))


def test_the_api_docstring_example_runs(tmp_path, monkeypatch, capsys):
    example = textwrap.dedent(prc3cfg.api.__doc__.split("\n", 1)[1].split("\n(a test runs")[0])
    with emulated_plant(tmp_path):
        monkeypatch.chdir(tmp_path)  # the example's "plant.yaml"
        exec(compile(example, "api.__doc__", "exec"), {})
    assert "travel to reference point: ['booth-a-left'" in capsys.readouterr().out


def test_the_readme_api_example_runs(tmp_path, monkeypatch, capsys):
    (tmp_path / "plants").mkdir()
    shutil.copy(DEMO, tmp_path / "plants" / "demo-line.yaml")  # emulator:// buses, state beside it
    monkeypatch.chdir(tmp_path)
    exec(compile(readme_block("Python API"), "README.md", "exec"), {})
    assert "6 modules to change" in capsys.readouterr().out


def test_the_readme_plugin_test_passes_in_a_plant_repository_made_from_the_wheel(tmp_path):
    """Build the wheel, install it (with pytest) into a new virtual environment, make a plant
    repository of the demo plant and the README's test, and run pytest there."""
    wheels = tmp_path / "wheels"
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-w", wheels, ROOT], capture_output=True, text=True)
    assert built.returncode == 0, built.stderr
    (wheel,) = wheels.glob("prc3cfg-*.whl")
    assert "prc3cfg/py.typed" in zipfile.ZipFile(wheel).namelist()  # type checkers read the API's annotations
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", venv], check=True)
    python = venv / "bin" / "python"
    installed = subprocess.run([python, "-m", "pip", "install", "-q", wheel, "pytest"], capture_output=True, text=True)
    assert installed.returncode == 0, installed.stderr
    repository = tmp_path / "plant-repo"
    repository.mkdir()
    shutil.copy(DEMO, repository / "plant.yaml")
    (repository / "test_plant.py").write_text(readme_block("Testing a plant repository"))
    env = {key: value for key, value in os.environ.items() if key != "PYTHONPATH"} | {"PRC3CFG_LOCK_DIR": str(tmp_path / "locks")}
    ran = subprocess.run([python, "-m", "pytest", "-q", "-p", "no:cacheprovider"], cwd=repository, capture_output=True, text=True, env=env)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert "1 passed" in ran.stdout
    schema = subprocess.run([venv / "bin" / "prc3cfg", "schema"], capture_output=True, text=True)
    assert schema.returncode == 0 and '"title": "PRC 3 plant"' in schema.stdout
