"""Line settings of an RS-422 line and the times that follow from them (link.md "The line").

Owns the character format and the character time, and the URL schemes of ports that are not
UARTs (TCP, the emulator). Does not own framing (see
`prc3cfg.core.framing`) or the cost of a plan (see `prc3cfg.core.bustime`). Pure.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

#: Ports whose bytes come over TCP (pyserial URLs): `HOST:PORT`, no UART between (link.md).
TCP_SCHEMES = ("socket", "rfc2217")
#: The in-process emulator a plant file can name as its port: `emulator://NAME`.
EMULATOR_SCHEME = "emulator://"
Parity = Literal["none", "odd", "even"]
PARITIES: tuple[Parity, ...] = get_args(Parity)
#: What a UART can be set to (the emulator's RFC 2217 gateway receives a client at any of them as a UART would).
DATA_BITS = (5, 6, 7, 8)
#: What a PRC 3 line takes: its frames are binary, and fewer bits lose the top of each byte.
FRAME_DATA_BITS = 8
STOP_BITS = (1, 1.5, 2)


@dataclass(frozen=True, slots=True)
class LineSettings:
    """Baud rate and character format. The default is the PRC 3 line: 9600 baud, 8E1."""

    baud: int = 9600
    data_bits: int = 8
    parity: str = "even"
    stop_bits: float = 1

    def __post_init__(self) -> None:
        if self.baud <= 0:
            raise ValueError(f"baud must be positive, not {self.baud}")
        if self.data_bits not in DATA_BITS:
            raise ValueError(f"data bits must be one of {DATA_BITS}, not {self.data_bits}")
        if self.parity not in PARITIES:
            raise ValueError(f"parity must be one of {', '.join(PARITIES)}, not {self.parity!r}")
        if self.stop_bits not in STOP_BITS:
            raise ValueError(f"stop bits must be one of 1, 1.5, 2, not {self.stop_bits}")

    @property
    def bits_per_char(self) -> float:
        """Start bit + data bits + parity bit + stop bits: 11 for 8E1."""
        return 1 + self.data_bits + (0 if self.parity == "none" else 1) + self.stop_bits

    @property
    def char_time(self) -> float:
        """Seconds one character takes on the line (8E1 at 9600 baud: 1.146 ms)."""
        return self.bits_per_char / self.baud

    def transmission_time(self, n_bytes: int) -> float:
        return n_bytes * self.char_time
