"""The entry point ends the process at once when a command is done (`prc3cfg.__main__`): what the
command said is all there, its exit code is the command's, and a profiler still gets to write what
it found."""

from __future__ import annotations

import json
import subprocess
import sys

from tests.emulated import emulated_plant


def test_a_large_output_is_whole_and_the_exit_code_the_commands(tmp_path):
    with emulated_plant(tmp_path) as plant:
        done = subprocess.run([sys.executable, "-m", "prc3cfg", "plan", plant.path, "--json", "--detailed-exitcode"],
                              capture_output=True, text=True)  # fmt: skip
    assert done.returncode == 2, done.stderr  # changes: exit 2, as the command returned it
    assert json.loads(done.stdout)["buses"]  # the whole document, flushed before the process ended


def test_an_error_is_said_and_its_exit_code_kept(tmp_path):
    done = subprocess.run([sys.executable, "-m", "prc3cfg", "validate", tmp_path / "missing.yaml"], capture_output=True, text=True)
    assert done.returncode == 1
    assert done.stderr.startswith("error: ") and done.stderr.endswith("\n")


def test_a_profiler_still_writes_its_profile(tmp_path):
    profile = tmp_path / "help.prof"
    done = subprocess.run([sys.executable, "-m", "cProfile", "-o", profile, "-m", "prc3cfg", "--help"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert profile.stat().st_size > 0
