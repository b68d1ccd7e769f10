"""The PRC 3 bus emulator: the device model served behind a real framing on a real stream.

`bus` is pure (who gets a message); `state` is the state file and, while an emulator
runs, the journal beside it; `server` is the running emulator over TCP and
pseudo-terminals, with the Python API tests use while it runs.
"""

from prc3cfg.shell.emulator.bus import BROADCAST, EmulatedBus
from prc3cfg.shell.emulator.server import Emulator, FaultInjection
from prc3cfg.shell.emulator.state import load_state, modules_to_serve, save_state

__all__ = ["BROADCAST", "EmulatedBus", "Emulator", "FaultInjection", "load_state", "modules_to_serve", "save_state"]
