"""Framing `open-driver`: raw bytes ended by a character delay, for a CP 524/525 running S5D004.

    +------+-------------+
    | ADDR | D0 … D(N-1) |  then silence ≥ ZVZ        request and reply alike
    +------+-------------+

No start code, no length, no checksum: the only end criterion is "character delay time
elapsed" (PROPAR bits 11,10 = 00), so a frame ends when the line has been idle for ZVZ
(4..65535 ms; 5..100 ms at 9600 baud). Parity is the only protection: every write must be
verified by reading back (not this module's job).

A frame ends on `line_idle()`, or on a `now` (of `receive_data` or `next_event`) that
finds the line silent for at least `zvz` since the last byte (see `base` for how the
silence before a chunk is measured). A `zvz` not longer than one character time ends a frame
after every byte, as the driver does: its time runs out before the next byte is in (seed 004
§5.2.8; plant files refuse such a ZVZ, `prc3cfg.core.gateway.zvz_too_short`).

Readings (where docs/line.md is silent):
- A frame of only the address byte is a `Frame` with message b"": the module answers it
  with error 11 (reading).
- The decoder delivers any address byte 0..255 and frames of any length; `encode` takes
  addresses 0..31 and messages of 0..1024 bytes (TELLEN's range) (reading).
- The direction cannot be told from the bytes: a decoder stamps its own (reading).
- `decoder()` needs `zvz` in seconds, > 0 (ValueError otherwise); the driver's 4 ms minimum
  is checked with the INIT data block, not here (reading).
- `inter_char_timeout` and `uart` are not used by this framing: ZVZ is its only gap, from a
  UART and from a TCP stream alike — a frame without a length has no other end (reading).
- A frame longer than the driver's longest (address and 1024 bytes, TELLEN's range) is
  discarded, in pieces of that length as it arrives, so a line that never goes quiet
  cannot grow the decoder without bound (reading).
"""

from __future__ import annotations

from prc3cfg.core.framing.base import Decoder, Direction, Framing
from prc3cfg.core.line import LineSettings

MAX_FRAME = 1 + 1024  # the address byte and TELLEN's longest message


class OpenDriverFraming(Framing):
    name = "open-driver"
    checked = False
    addresses = range(0, 32)
    lengths = range(0, 1025)
    overhead = 1  # the address byte

    def _encode(self, direction: Direction, address: int, message: bytes) -> bytes:
        return bytes([address]) + message

    def decoder(
        self,
        direction: Direction,
        line: LineSettings,
        *,
        zvz: float | None = None,
        inter_char_timeout: float | None = None,
        uart: bool = True,
    ) -> OpenDriverDecoder:
        if zvz is None or not zvz > 0:
            raise ValueError(f"the open-driver framing needs the character delay time zvz (s > 0), not {zvz}")
        return OpenDriverDecoder(direction, line, zvz)


class OpenDriverDecoder(Decoder):
    def __init__(self, direction: Direction, line: LineSettings, zvz: float) -> None:
        super().__init__(direction, line)
        self.zvz = zvz
        self._every_byte = zvz <= line.char_time  # a frame of each byte, as the driver makes
        self._frame = bytearray()
        self._too_long = False  # the frame being received has passed MAX_FRAME bytes

    def line_idle(self) -> None:
        if self._too_long:
            self._discard(f"a frame longer than {MAX_FRAME} bytes", self._frame)
        elif self._frame:
            self._emit(self._frame[0], self._frame[1:])
        self._frame, self._too_long = bytearray(), False

    def _clock(self, now: float, n_bytes: int) -> None:
        if self._silence(now, n_bytes) >= self.zvz:
            self.line_idle()

    def _take(self, data: bytes, now: float) -> None:
        if self._every_byte:
            for byte in data:
                self._frame.append(byte)
                self.line_idle()
            return
        i, n = 0, len(data)
        while i < n:
            if len(self._frame) == MAX_FRAME:
                self._discard(f"a frame longer than {MAX_FRAME} bytes", self._frame)
                self._frame, self._too_long = bytearray(), True
            taken = data[i : i + MAX_FRAME - len(self._frame)]
            self._frame += taken
            i += len(taken)
