"""Framings: how a PRC 3 message and its module address become the bytes of one frame, and back.

Three framings (docs/line.md), one module each, with the frame layout drawn in its docstring:
`crc16` (start code, length, CRC), `open-driver` (raw bytes ended by silence) and `stx`
(7Eh, stuffing, sum). Sans-IO like h11: no port, no socket, no sleeping, no clock; a
decoder is fed bytes with their arrival times and hands back `Frame`, `Discarded` or
`NEED_DATA` (see `base`). Does not own the messages (`prc3cfg.core.codec`), the line settings
(`prc3cfg.core.line`) nor the port (`prc3cfg.shell.link`).
"""

from __future__ import annotations

from prc3cfg.core.framing.base import (
    NEED_DATA,
    Decoder,
    Direction,
    Discarded,
    Frame,
    Framing,
    FramingError,
    FramingName,
)
from prc3cfg.core.framing.crc16 import Crc16Framing
from prc3cfg.core.framing.open_driver import OpenDriverFraming
from prc3cfg.core.framing.stx import StxFraming

FRAMINGS: dict[str, Framing] = {f.name: f for f in (Crc16Framing(), OpenDriverFraming(), StxFraming())}


def get_framing(name: str) -> Framing:
    """The framing called `name`; ValueError naming the valid ones otherwise."""
    try:
        return FRAMINGS[name]
    except KeyError:
        raise ValueError(f"unknown framing {name!r}: use one of {', '.join(FRAMINGS)}") from None


def detects_damage(framing: str, parity: str) -> bool:
    """Whether a damaged frame can be told from a good one on a line: by a checksum (crc16, stx) or
    by parity on each character. Without either (open-driver, no parity) any damage passes — a
    write can become another write, a read a write, an address the broadcast 0."""
    return get_framing(framing).checked or parity != "none"


__all__ = [
    "FRAMINGS",
    "NEED_DATA",
    "Decoder",
    "Direction",
    "Discarded",
    "Frame",
    "Framing",
    "FramingError",
    "FramingName",
    "detects_damage",
    "get_framing",
]
