"""What every test shares: a lock directory of its own, the demo plant on emulators, the
worktree's wheel, the hypothesis profile of its tier, and the command line's click command built once.

The suite has two tiers: `pytest` runs the fast one (the README's command), `pytest -m soak`
the tests marked `soak` — many races, seeds or examples of behaviours the fast tier tests with
a few. `PRC3CFG_HYPOTHESIS_PROFILE` names the hypothesis profile: "fast" (the default) or
"soak" (`.ci/run` sets it for the soak tier). A property of the fast tier names its own small
count; its soak sibling names none and tries the profile's: 2,000 examples under "soak" (the
most any acceptance asked for), hypothesis's 100 under "fast" — a quick look at the soak tier —
unless one example takes about a second (the choice of broadcasts: 600, some 9 minutes).
Both profiles are derandomised: a run tries the examples the run before tried, and a failure
found once is found again.
"""

from __future__ import annotations

import compileall
import os
import subprocess
import sys
from pathlib import Path

import pytest

# The bytecode pytest writes as it rewrites asserts is kept, whatever PYTHONDONTWRITEBYTECODE says (CI images
# set it): pytest rewrites each test module as it collects it — and each module of prc3cfg (the distribution
# of a pytest plugin, `prc3cfg.shell.pytest_plugin`, is rewritten whole) — and keeps what it wrote only where
# bytecode may be written. Set before anything of prc3cfg is imported (here, by `emulated`; the plugin
# imports none of it): without it each worker rewrote every test module and every module of prc3cfg on
# every run (collection 4.7 to 5.4 s of CPU a worker, 3.4 s with what was rewritten kept).
sys.dont_write_bytecode = False

import typer.main  # noqa: E402 — after the line above
from emulated import emulated_plant  # noqa: E402
from hypothesis import settings  # noqa: E402

settings.register_profile("fast", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("soak", parent=settings.get_profile("fast"), max_examples=2_000)
settings.load_profile(os.environ.get("PRC3CFG_HYPOTHESIS_PROFILE", "fast"))

ROOT = Path(__file__).resolve().parents[1]

_built: dict[tuple, tuple[typer.Typer, object]] = {}
_get_command = typer.main.get_command


def _shape(app: typer.Typer) -> tuple:
    """What a typer app's click command is built from that can change: the commands and groups registered."""
    return (id(app), len(app.registered_commands),
            tuple(_shape(group.typer_instance) for group in app.registered_groups if group.typer_instance))


def _get_command_once(app: typer.Typer):
    """typer builds the whole click command tree again on every call of the app (0.065 s of CPU for prc3cfg's
    36 commands: the type hints and signatures of each) — once a process for the console script, but once
    for each of the thousands of commands the tests run in this process (`run_cli`). Built once for each
    shape of the app instead; the only input typer reads besides the app is this environment variable."""
    key = (_shape(app), os.environ.get("_TYPER_COMPLETE_TEST_DISABLE_SHELL_DETECTION"))
    if key not in _built:  # the app kept with its command: while it is, no other app is given its id
        _built[key] = (app, _get_command(app))
    return _built[key][1]


typer.main.get_command = _get_command_once


def pytest_configure(config: pytest.Config) -> None:
    """prc3cfg's bytecode written once, before any test: the tests start `python -m prc3cfg` hundreds of
    times, and where PYTHONDONTWRITEBYTECODE is set (CI images set it) and the tree is a fresh clone, each of
    those processes would compile every module it imports again — 0.15 s of a `plan`'s 0.37 s. Up-to-date
    files are left as they are, so the workers' calls cost a `stat` each."""
    compileall.compile_dir(ROOT / "prc3cfg", quiet=2)


def pytest_xdist_auto_num_workers(config) -> int:
    """`-n auto` (pyproject.toml's addopts): three workers a core, not one. The fast tier waits far more than
    it computes — on emulated lines at their speed, for the processes it starts, on terminals — so one worker
    a core left both cores idle most of the run (4 min 47 s of CPU in 6 min 33 s on 2 cores). More a core use
    that time: on 2 idle cores, 29 November 2026, 4 workers took 218 s, 6 took 194 s, 8 took 193 s. The
    tests stay correct under load because none asserts a wall-clock time."""
    return 3 * (os.cpu_count() or 1)


@pytest.fixture(autouse=True)
def private_locks(tmp_path, monkeypatch):
    """Line locks, serial devices' lock files and records of untold axis releases in the test's
    own folder: tests running at once never wait for each other, and a test that kills an apply
    leaves nothing to the next."""
    monkeypatch.setenv("PRC3CFG_LOCK_DIR", str(tmp_path / "locks"))
    monkeypatch.setenv("PRC3CFG_STATE_DIR", str(tmp_path / "state"))
    # the serial devices' LCK.. files: machine state, left to the tests that mean it
    (tmp_path / "uucp").mkdir()
    monkeypatch.setenv("PRC3CFG_UUCP_LOCK_DIR", str(tmp_path / "uucp"))
    # a machine's list of its lines: the tests' emulators are none of them
    monkeypatch.delenv("PRC3CFG_PORTS", raising=False)


@pytest.fixture
def plant(tmp_path):
    """The demo plant (`plants/demo-line.yaml`) with every bus on an emulator, factory modules."""
    with emulated_plant(tmp_path) as emulated:
        yield emulated


@pytest.fixture(scope="session")
def wheel(tmp_path_factory) -> Path:
    """The worktree's wheel, as a release builds it (`.ci/release --wheel-only`: from a copy of the
    sources), once a session. Tests using it are in the xdist group "wheel", so one worker builds it once."""
    wheels = tmp_path_factory.mktemp("wheels")
    built = subprocess.run([sys.executable, ROOT / ".ci" / "release", "--wheel-only", "--out", wheels],
                           capture_output=True, text=True)
    assert built.returncode == 0, built.stderr
    (path,) = wheels.glob("prc3cfg-*.whl")
    return path
