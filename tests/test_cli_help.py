"""`prc3cfg --help` is quick because the commands import what they use only when they run: listing them loads
typer and prc3cfg's command modules, never the plant loader, the planner, the link, rich, nor the standard
library's logging, sockets, hashes or thread pools; a command that talks on no line (`plan --actual`,
`validate`) loads no link; a plan loads no doctor, no importer, no rich when nothing it writes to is a
terminal, and no emulator server unless its port is `emulator://`. (How fast: bench/startup_bench.py.)"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
import typer
from emulated import DEMO, emulated_plant

from prc3cfg.cli.common import ADDRESSES, DATA_BITS, FRAMING_NAMES, PARITY_NAMES, STOP_BITS, VerifyChoice
from prc3cfg.core import line
from prc3cfg.core.device import ModuleState
from prc3cfg.core.framing import FRAMINGS
from prc3cfg.core.image import MAX_MODULE_ADDRESS
from prc3cfg.shell.apply import Verify as ApplyVerify
from prc3cfg.shell.plant_files import load_plant

LISTING = """
import sys
from prc3cfg.cli import main
try:
    main({args})
except SystemExit:
    pass
heavy = sorted(m for m in sys.modules if m.split(".")[0] in {tops}
               or m in ("prc3cfg.api", "prc3cfg.core.planner", "prc3cfg.shell.link", "prc3cfg.plant",
                        "prc3cfg.shell.emulator"))
print("heavy:", heavy, file=sys.stderr)
"""
#: What the listing of the commands loads none of (the modules' first names): json and html are a records
#: command's output and `core.text`'s markdown, imported where they run.
LISTING_SPARES = ("pydantic", "serial", "yaml", "rich", "logging", "socket", "hashlib", "concurrent",
                  "secrets", "json", "html")
#: The whole of prc3cfg that `prc3cfg --help` loads besides the command modules: what their signatures and
#: `main` use.
LISTING_LOADS = ["prc3cfg", "prc3cfg.__main__", "prc3cfg.cli", "prc3cfg.cli.common", "prc3cfg.cli.durations",
                 "prc3cfg.core", "prc3cfg.core.text", "prc3cfg.errors", "prc3cfg.shell",
                 "prc3cfg.shell.cancel", "prc3cfg.shell.platform"]


def test_listing_the_commands_loads_nothing_heavy():
    done = subprocess.run([sys.executable, "-c", LISTING.format(args=["--help"], tops=LISTING_SPARES)],
                          capture_output=True, text=True)
    assert "Commands" in done.stdout and "apply" in done.stdout
    assert done.stderr.strip() == "heavy: []"


def test_the_listing_loads_of_prc3cfg_its_command_modules_and_what_they_need_only():
    """`prc3cfg --help` as the console script runs it: a module a command module imports at its top (for a
    default, an annotation) is paid by every start-up — one more here is a decision, not an accident."""
    probe = ("import sys, prc3cfg.__main__\nfrom prc3cfg.cli import main\ntry:\n    main(['--help'])\n"
             "except SystemExit:\n    pass\n"
             "print(sorted(m for m in sys.modules if m.startswith('prc3cfg')), file=sys.stderr)")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    from prc3cfg.cli import COMMAND_MODULES

    commands = {f"prc3cfg.cli.{module}" for module in COMMAND_MODULES.values()}
    assert "Commands" in done.stdout, done.stderr
    assert done.stderr.strip().splitlines()[-1] == str(sorted([*LISTING_LOADS, *commands]))


def test_the_commands_signatures_are_objects_not_strings():
    """typer reads a command's signature three or four times to build it (its parameters, its callback, …)
    and evaluates a string annotation (`from __future__ import annotations`) each time: 12 of the listing's
    25 ms CPU. The modules that declare commands write their annotations as objects, quoting only what only
    mypy imports."""
    from prc3cfg.cli import _register_commands, app

    _register_commands()

    def callbacks(group: typer.Typer):
        yield from (info.callback for info in group.registered_commands)
        yield from (group.registered_callback.callback,) if group.registered_callback else ()
        for sub in group.registered_groups:
            yield from callbacks(sub.typer_instance)

    strings = [f"{f.__module__}.{f.__name__}: {name}" for f in callbacks(app)
               for name, annotation in f.__annotations__.items() if isinstance(annotation, str)]
    assert strings == []


def test_the_table_of_command_modules_is_what_the_modules_register():
    """`COMMAND_MODULES` names each command's and group's module, in the listing's order: a command
    line loads only the module its table entry names, so an entry that is wrong runs no command."""
    from prc3cfg.cli import COMMAND_MODULES, _register_commands, app

    _register_commands()
    registered = [(info.name or typer.main.get_command_name(info.callback.__name__), info.callback.__module__)
                  for info in app.registered_commands]
    registered += [(group.name,
                    {c.callback.__module__ for c in group.typer_instance.registered_commands}.pop())
                   for group in app.registered_groups]
    assert sorted(registered) == sorted((name, f"prc3cfg.cli.{module}")
                                        for name, module in COMMAND_MODULES.items())
    listed = typer.main.get_command(app).list_commands(None)
    assert listed == list(COMMAND_MODULES)


@pytest.mark.parametrize("command", ["validate", "records", "emulator"])
def test_a_command_line_loads_only_its_command_s_module(command):
    """typer builds every registered command before it runs one: a command line registers its own module's
    only."""
    probe = f"""
import sys
from prc3cfg.cli import main
try:
    main([{command!r}, "--help"])
except SystemExit:
    pass
print(sorted(m for m in sys.modules if m.endswith("_commands")), file=sys.stderr)
"""
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    from prc3cfg.cli import COMMAND_MODULES

    assert done.stderr.strip() == str([f"prc3cfg.cli.{COMMAND_MODULES[command]}"]), done.stderr


def test_the_names_the_help_uses_are_the_real_ones():
    assert FRAMING_NAMES == tuple(FRAMINGS)
    assert ADDRESSES == range(1, MAX_MODULE_ADDRESS + 1)
    assert (PARITY_NAMES, DATA_BITS, STOP_BITS) == (line.PARITIES, (line.FRAME_DATA_BITS,), line.STOP_BITS)
    assert [v.value for v in VerifyChoice] == [v.value for v in ApplyVerify]


#: Runs the command line's arguments in this process, then names what of the link and the emulator got loaded.
LOADED_BY = """
import sys
from prc3cfg.cli import main
try:
    main(sys.argv[1:])
except SystemExit as stop:
    assert not stop.code, stop.code
loaded = sorted(m for m in sys.modules if m.split(".")[0] == "serial"
                or m.startswith(("prc3cfg.shell.link.", "prc3cfg.shell.emulator.")))
print("loaded:", loaded, file=sys.stderr)
"""


def test_a_plan_against_saved_images_loads_no_link(tmp_path):
    """`plan --actual` talks on no line: neither pyserial nor the link nor the emulator is loaded for it."""
    plant = tmp_path / "plant.yaml"
    plant.write_text(DEMO.read_text())
    images = tmp_path / "images.json"
    images.write_text(json.dumps([{"bus": bus.name, **ModuleState.factory(m.address).image.to_json()}
                                  for bus in load_plant(plant).buses for m in bus.modules]))
    done = subprocess.run([sys.executable, "-c", LOADED_BY, "plan", str(plant), "--actual", str(images)],
                          capture_output=True, text=True)
    assert "booth-a-left" in done.stdout, done.stderr  # the plan was made and shown
    assert done.stderr.strip().splitlines()[-1] == "loaded: []"
    validated = subprocess.run([sys.executable, "-c", LOADED_BY, "validate", str(plant)], capture_output=True,
                               text=True)
    assert validated.stderr.strip().splitlines()[-1] == "loaded: []"


#: Runs the command line's arguments in this process (stdout and stderr pipes), then names what it loaded of
#: these.
LOADED_OF = """
import sys
from prc3cfg.cli import main
try:
    main(sys.argv[1:])
except SystemExit as stop:
    assert stop.code in (0, 2), stop.code
loaded = sorted(m for m in sys.modules if m.split(".")[0] == "rich"
                or m in ("prc3cfg.shell.doctor", "prc3cfg.plant.importer", "prc3cfg.shell.emulator.server",
                         "prc3cfg.core.policy", "prc3cfg.plant.policy", "prc3cfg.plant.adopt",
                         "prc3cfg.core.render.comment", "prc3cfg.core.render.show"))
print("loaded:", loaded, file=sys.stderr)
"""


def test_a_plan_loads_what_it_runs_only(tmp_path):
    """Piped, `plan` loads no rich (its progress bar and colours are for a terminal), nor doctor's search or
    the importer (it asks only whether doctor could measure a port), nor the policy's rules where the plant
    file names no policy, nor adopt's rewriting, nor the pull-request comment or `show`'s words (nor does
    `apply`); on `emulator://` it runs the emulator, on `socket://` it does not."""
    plant = tmp_path / "plant.yaml"
    plant.write_text(DEMO.read_text())
    on_emulator = subprocess.run([sys.executable, "-c", LOADED_OF, "plan", str(plant)], capture_output=True,
                                 text=True, cwd=tmp_path,
                                 env=_no_terminal())
    assert "booth-a-left" in on_emulator.stdout, on_emulator.stderr
    assert on_emulator.stderr.strip().splitlines()[-1] == "loaded: ['prc3cfg.shell.emulator.server']"
    (tmp_path / "socket").mkdir()
    with emulated_plant(tmp_path / "socket") as emulated:
        on_socket = subprocess.run([sys.executable, "-c", LOADED_OF, "plan", str(emulated.path)],
                                   capture_output=True, text=True,
                                   cwd=tmp_path, env=_no_terminal())
    assert "booth-a-left" in on_socket.stdout, on_socket.stderr
    assert on_socket.stderr.strip().splitlines()[-1] == "loaded: []"
    applied = subprocess.run([sys.executable, "-c", LOADED_OF, "apply", str(plant), "--auto-approve",
                              "--allow-axis-release"],
                             capture_output=True, text=True, cwd=tmp_path, env=_no_terminal())
    assert "Apply complete" in applied.stdout, applied.stderr
    assert applied.stderr.strip().splitlines()[-1] == "loaded: ['prc3cfg.shell.emulator.server']"


def test_a_plan_loads_the_policy_its_plant_file_names(tmp_path):
    """The other side of `test_a_plan_loads_what_it_runs_only`: a plant file that names a policy has it loaded
    and judged."""
    plant = tmp_path / "plant.yaml"
    plant.write_text(DEMO.read_text() + "\npolicy: rules.yaml\n")
    (tmp_path / "rules.yaml").write_text("format: prc3cfg-policy/1\nenvelopes:\n  - name: booth speeds\n    "
                                         "level: advisory\n"
                                         "    buses: [booth-a]\n    limits:\n      speed: "
                                         "{max: 0.300}\n")
    done = subprocess.run([sys.executable, "-c", LOADED_OF, "plan", str(plant)], capture_output=True,
                          text=True, cwd=tmp_path,
                          env=_no_terminal())
    said = done.stdout + done.stderr
    assert "Policy" in said and "booth speeds" in said, said
    assert done.stderr.strip().splitlines()[-1] == ("loaded: ['prc3cfg.core.policy', "
                                                    "'prc3cfg.plant.policy', "
                                                    "'prc3cfg.shell.emulator.server']")


def test_a_plan_builds_no_checker_of_files_it_does_not_read(tmp_path):
    """pydantic models are built when a file of theirs is first read: a plan on `emulator://` in a fresh
    folder reads no emulator state file (`prc3cfg.shell.emulator.state`) and no snapshot
    (`prc3cfg.shell.records`); the apply after it reads the plan's state file, and still no snapshot."""
    plant = tmp_path / "plant.yaml"
    plant.write_text(DEMO.read_text())
    probe = LOADED_BY.replace(
        'print("loaded:", loaded, file=sys.stderr)',
        """from prc3cfg.shell import records
from prc3cfg.shell.emulator import state
print("built:", state._StateFile.__pydantic_complete__, records._SnapshotDocument.__pydantic_complete__,
      file=sys.stderr)""",
    )
    planned = subprocess.run([sys.executable, "-c", probe, "plan", str(plant)], capture_output=True,
                             text=True, cwd=tmp_path)
    assert planned.stderr.strip().splitlines()[-1] == "built: False False", planned.stderr
    applied = subprocess.run([sys.executable, "-c", probe, "apply", str(plant), "--auto-approve",
                              "--allow-axis-release"],
                             capture_output=True, text=True, cwd=tmp_path)
    assert applied.stderr.strip().splitlines()[-1] == "built: True False", applied.stderr


def _no_terminal() -> dict[str, str]:
    """This environment without what makes rich take a pipe for a terminal."""
    return {name: value for name, value in os.environ.items()
            if name not in ("TTY_COMPATIBLE", "FORCE_COLOR")}


def _command_lines(command=None, words: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every command and sub-command of `prc3cfg`, as the words that name it."""
    import typer

    from prc3cfg.cli import _register_commands, app

    if command is None:
        _register_commands()
        command = typer.main.get_command(app)
    found = [words] if words else []
    for name, sub in sorted(getattr(command, "commands", {}).items()):
        found += _command_lines(sub, (*words, name))
    return found


@pytest.mark.soak
@pytest.mark.parametrize("words", _command_lines(), ids=" ".join)
def test_every_commands_help_loads_nothing_heavy(words):
    """The listing's guarantee (`test_listing_the_commands_loads_nothing_heavy`) for each command's own
    `--help` — but pydantic and what it loads: typer checks a command's options with it."""
    done = subprocess.run([sys.executable, "-c",
                           LISTING.format(args=[*words, "--help"], tops=("serial", "yaml", "rich"))],
                          capture_output=True, text=True)
    assert "Usage" in done.stdout, done.stderr
    assert done.stderr.strip() == "heavy: []"


def test_the_listing_keeps_the_table_s_order_whichever_command_module_was_imported_first():
    """A program that runs several command lines (the tests, an embedding) imports the modules in the order it
    runs them: the listing is still the table's."""
    probe = ("import typer, prc3cfg.cli.plan_commands, prc3cfg.cli.records_commands\n"
             "from prc3cfg.cli import COMMAND_MODULES, _register_commands, app\n"
             "_register_commands()\n"
             "print(typer.main.get_command(app).list_commands(None) == list(COMMAND_MODULES))\n")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=False)
    assert done.stdout.strip() == "True", done.stderr


#: The listing as prc3cfg shows it (no command's options built), then as typer shows it with every command
#: built, then a command run in the same process: prc3cfg's listing leaves the app as it was.
LISTED_AND_BUILT = """
import contextlib, io, sys
import typer
from prc3cfg.cli import _register_commands, app, main
def said(args):
    with contextlib.redirect_stdout(io.StringIO()) as out:
        try:
            main(args)
        except SystemExit as ended:
            return out.getvalue(), ended.code
_register_commands()
built = typer.main.get_command(app)
with built.make_context("prc3cfg", ["--help"], resilient_parsing=True) as context:
    full = built.get_help(context) + chr(10)
print(said(["--help"]) == (full, 0), said([])[0] == full, said(["schema"])[1] == 0)
"""


def test_the_listing_is_typer_s_with_every_command_built_and_leaves_the_commands_as_they_were():
    """`prc3cfg --help` and `prc3cfg` list the commands without building their options
    (bench/startup_bench.py: 8 ms of the listing's 60): the same text as typer's listing of the commands
    built, and a command run after it in the same process runs."""
    done = subprocess.run([sys.executable, "-c", LISTED_AND_BUILT], capture_output=True, text=True,
                          env={**os.environ, "COLUMNS": "100"}, check=False)
    assert done.stdout.split() == ["True", "True", "True"], done.stderr


#: One process runs every command line's `--help` in this seed's order (as a program that embeds the command
#: line would).
HELP_IN_ORDER = """
import contextlib, io, json, random, sys
from prc3cfg.cli import main
lines = json.loads(sys.argv[1])
random.Random(int(sys.argv[2])).shuffle(lines)
said = {}
for words in lines:
    with contextlib.redirect_stdout(io.StringIO()) as out:
        try:
            main([*words, "--help"])
        except SystemExit:
            pass
    said[" ".join(words)] = out.getvalue()
print(json.dumps(said))
"""


@pytest.mark.soak
def test_each_help_is_the_fresh_processs_whatever_ran_before_it():
    """Each command line's `--help` in its own `python -m prc3cfg` process, as a person runs it, is what one
    process that ran other command lines first (their modules imported, their commands built) prints, in every
    seed's order."""
    lines = [list(words) for words in [(), *_command_lines()]]
    fresh = {" ".join(words): subprocess.run([sys.executable, "-m", "prc3cfg", *words, "--help"],
                                             capture_output=True, text=True, check=True).stdout
             for words in lines}
    for seed in range(4):
        done = subprocess.run([sys.executable, "-c", HELP_IN_ORDER, json.dumps(lines), str(seed)],
                              capture_output=True, text=True, check=True)
        assert json.loads(done.stdout) == fresh, f"seed {seed}"
