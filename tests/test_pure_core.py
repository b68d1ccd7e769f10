"""The pure core imports no `serial` and no `socket` (style.md §"A pure core, a thin shell").

Each module is imported in a fresh interpreter whose import system refuses `serial` and
`socket` (and their submodules), so a core module that reaches for the outside — directly or
through anything it imports — fails here.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: The pure core: what a module does, what a plan is, how it is found, priced and shared.
#: (`render` and `importer` are pure too, but reach pydantic through `prc3cfg.plant`, and
#: pydantic imports `socket` itself.)
CORE = [
    "prc3cfg.image", "prc3cfg.codec", "prc3cfg.device", "prc3cfg.error_codes", "prc3cfg.line", "prc3cfg.framing",
    "prc3cfg.bustime", "prc3cfg.planner", "prc3cfg.verification", "prc3cfg.sharing", "prc3cfg.plantplan",
    "prc3cfg.gateway",
]  # fmt: skip

BLOCKING_IMPORT = """
import importlib, importlib.abc, sys

BLOCKED = ("serial", "socket", "_socket")

class Blocker(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ImportError(f"{name} is blocked: the pure core must not import it")
        return None

for loaded in [m for m in sys.modules if m.split(".")[0] in BLOCKED]:
    del sys.modules[loaded]
sys.meta_path.insert(0, Blocker())
for name in sys.argv[1:]:
    importlib.import_module(name)
print("ok")
"""

PLAIN_IMPORT = "import importlib, sys\nfor name in sys.argv[1:]: importlib.import_module(name)\nprint('ok')"


def run(script: str, *modules: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", script, *modules], cwd=ROOT, capture_output=True, text=True, timeout=60
    )


@pytest.mark.parametrize("module", CORE)
def test_core_module_imports_without_serial_and_socket(module):
    result = run(BLOCKING_IMPORT, module)
    assert result.stdout.strip() == "ok", result.stderr


def test_the_whole_core_imports_together():
    result = run(BLOCKING_IMPORT, *CORE)
    assert result.stdout.strip() == "ok", result.stderr


@pytest.mark.parametrize("module", ["serial", "serial.tools.list_ports", "socket", "socketserver"])
def test_the_blocker_blocks(module):
    """The check itself can fail: a module that imports serial or socket, even indirectly
    (socketserver imports socket), is refused."""
    result = run(BLOCKING_IMPORT, module)
    assert result.returncode != 0
    assert "is blocked: the pure core must not import it" in result.stderr
