"""`prc3cfg --help` is quick because the commands import what they use only when they run: listing
them loads typer and prc3cfg's command modules, never the plant loader, the planner or the link;
and a command that talks on no line (`plan --actual`, `validate`) loads no link."""

from __future__ import annotations

import json
import subprocess
import sys

from emulated import DEMO

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
    main(["--help"])
except SystemExit:
    pass
heavy = sorted(m for m in sys.modules if m.split(".")[0] in ("pydantic", "serial", "yaml")
               or m in ("prc3cfg.api", "prc3cfg.core.planner", "prc3cfg.shell.link", "prc3cfg.plant", "prc3cfg.shell.emulator"))
print("heavy:", heavy, file=sys.stderr)
"""


def test_listing_the_commands_loads_nothing_heavy():
    done = subprocess.run([sys.executable, "-c", LISTING], capture_output=True, text=True)
    assert "Commands" in done.stdout and "apply" in done.stdout
    assert done.stderr.strip() == "heavy: []"


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
loaded = sorted(m for m in sys.modules if m.split(".")[0] == "serial" or m.startswith(("prc3cfg.shell.link.", "prc3cfg.shell.emulator.")))
print("loaded:", loaded, file=sys.stderr)
"""


def test_a_plan_against_saved_images_loads_no_link(tmp_path):
    """`plan --actual` talks on no line: neither pyserial nor the link nor the emulator is loaded for it."""
    plant = tmp_path / "plant.yaml"
    plant.write_text(DEMO.read_text())
    images = tmp_path / "images.json"
    images.write_text(json.dumps([{"bus": bus.name, **ModuleState.factory(m.address).image.to_json()}
                                  for bus in load_plant(plant).buses for m in bus.modules]))  # fmt: skip
    done = subprocess.run([sys.executable, "-c", LOADED_BY, "plan", str(plant), "--actual", str(images)], capture_output=True, text=True)
    assert "booth-a-left" in done.stdout, done.stderr  # the plan was made and shown
    assert done.stderr.strip().splitlines()[-1] == "loaded: []"
    validated = subprocess.run([sys.executable, "-c", LOADED_BY, "validate", str(plant)], capture_output=True, text=True)
    assert validated.stderr.strip().splitlines()[-1] == "loaded: []"
