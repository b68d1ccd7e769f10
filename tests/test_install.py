"""The README's first command on Debian's own Python, as a newcomer runs it: a virtual environment (PEP 668
refuses `pip install` outside one; plain Debian has no `python`), install, plan, apply against the embedded
emulator — in a copy of this tree, the dependencies from the package index. Soak tier: it installs
from the network, about a minute."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest
from test_docs import readme_commands

ROOT = Path(__file__).resolve().parents[1]
DEBIAN_PYTHON = Path("/usr/bin/python3")


@pytest.mark.soak
@pytest.mark.skipif(not DEBIAN_PYTHON.exists(), reason="no Debian Python at /usr/bin/python3")
def test_the_readme_s_setup_on_debian_s_own_python_installs_plans_and_applies(tmp_path):
    if subprocess.run([DEBIAN_PYTHON, "-c", "import ensurepip, venv"], capture_output=True).returncode != 0:
        pytest.skip("Debian's Python without python3-venv (apt install python3-venv)")
    first = readme_commands("sh")[0]
    assert first.startswith("python3 -m venv .venv && . .venv/bin/activate && python -m pip install . &&")
    tree = tmp_path / "prc3cfg"
    shutil.copytree(ROOT, tree,
                    ignore=shutil.ignore_patterns(".git", ".venv", "__pycache__", "*.egg-info", ".prc3cfg",
                                                  "build", ".*_cache"))
    env = {key: value for key, value in os.environ.items()
           if not key.startswith(("PYTHON", "VIRTUAL_ENV", "PYENV"))}
    env["PATH"] = "/usr/bin:/bin"  # Debian's python3 first: not this test's interpreter, not pyenv's shims
    done = subprocess.run(["bash", "-ec", first], cwd=tree, env=env, capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert "Apply complete: 6 modules written and verified." in done.stdout
    assert (tree / ".venv" / "bin" / "prc3cfg").exists() and "Traceback" not in done.stderr
