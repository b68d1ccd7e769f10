"""The entry point ends the process at once when a command is done (`prc3cfg.__main__`): what the
command said is all there, its exit code is the command's, and a profiler still gets to write what
it found."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

from tests.emulated import emulated_plant

ROOT = Path(__file__).resolve().parents[1]


def test_a_large_output_is_whole_and_the_exit_code_the_commands(tmp_path):
    with emulated_plant(tmp_path) as plant:
        done = subprocess.run([sys.executable, "-m", "prc3cfg", "plan", plant.path, "--json",
                               "--detailed-exitcode"],
                              capture_output=True, text=True)
    assert done.returncode == 2, done.stderr  # changes: exit 2, as the command returned it
    assert json.loads(done.stdout)["buses"]  # the whole document, flushed before the process ended


def test_an_error_is_said_and_its_exit_code_kept(tmp_path):
    done = subprocess.run([sys.executable, "-m", "prc3cfg", "validate", tmp_path / "missing.yaml"],
                          capture_output=True, text=True)
    assert done.returncode == 1
    assert done.stderr.startswith("error: ") and done.stderr.endswith("\n")


def test_a_profiler_still_writes_its_profile(tmp_path):
    profile = tmp_path / "help.prof"
    done = subprocess.run([sys.executable, "-m", "cProfile", "-o", profile, "-m", "prc3cfg", "--help"],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert profile.stat().st_size > 0


def in_cp1252(**extra: str) -> dict[str, str]:
    """The environment of a process whose stdout and stderr would write cp1252 (a Windows code page)."""
    return os.environ | {"PYTHONIOENCODING": "cp1252", "PYTHONUTF8": "0"} | extra


def test_the_schema_is_written_whole_whatever_the_code_page(tmp_path):
    """`prc3cfg schema > file` under cp1252: the schema holds → and —, which cp1252 cannot encode in part."""
    written = tmp_path / "plant.schema.json"
    with open(written, "wb") as file:
        done = subprocess.run([sys.executable, "-m", "prc3cfg", "schema"], stdout=file,
                              stderr=subprocess.PIPE, env=in_cp1252())
    assert done.returncode == 0, done.stderr.decode()
    assert written.read_bytes() == (ROOT / "schemas" / "plant.schema.json").read_bytes()


def test_the_schema_written_with_out_is_the_schema_in_utf_8(tmp_path):
    """`prc3cfg schema --out FILE`: what PowerShell 5.1's `>` cannot do (it writes UTF-16) — UTF-8, whatever
    the code page."""
    written = tmp_path / "plant.schema.json"
    done = subprocess.run([sys.executable, "-m", "prc3cfg", "schema", "--out", str(written)],
                          capture_output=True, env=in_cp1252())
    assert done.returncode == 0 and done.stdout == b"", done.stderr.decode()
    assert written.read_bytes() == (ROOT / "schemas" / "plant.schema.json").read_bytes()


def test_a_plan_piped_on_prints_its_signs_whatever_the_code_page(tmp_path):
    """`prc3cfg plan plants/demo-line.yaml | cat` under cp1252: ⚠ and → in UTF-8, no traceback."""
    plant = tmp_path / "demo-line.yaml"
    shutil.copy(ROOT / "plants" / "demo-line.yaml", plant)
    done = subprocess.run([sys.executable, "-m", "prc3cfg", "plan", str(plant)], capture_output=True,
                          env=in_cp1252())
    assert done.returncode == 0, done.stderr.decode()
    assert b"Traceback" not in done.stderr
    text = done.stdout.decode("utf-8")
    assert "→" in text and "⚠" in text


def test_an_error_names_a_file_whatever_the_code_page(tmp_path):
    """stderr too: a one-line error naming a path with a character cp1252 lacks."""
    missing = tmp_path / "línea→1.yaml"
    done = subprocess.run([sys.executable, "-m", "prc3cfg", "validate", str(missing)], capture_output=True,
                          env=in_cp1252())
    assert done.returncode == 1
    assert done.stderr.decode("utf-8").startswith("error: ") and "línea→1.yaml" in done.stderr.decode("utf-8")
