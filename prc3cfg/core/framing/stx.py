"""Framing `stx`: start byte, stuffing and a sum, after the Parker SPD converter protocol (docs/line.md).

    +-----+----------+---+-------------+-----+
    | 7Eh | CMD|ADDR | N | D0 … D(N-1) | CHK |
    +-----+----------+---+-------------+-----+
          |<--- CHK = sum mod 256 ---->|
    CMD|ADDR: bits 7-5 type (001 request, 010 reply), bits 4-0 address 0..31 (0 = broadcast).
    N = 1..255. Every byte after the leading 7Eh that equals 7Eh (CMD|ADDR, N, data or
    CHK) is sent as 7Eh 00h; the receiver drops the 00h. A 7Eh followed by anything else
    starts a new frame. CHK is the sum of the unstuffed bytes.

From a UART the whole frame must arrive within the SPD message time-out for the baud,
counted from its 7Eh, plus the frame's own transmission time (docs/line.md). From a TCP stream
(`uart=False`, see `base`) there is no message time-out: a frame ends by its N alone, so a
frame split and delayed by the network or a paused process is still taken whole.

Readings (where docs/line.md is silent):
- SPD time-out for a baud not in the table: the entry of the next lower listed baud; below
  600 baud 512 ms × 600 / baud; above 57600 baud 8 ms (reading).
- The frame's transmission time counts its bytes on the line, stuffing included, as far as
  they are known: before N has arrived, N = 1 is assumed; the stuffed 00h bytes not yet
  received are not counted (reading). A frame is in time if its last byte arrives at most
  that long after its 7Eh, byte times as `base` reads them.
- A partial frame is dropped as soon as a `now` (of `receive_data` or `next_event`) is past
  its deadline even if every byte of the arriving chunk belonged to it; the chunk's bytes then
  hunt for a new 7Eh (reading).
- A 7Eh followed by something other than 00h inside a frame discards the partial frame
  (without that 7Eh) and starts a new one at that 7Eh (reading).
- N = 0 discards the frame at once as a bad length; hunting resumes at the next byte (reading).
- A frame of the wrong type (another direction, or a type that is neither) is read to its
  end, as N says, and discarded as a whole; a bad checksum is reported before a wrong type
  (reading).
- Bytes outside a frame are reported as one `Discarded` when a 7Eh or `line_idle()` ends the
  run (reading). While hunting, 7Eh 00h is taken as a frame start (type 000, discarded).
- `line_idle()` discards a partial frame; `zvz` and `inter_char_timeout` are not used (reading).
"""

from __future__ import annotations

from prc3cfg.core.framing.base import Decoder, Direction, Framing, ms
from prc3cfg.core.line import LineSettings

START = 0x7E
NO_START = "no 7Eh start code"  # why bytes outside a frame are discarded
STUFFED = bytes([START, 0x00])
TYPES = {Direction.REQUEST: 0b001, Direction.REPLY: 0b010}  # bits 7-5 of CMD|ADDR
ADDRESS_MASK = 0x1F
SPD_TIMEOUTS = {  # baud → message time-out, s
    600: 0.512, 1200: 0.256, 2400: 0.128, 4800: 0.064, 9600: 0.032, 19200: 0.016, 38400: 0.012, 57600: 0.008,
}


def message_timeout(baud: int) -> float:
    """The SPD message time-out in seconds for `baud`, before the frame's transmission time."""
    lowest = min(SPD_TIMEOUTS)
    if baud < lowest:
        return SPD_TIMEOUTS[lowest] * lowest / baud
    return SPD_TIMEOUTS[max(b for b in SPD_TIMEOUTS if b <= baud)]


def checksum(data: bytes | bytearray) -> int:
    return sum(data) & 0xFF


class StxFraming(Framing):
    name = "stx"
    checked = True
    addresses = range(0, 32)
    lengths = range(1, 256)
    overhead = 4  # 7Eh, CMD|ADDR, N, CHK
    stuffs = True

    def _encode(self, direction: Direction, address: int, message: bytes) -> bytes:
        body = bytes([TYPES[direction] << 5 | address, len(message)]) + message
        return bytes([START]) + (body + bytes([checksum(body)])).replace(bytes([START]), STUFFED)

    def stuffing(self, direction: Direction, address: int, message: bytes) -> int:
        """A 00h after every 7Eh of CMD|ADDR, N, the data and CHK."""
        header = (TYPES[direction] << 5 | address, len(message))
        return message.count(START) + header.count(START) + ((sum(header) + sum(message)) & 0xFF == START)

    def decoder(
        self,
        direction: Direction,
        line: LineSettings,
        *,
        zvz: float | None = None,
        inter_char_timeout: float | None = None,
        uart: bool = True,
    ) -> StxDecoder:
        return StxDecoder(direction, line, message_timeout(line.baud) if uart else float("inf"))


class StxDecoder(Decoder):
    def __init__(self, direction: Direction, line: LineSettings, message_timeout: float) -> None:
        super().__init__(direction, line)
        self.message_timeout = message_timeout
        self._type = TYPES[direction]
        self._raw = bytearray()  # the frame as received, from its 7Eh; empty while hunting
        self._body = bytearray()  # unstuffed: CMD|ADDR, N, D0 … D(N-1), CHK
        self._start = 0.0  # arrival of the frame's 7Eh
        self._escape_at: float | None = None  # arrival of a 7Eh inside the frame that awaits its 00h

    def line_idle(self) -> None:
        self._abandon("incomplete frame, then the line went idle")
        self._flush_skipped(NO_START)

    def _clock(self, now: float, n_bytes: int) -> None:
        # the coming bytes may complete the frame, so allow for all of them
        if self._raw and now > (deadline := self._deadline(len(self._raw) + n_bytes)):
            self._abandon(self._late(now, deadline))

    def _deadline(self, at_least: int = 0) -> float:
        """When the frame must be complete: its length as known so far, or `at_least` bytes."""
        expected_body = self._body[1] + 3 if len(self._body) >= 2 else 4
        length = max(len(self._raw) + expected_body - len(self._body), at_least)
        return self._start + self.message_timeout + length * self.line.char_time

    def _late(self, at: float, deadline: float) -> str:
        return f"message time-out: {ms(at - self._start)} after its 7Eh, limit {ms(deadline - self._start)}"

    def _take(self, data: bytes, now: float) -> None:
        """A run at a time: garbage up to the next 7Eh, and the bytes of a frame up to the next 7Eh
        or the end of the frame's header or body; a 7Eh, and the byte after it, one by one."""
        i, n = 0, len(data)
        while i < n:
            if not self._raw:
                start = data.find(START, i)
                if start < 0:
                    self._skip(data[i:], NO_START)
                    return
                self._skip(data[i:start], NO_START)
                i = start
            elif self._escape_at is None and data[i] != START:
                body = self._body
                end = min(n, i + (body[1] + 3 if len(body) >= 2 else 2) - len(body))
                if (stop := data.find(START, i, end)) >= 0:
                    end = stop
                run = data[i:end]
                self._raw += run
                body += run
                i = end
                self._grown(now - (n - end) * self.line.char_time)
                continue
            self._byte(data[i], now - (n - 1 - i) * self.line.char_time)
            i += 1

    def _byte(self, byte: int, at: float) -> None:
        """A 7Eh, or the byte after a 7Eh inside a frame; arrived at `at`."""
        if self._escape_at is not None:
            escape_at, self._escape_at = self._escape_at, None
            if byte == 0x00:
                self._raw.append(byte)
                self._body.append(START)
                self._grown(at)
                return
            self._abandon("cut short by a 7Eh start code", self._raw[:-1])
            self._begin(escape_at)
        if byte != START:
            self._raw.append(byte)
            self._body.append(byte)
            self._grown(at)
        elif self._raw:
            self._raw.append(byte)
            self._escape_at = at
        else:
            self._begin(at)

    def _begin(self, at: float) -> None:
        self._flush_skipped(NO_START)
        self._raw, self._body, self._start = bytearray([START]), bytearray(), at

    def _abandon(self, reason: str, data: bytearray | None = None) -> None:
        if self._raw:
            self._discard(reason, self._raw if data is None else data)
        self._raw, self._body, self._escape_at = bytearray(), bytearray(), None

    def _grown(self, at: float) -> None:
        """The body has grown, its last byte arrived at `at`: a bad length, or a complete frame?"""
        body = self._body
        if len(body) == 2 and body[1] == 0:
            self._abandon("bad length N = 0")
        elif len(body) >= 2 and len(body) == body[1] + 3:
            self._complete(at)

    def _complete(self, at: float) -> None:
        body, frame, deadline = self._body, self._raw, self._deadline()
        self._raw, self._body = bytearray(), bytearray()
        kind, expected = body[0] >> 5, checksum(body[:-1])
        if at > deadline:
            self._discard(self._late(at, deadline), frame)
        elif body[-1] != expected:
            self._discard(f"bad checksum {body[-1]:02X}h, expected {expected:02X}h", frame)
        elif kind != self._type:
            self._discard(f"type {kind:03b}, expected {self._type:03b} ({self.direction.value})", frame)
        else:
            self._emit(body[0] & ADDRESS_MASK, body[2:-1])
