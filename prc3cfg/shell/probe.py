"""A probe: whether anything answers a 50h at an address, and what — the one reading of a probe's
outcome that a scan, the proof that a line's unlisted addresses are silent (`answering`, for
`prc3cfg.shell.planning`) and the doctor's search all share.

Silence is an empty address (None); something heard that never became a usable reply — garbled,
damaged on every retry — is not (`Heard` with no reply). A failing port, a read a module took for
a write and a module without read messages are raised: none of them says the address is empty.
Does not own the exchange itself (`Link.probe`) nor how long a probe may take on a line's budget
(`prc3cfg.core.plant_planner`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from prc3cfg.core import codec
from prc3cfg.core.plant_planner import PROBE_TIMEOUT, PROOF_PROBES

if TYPE_CHECKING:
    from collections.abc import Sequence

    from prc3cfg.shell.link.client import Link


@dataclass(frozen=True)
class Heard:
    """Something answered a probe: its reply, or None when what came back was never usable."""

    reply: int | codec.SystemReply | codec.ProgramsReply | None


def probe(link: Link, address: int, timeout: float, tries: int = 1) -> Heard | None:
    """A 50h at `address`, waiting `timeout` (`Link.probe`), made up to `tries` times while nothing
    answers: what was heard, or None when nothing was."""
    # a plan made from images probes nothing
    from prc3cfg.shell.link.client import LinkError, NoReadMessages, PortFailed, PossibleWrite

    for _ in range(tries):
        try:
            reply = link.probe(address, codec.ReadSystem(), timeout)
        except (PortFailed, PossibleWrite, NoReadMessages):
            raise  # the port, not an absent module; a read a module executed as a write
        except LinkError:
            return Heard(None)  # something answered, if garbled: not an empty address
        if reply is not None:
            return Heard(reply)
    return None


def probe_timeout(timeout: float) -> float:
    """How long a probe waits at an address of a line whose reply time-out is `timeout`: at most
    `PROBE_TIMEOUT`."""
    return min(timeout, PROBE_TIMEOUT)


def answering(link: Link, addresses: Sequence[int]) -> list[int]:
    """The addresses among those given where something answers a 50h (`PROOF_PROBES` tries each)."""
    return [address for address in addresses
            if probe(link, address, probe_timeout(link.timeout), PROOF_PROBES) is not None]

