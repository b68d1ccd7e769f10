"""What every framing shares: directions, the events a decoder hands back, and the decoder model.

A `Framing` turns (direction, module address, PRC 3 message) into the bytes of one frame
(`encode`), says how long that frame is without building it (`frame_length`, and `stuffing`
where its bytes count: what the bus time of a plan is priced by, `prc3cfg.core.bustime`), and
makes `Decoder`s, which work like h11's connection: `receive_data(bytes, now)`
only stores and parses, `next_event(now)` hands back a `Frame`, a `Discarded` or `NEED_DATA`.
Nothing here reads a port, sleeps or reads a clock: every time is given by the caller,
in seconds on a monotonic clock.

Time, for every decoder (reading):
- the bytes of one `receive_data` chunk count as having arrived back to back, the last at
  `now`: byte i of n at `now - (n - 1 - i) × char time`. The silence before a chunk of n bytes
  is therefore `now - previous now - n × char time`, not the plain difference of the two
  `now`s, so a UART FIFO or a USB adapter that hands over a steady stream in bursts does not
  look like a gap, and a frame that ends early in a long chunk ends early;
- `next_event(now)` with a `now` says "the line has been silent up to `now`": it applies the
  framing's gap or time-out just as a later chunk would;
- `line_idle()` says the caller saw the line idle for the framing's gap, whatever the times.

Where the bytes come from (`uart`, a choice of the caller, who knows its port):
- `uart=True` (the default): from a UART — a serial port, a pseudo-terminal. Arrival times
  are the line's, and a gap inside a frame or a late frame means the frame is broken;
- `uart=False`: from a network byte stream — TCP (`socket://`, `rfc2217://`, the emulator's
  TCP side). TCP delivers every byte in order but not on time: a frame can be split into
  pieces and held back by the network, a paused process or a busy machine, so arrival
  times say nothing about the line. A framing whose frames carry their length (crc16,
  stx) then ends a frame by its length alone: no inter-character time-out (crc16) and no
  message time-out (stx) discards it. open-driver frames carry no length: its ZVZ gap
  stays the delimiter everywhere, and it ignores `uart`.

Speed: bytes outside any frame are skipped a run at a time (`bytes.find` of the start
code), not byte by byte, and still reported as `Discarded` pieces of at most `MAX_SKIPPED`
bytes, so a line of endless garbage costs little and never grows a decoder.

Errors are split like h11's: `FramingError` is *our* misuse when encoding (address or length
out of range). What the *peer* sends is never an exception: a receiver throws bad bytes away,
and the decoder reports them as `Discarded` for traces.

Owns: the shared types and the event queue. Does not own any frame layout (one module per
framing: `crc16`, `open_driver`, `stx`) nor the line's character format (`prc3cfg.core.line`).
"""

from __future__ import annotations

import abc
import enum
from collections import deque
from dataclasses import dataclass
from typing import ClassVar, Final, Literal

from prc3cfg.core.line import LineSettings


class Direction(enum.Enum):
    REQUEST = "request"  # master → module
    REPLY = "reply"  # module → master


@dataclass(frozen=True, slots=True)
class Frame:
    """A complete, valid frame: who it is for (0 = broadcast) and the PRC 3 message inside."""

    direction: Direction
    address: int
    message: bytes


@dataclass(frozen=True, slots=True)
class Discarded:
    """Bytes a receiver threw away, and why in a few words (for traces, never for control)."""

    reason: str
    data: bytes


class _NeedData(enum.Enum):
    """An enum of one member, so that `event is not NEED_DATA` narrows (the pattern of h11's sentinels)."""

    NEED_DATA = enum.auto()

    def __repr__(self) -> str:
        return "NEED_DATA"


NEED_DATA: Final = _NeedData.NEED_DATA
"""`next_event` returns this when no complete frame or discard is ready yet."""


#: The longest run of bytes outside any frame that a decoder holds: a longer run is reported
#: in pieces, so a line of endless garbage cannot grow a decoder without bound.
MAX_SKIPPED = 256


class FramingError(Exception):
    """Our own misuse: a frame cannot carry this address or message length."""


def ms(seconds: float) -> str:
    return f"{seconds * 1000:.1f} ms"


class Decoder(abc.ABC):
    """Bytes in, events out, for one direction on one line. Never raises on what it is fed."""

    def __init__(self, direction: Direction, line: LineSettings) -> None:
        self.direction = direction
        self.line = line
        self._events: deque[Frame | Discarded] = deque()
        self._last: float | None = None  # `now` of the latest chunk that carried bytes
        self._skipped = bytearray()  # bytes seen while hunting for a start code

    def receive_data(self, data: bytes, now: float) -> None:
        """Take a chunk of bytes whose last byte arrived at `now`."""
        self._clock(now, len(data))
        self._take(bytes(data), now)
        if data:
            self._last = now

    def next_event(self, now: float | None = None) -> Frame | Discarded | Literal[_NeedData.NEED_DATA]:
        """The next event in arrival order, or NEED_DATA; `now` first lets time-outs expire."""
        if now is not None:
            self._clock(now, 0)
        return self._events.popleft() if self._events else NEED_DATA

    @abc.abstractmethod
    def line_idle(self) -> None:
        """The caller saw the line idle for the framing's gap: end or drop what is pending."""

    @abc.abstractmethod
    def _clock(self, now: float, n_bytes: int) -> None:
        """Time has reached `now`; `n_bytes` bytes are about to arrive (0: none)."""

    @abc.abstractmethod
    def _take(self, data: bytes, now: float) -> None:
        """Take a chunk of bytes whose last byte arrived at `now` (byte i of n at `now - (n - 1 - i) × char
        time`)."""

    def _silence(self, now: float, n_bytes: int) -> float:
        """How long the line was idle before `n_bytes` bytes arriving back to back up to `now`."""
        if self._last is None:
            return float("inf")
        return now - self._last - n_bytes * self.line.char_time

    def _emit(self, address: int, message: bytes | bytearray) -> None:
        self._events.append(Frame(self.direction, address, bytes(message)))

    def _discard(self, reason: str, data: bytes | bytearray) -> None:
        self._events.append(Discarded(reason, bytes(data)))

    def _skip(self, run: bytes, reason: str) -> None:
        """Bytes outside any frame; a long run is reported in pieces of MAX_SKIPPED bytes."""
        skipped = self._skipped
        skipped += run
        if len(skipped) >= MAX_SKIPPED:
            whole = len(skipped) - len(skipped) % MAX_SKIPPED
            for start in range(0, whole, MAX_SKIPPED):
                self._discard(reason, skipped[start : start + MAX_SKIPPED])
            del skipped[:whole]

    def _flush_skipped(self, reason: str) -> None:
        if self._skipped:
            self._discard(reason, self._skipped)
            self._skipped = bytearray()


#: The framings' names, as a plant file's `framing` takes them (`FRAMINGS` holds one of each).
FramingName = Literal["crc16", "open-driver", "stx"]


class Framing(abc.ABC):
    """One way to put a message and its module address on the line (docs/line.md "Framing …")."""

    name: ClassVar[FramingName]
    checked: ClassVar[bool]  # a checksum protects the frame: a damaged one is discarded, never delivered
    addresses: ClassVar[range]  # addresses `encode` accepts
    lengths: ClassVar[range]  # message lengths `encode` accepts
    overhead: ClassVar[int]  # bytes a frame adds to its message, stuffing aside
    stuffs: ClassVar[bool] = False  # a frame's length depends on its bytes (`stuffing`)

    def frame_length(self, size: int) -> int:
        """Bytes of a frame that carries a message of `size` bytes, stuffing aside."""
        return size + self.overhead

    def stuffing(self, direction: Direction, address: int, message: bytes) -> int:
        """Bytes the stuffing adds to the frame of `message` (none where the framing does not stuff)."""
        return 0

    def encode(self, direction: Direction, address: int, message: bytes) -> bytes:
        """The bytes of one frame; `FramingError` if the framing cannot carry it."""
        if address not in self.addresses:
            raise FramingError(f"{self.name}: address {address} is outside {_span(self.addresses)}")
        if len(message) not in self.lengths:
            raise FramingError(f"{self.name}: a message of {len(message)} bytes is outside "
                               f"{_span(self.lengths)} bytes")
        return self._encode(direction, address, bytes(message))

    @abc.abstractmethod
    def _encode(self, direction: Direction, address: int, message: bytes) -> bytes: ...

    @abc.abstractmethod
    def decoder(
        self,
        direction: Direction,
        line: LineSettings,
        *,
        zvz: float | None = None,
        inter_char_timeout: float | None = None,
        uart: bool = True,
    ) -> Decoder:
        """A decoder for frames travelling in `direction`; times in seconds; `uart=False` for
        bytes from a TCP stream, where arrival times say nothing about the line."""


def _span(values: range) -> str:
    return f"{values.start}..{values.stop - 1}"
