"""A whole PRC 3 bus in software: modules at addresses, one message at a time.

Owns who receives a message: the module at its address (silence when there is none), or
every module for the broadcast address 0 (processed by all, answered by none). What a
module does with it is `prc3cfg.core.device`. Pure: the server around it owns threads,
sockets, the state file and time.
"""

from __future__ import annotations

from dataclasses import dataclass

from prc3cfg.core import device
from prc3cfg.core.device import ModuleState
from prc3cfg.core.image import MAX_MODULE_ADDRESS

BROADCAST = 0


@dataclass(frozen=True, slots=True)
class Delivery:
    reply: bytes | None  # None: nobody answers
    changed: bool  # some module's state changed


class EmulatedBus:
    """The modules of one line, by address. Not thread-safe: the server serialises access."""

    def __init__(self, modules: dict[int, ModuleState]) -> None:
        for address, state in modules.items():
            if not 1 <= address <= MAX_MODULE_ADDRESS or state.address != address:
                raise ValueError(f"module at address {address} must have S9 = {address} in "
                                 f"1..{MAX_MODULE_ADDRESS}")
        self.modules = dict(sorted(modules.items()))

    def deliver(self, address: int, message: bytes) -> Delivery:
        if address == BROADCAST:
            changed = False
            for addr, each in self.modules.items():
                outcome = device.process(each, message, broadcast=True)
                changed |= outcome.state is not each
                self.modules[addr] = outcome.state
            return Delivery(None, changed)
        state = self.modules.get(address)
        if state is None:
            return Delivery(None, False)
        outcome = device.process(state, message)
        self.modules[address] = outcome.state
        return Delivery(outcome.reply, outcome.state is not state)
