"""Framing `crc16`: start code, length and CRC, after the Parker Compax3 binary record (docs/line.md).

    +------+------+-----+-------------+-------+-------+
    | A5h  | ADDR | N-1 | D0 … D(N-1) | CRC_H | CRC_L |   request
    | 05h  |      |     |             |       |       |   reply
    +------+------+-----+-------------+-------+-------+
    |<----- CRC-16/CCITT-FALSE ------>|
    N = 1..256. CRC: polynomial 1021h, initial FFFFh, no reflection, no final XOR
    ("123456789" → 29B1h), `binascii.crc_hqx(data, 0xFFFF)`.

A receiver hunts for its direction's start code, reads N from the third byte and checks
the CRC. It discards a frame with a bad CRC and, from a UART, a frame with a gap of more
than the inter-character time-out inside it (default 5 character times: 5.7 ms at 9600
8E1). From a TCP stream (`uart=False`, see `base`) a frame ends by its length alone: the
inter-character time-out is infinite, so a frame split and delayed by the network or a
paused process is still taken whole.

Readings (where docs/line.md is silent):
- Bytes before a start code, a start code of the other direction included, are skipped and
  reported as one `Discarded` when a start code, a gap longer than the time-out or
  `line_idle()` ends the run (reading).
- After a bad CRC, hunting resumes after the whole discarded frame, as a receiver that has
  read N bytes would; not at the byte after its start code (reading).
- After a gap, the byte that arrived after it starts the hunt for a new start code (reading).
- `encode` takes addresses 0..30 (docs/line.md); a decoder delivers any address byte and leaves
  it to the receiver to ignore addresses it does not have (reading).
- `zvz` is not used by this framing (reading).
"""

from __future__ import annotations

import binascii

from prc3cfg.core.framing.base import Decoder, Direction, Framing, ms
from prc3cfg.core.line import LineSettings

START_CODES = {Direction.REQUEST: 0xA5, Direction.REPLY: 0x05}
HEADER = 3  # start code, ADDR, N-1
TRAILER = 2  # CRC_H, CRC_L
TIMEOUT_CHARS = 5  # default inter-character time-out, in character times


def crc(data: bytes | bytearray) -> int:
    """CRC-16/CCITT-FALSE."""
    return binascii.crc_hqx(data, 0xFFFF)


class Crc16Framing(Framing):
    name = "crc16"
    checked = True
    addresses = range(0, 31)
    lengths = range(1, 257)
    overhead = HEADER + TRAILER

    def _encode(self, direction: Direction, address: int, message: bytes) -> bytes:
        covered = bytes([START_CODES[direction], address, len(message) - 1]) + message
        return covered + crc(covered).to_bytes(2, "big")

    def decoder(
        self,
        direction: Direction,
        line: LineSettings,
        *,
        zvz: float | None = None,
        inter_char_timeout: float | None = None,
        uart: bool = True,
    ) -> Crc16Decoder:
        if not uart:
            inter_char_timeout = float("inf")
        elif inter_char_timeout is None:
            inter_char_timeout = TIMEOUT_CHARS * line.char_time
        return Crc16Decoder(direction, line, inter_char_timeout)


class Crc16Decoder(Decoder):
    def __init__(self, direction: Direction, line: LineSettings, inter_char_timeout: float) -> None:
        super().__init__(direction, line)
        self.inter_char_timeout = inter_char_timeout
        self._start_code = START_CODES[direction]
        self._frame = bytearray()  # from the start code on; empty while hunting
        self._no_start_code = f"no {self._start_code:02X}h start code"

    def line_idle(self) -> None:
        self._end_burst("then the line went idle")

    def _clock(self, now: float, n_bytes: int) -> None:
        silence = self._silence(now, n_bytes)
        if silence > self.inter_char_timeout:
            self._end_burst(f"then {ms(silence)} of silence (inter-character time-out "
                            f"{ms(self.inter_char_timeout)})")

    def _end_burst(self, why: str) -> None:
        if self._frame:
            self._discard(f"incomplete frame, {why}", self._frame)
            self._frame = bytearray()
        self._flush_skipped(self._no_start_code)

    def _take(self, data: bytes, now: float) -> None:
        """Whole runs at a time: garbage up to the next start code, then as much of the frame as N asks
        for."""
        i, n = 0, len(data)
        while i < n:
            frame = self._frame
            if not frame:
                start = data.find(self._start_code, i)
                if start < 0:
                    self._skip(data[i:], self._no_start_code)
                    return
                self._skip(data[i:start], self._no_start_code)
                self._flush_skipped(self._no_start_code)
                frame.append(self._start_code)
                i = start + 1
                continue
            length = HEADER + frame[2] + 1 + TRAILER if len(frame) >= HEADER else HEADER
            taken = data[i : i + length - len(frame)]
            frame += taken
            i += len(taken)
            if len(frame) == length and length > HEADER:
                self._frame = bytearray()
                received, expected = int.from_bytes(frame[-TRAILER:], "big"), crc(frame[:-TRAILER])
                if received == expected:
                    self._emit(frame[1], frame[HEADER:-TRAILER])
                else:
                    self._discard(f"bad CRC {received:04X}h, expected {expected:04X}h", frame)
