"""The folders are the layers, and the pure core imports no `serial` and no `socket`
(style.md §"A pure core, a thin shell").

Each layer imports only the layers below it (read from the source). Each core module is
imported in a fresh interpreter whose import system refuses `serial` and `socket` (and their
submodules), so a core module that reaches for the outside — directly or through anything it
imports — fails here.
"""

from __future__ import annotations

import ast
import importlib
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

PACKAGE = ROOT / "prc3cfg"


def modules_of(folder: str) -> list[str]:
    """Every module of a layer folder, by its dotted name."""
    return sorted(".".join(p.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
                  for p in (PACKAGE / folder).rglob("*.py"))


#: The pure core: every module of `prc3cfg/core/` — what a module holds and does, what a plan
#: is, how it is found, priced, shared and rendered.
CORE = modules_of("core")

#: What each layer may import of prc3cfg (style.md §1: the folders show the layers), without
#: exceptions. The core imports only itself; plant files are read from bytes the shell hands
#: over; the shell never reaches up into the API or the CLI; the API (the workflow: every layer
#: below it) never into the CLI.
MAY_IMPORT = {
    "core": ("prc3cfg.core", "prc3cfg.errors"),
    "plant": ("prc3cfg.core", "prc3cfg.plant", "prc3cfg.errors"),
    "shell": ("prc3cfg.core", "prc3cfg.plant", "prc3cfg.shell", "prc3cfg.errors"),
    "api": ("prc3cfg.core", "prc3cfg.plant", "prc3cfg.shell", "prc3cfg.api", "prc3cfg.errors"),
}


def prc3cfg_imports(path: Path) -> set[str]:
    """The prc3cfg modules a file imports (`from prc3cfg.x import y` gives prc3cfg.x.y and prc3cfg.x)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.split(".")[0] == "prc3cfg")
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "prc3cfg":
            found.update(f"{node.module}.{a.name}" for a in node.names)
    return found


def allowed(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes) or name == "prc3cfg.__version__"


@pytest.mark.parametrize("layer", sorted(MAY_IMPORT))
def test_each_layer_imports_only_the_layers_below_it(layer):
    wrong = {f"{path.relative_to(ROOT)} imports {name}"
             for path in (PACKAGE / layer).rglob("*.py")
             for name in prc3cfg_imports(path) if not allowed(name, MAY_IMPORT[layer])}
    assert not wrong, sorted(wrong)


#: What the core never imports (issue 43): it takes no lock and starts no thread — the lines' threads
#: take turns with it in the shell (`prc3cfg.shell.planning`) — and it never waits on anything.
CORE_NEVER = ("threading", "_thread", "concurrent", "multiprocessing", "asyncio", "queue", "time")


def test_the_core_never_locks_nor_waits():
    found = {f"{path.relative_to(ROOT)} imports {alias.name if isinstance(node, ast.Import) else node.module}"
             for path in (PACKAGE / "core").rglob("*.py")
             for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
             if isinstance(node, ast.Import | ast.ImportFrom)
             for alias in node.names
             if ((alias.name if isinstance(node, ast.Import) else node.module or "").split(".")[0]
                 in CORE_NEVER)}
    assert not found, sorted(found)


#: What the command line may import: the API, and what it needs to parse arguments, ask and render
#: (style.md §1: "The CLI parses arguments, asks, and renders: nothing else"). The workflow's
#: parts — planner, device model, read-back, apply, locks, records, adopt, importer — only through
#: `prc3cfg.api`.
CLI_MAY_IMPORT = (
    "prc3cfg.api", "prc3cfg.cli", "prc3cfg.errors",
    # rendering, and the values it shows
    "prc3cfg.core.render", "prc3cfg.core.events", "prc3cfg.core.text", "prc3cfg.core.units",
                  "prc3cfg.core.line.LineSettings",
    "prc3cfg.core.fleet.markdown",  # the fleet summary's table
    "prc3cfg.core.plant_plan.PlantPlan", "prc3cfg.shell.link.client.Link",
    # the plan file `plan --out` writes (reading one back is the workflow's: `api.read_plan`)
    "prc3cfg.core.plan_file.write",
    # plant files: loading one is validating it; showing one shows where each value came from
    "prc3cfg.plant.Module", "prc3cfg.plant.Plant", "prc3cfg.plant.PlantError",
    "prc3cfg.plant.plant_schema_text", "prc3cfg.plant.profiles.Sourced",
    "prc3cfg.plant.problems.Finding",
    # the terminal: Ctrl-C, output files
    "prc3cfg.shell.cancel", "prc3cfg.shell.files.write_atomically", "prc3cfg.shell.platform.open_text",
    "prc3cfg.shell.platform.command_line",  # a command printed for a person, quoted for their shell
)


def test_the_command_line_reaches_the_workflow_only_through_the_api():
    wrong = {f"{path.relative_to(ROOT)} imports {name}"
             for path in (PACKAGE / "cli").rglob("*.py")
             for name in prc3cfg_imports(path) if not allowed(name, CLI_MAY_IMPORT)}
    assert not wrong, sorted(wrong)
    assert not allowed("prc3cfg.plant.adopt.adopt", CLI_MAY_IMPORT)  # the check can fail
    inside = {f"{path.relative_to(ROOT)} imports {name}" for path in (PACKAGE / "cli").rglob("*.py")
              for name in prc3cfg_imports(path) if name.startswith("prc3cfg.api._")}
    assert not inside, sorted(inside)  # the API's own modules are its inside: the CLI calls `prc3cfg.api`


def test_the_api_never_reaches_into_the_command_line():
    """The API sits between the layers and the CLI: it may import every layer, never the CLI."""
    # the check reads something
    assert len(list((PACKAGE / "api").glob("*.py"))) > 1 and prc3cfg_imports(PACKAGE / "api" / "_apply.py")
    assert not {name for path in (PACKAGE / "api").rglob("*.py") for name in prc3cfg_imports(path)
                if allowed(name, ("prc3cfg.cli",))}


def test_the_layer_check_can_fail():
    """A core module that reached for the shell would be caught."""
    assert not allowed("prc3cfg.shell.link.client.Link", MAY_IMPORT["core"])
    assert any(not allowed(name, MAY_IMPORT["core"])
               for name in prc3cfg_imports(PACKAGE / "shell" / "readback.py"))


def test_every_module_is_in_a_layer():
    """Only the package's entry points live outside a layer folder."""
    top = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert top == ["__init__.py", "__main__.py", "errors.py"]
    assert sorted(p.name for p in PACKAGE.iterdir() if p.is_dir() and p.name != "__pycache__") == [
        "api", "cli", "core", "plant", "shell"]


def third_party_of_core() -> list[str]:
    """The packages outside the standard library the core imports at module level (pydantic):
    our dependencies, whose own imports are theirs — some releases of typing_extensions, which
    pydantic_core uses, import asyncio and with it socket."""
    found: set[str] = set()
    for path in (PACKAGE / "core").rglob("*.py"):
        for node in ast.parse(path.read_text()).body:
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else [])
            found.update(n.split(".")[0] for n in names)
    return sorted(found - set(sys.stdlib_module_names) - {"prc3cfg", "__future__"})


def test_the_core_has_third_party_imports_to_load_first():
    assert "pydantic" in third_party_of_core()  # the list is read from the source, not empty


BLOCKING_IMPORT = """
import importlib, importlib.abc, sys

for dependency in sys.argv[1].split(","):  # loaded before the blocker: their imports are theirs
    importlib.import_module(dependency)

BLOCKED = ("serial", "socket", "_socket")

class Blocker(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ImportError(f"{name} is blocked: the pure core must not import it")
        return None

for loaded in [m for m in sys.modules if m.split(".")[0] in BLOCKED]:
    del sys.modules[loaded]
sys.meta_path.insert(0, Blocker())
for name in sys.argv[2:]:
    importlib.import_module(name)
print("ok")
"""


#: BLOCKING_IMPORT of each module alone, in one process: a child forked for each from a parent that has loaded
#: the dependencies and the blocker and nothing of prc3cfg — what a process of its own would hold, without an
#: interpreter's start-up a module (40 of them: 18 s of the fast tier, one process each). POSIX's fork: the
#: fast tier runs on Linux.
BLOCKING_EACH = BLOCKING_IMPORT.replace("""for name in sys.argv[2:]:
    importlib.import_module(name)
print("ok")""", """import json, os, traceback
said = {}
for name in sys.argv[2:]:
    read, write = os.pipe()
    child = os.fork()
    if child == 0:
        os.close(read)
        try:
            importlib.import_module(name)
            message = "ok"
        except BaseException:
            message = traceback.format_exc()
        os.write(write, message.encode())
        os._exit(0)
    os.close(write)
    with os.fdopen(read, "rb") as pipe:
        said[name] = pipe.read().decode()
    os.waitpid(child, 0)
print(json.dumps(said))""")


def run(script: str, *modules: str) -> subprocess.CompletedProcess[str]:
    first = [",".join(third_party_of_core())] if script in (BLOCKING_IMPORT, BLOCKING_EACH) else []
    return subprocess.run(
        [sys.executable, "-c", script, *first, *modules], cwd=ROOT, capture_output=True, text=True, timeout=60
    )


@pytest.fixture(scope="module")
def imported_alone() -> dict[str, str]:
    """Each core module imported alone behind the blocker: module → "ok" or its traceback."""
    result = run(BLOCKING_EACH, *CORE)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


@pytest.mark.xdist_group("core_imported_alone")  # one worker runs the fixture's one process for all 40
@pytest.mark.parametrize("module", CORE)
def test_core_module_imports_without_serial_and_socket(module, imported_alone):
    assert imported_alone[module] == "ok"


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


def test_the_blocker_blocks_in_each_forked_child_alone():
    said = json.loads(run(BLOCKING_EACH, "socketserver", "prc3cfg.core.codec", "serial").stdout)
    assert ("is blocked: the pure core must not import it" in said["socketserver"]
            and said["prc3cfg.core.codec"] == "ok")
    # socketserver's child loaded nothing for the next
    assert "is blocked: the pure core must not import it" in said["serial"]


def api_names_used(path: Path) -> set[str]:
    """The names a file takes from `prc3cfg.api`: `api.NAME`, and `from prc3cfg.api import NAME`."""
    tree = ast.parse(path.read_text())
    used = {node.attr for node in ast.walk(tree) if isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name) and node.value.id == "api"}
    used |= {a.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
             and node.module == "prc3cfg.api" for a in node.names}
    return used


def test_the_command_line_calls_only_what_the_api_exports():
    """`prc3cfg.api.__all__` is what the CLI (and a user's script) calls: the CLI reaches nothing else of
    it."""
    import prc3cfg.api

    used = {name: path.relative_to(ROOT) for path in (PACKAGE / "cli").rglob("*.py")
            for name in api_names_used(path)}
    assert used.keys() >= {"apply", "plan", "LineOptions"}  # the check sees what the CLI uses
    assert not {f"{path} uses api.{name}" for name, path in used.items() if name not in prc3cfg.api.__all__}
    assert all(hasattr(prc3cfg.api, name) for name in prc3cfg.api.__all__)


@pytest.mark.parametrize("package", ["prc3cfg.api", "prc3cfg.core.render"])
def test_a_lazy_package_imports_each_name_from_where_the_type_checker_finds_it(package):
    """`prc3cfg.api` and `prc3cfg.core.render` import each name when first asked for, from its module in
    `_HOMES` (`prc3cfg.core.lazy`); the type checker reads the imports under TYPE_CHECKING: the two say the
    same, name for name, and a name that is in neither is no name of the package."""
    lazy = importlib.import_module(package)
    path = PACKAGE.parent.joinpath(*package.split("."), "__init__.py")
    tree = ast.parse(path.read_text())
    (checking,) = [node for node in tree.body if isinstance(node, ast.If)
                   and getattr(node.test, "id", None) == "TYPE_CHECKING"]
    imported = {(node.module, a.name) for node in checking.body if isinstance(node, ast.ImportFrom)
                for a in node.names if a.asname == a.name}
    homes = {(module, name) for module, names in lazy._HOMES.items() for name in names}
    assert len(imported) == len(checking.body) == len(homes) and imported == homes
    # a module named as a name of the package would hide that name once imported (Python binds it there)
    assert not {home.removeprefix(f"{package}.") for home in lazy._HOMES} & {name for _, name in homes}
    assert all(getattr(lazy, name) is getattr(importlib.import_module(home), name) for home, name in homes)
    assert {name for _, name in homes} <= set(dir(lazy))
    with pytest.raises(AttributeError, match=f"module '{package}' has no attribute 'nothing_of_this_name'"):
        lazy.nothing_of_this_name  # noqa: B018 — a name outside the package is no name of it


def test_every_module_of_the_package_imports():
    """Each module imported in a fresh interpreter: an annotation evaluated at import (a module without
    `from __future__ import annotations`) that names a type imported only for the type checker fails here, not
    at the first run of its command."""
    modules = sorted(".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
                     for path in (ROOT / "prc3cfg").rglob("*.py"))
    script = "import importlib, sys\nfor name in sys.argv[1:]:\n    importlib.import_module(name)\n"
    done = subprocess.run([sys.executable, "-c", script, *modules], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr
