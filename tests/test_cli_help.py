"""`prc3cfg --help` is quick because the commands import what they use only when they run: listing
them loads typer and prc3cfg's command modules, never the plant loader, the planner or the link."""

from __future__ import annotations

import subprocess
import sys

from prc3cfg.cli.common import ADDRESSES, DATA_BITS, FRAMING_NAMES, PARITY_NAMES, STOP_BITS, VerifyChoice
from prc3cfg.core import line
from prc3cfg.core.framing import FRAMINGS
from prc3cfg.core.image import MAX_MODULE_ADDRESS
from prc3cfg.shell.apply import Verify as ApplyVerify

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
