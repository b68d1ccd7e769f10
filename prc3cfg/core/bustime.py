"""Bus time: what one exchange costs on a line (docs/line.md "Bus time — the cost a plan is judged by").

    t = (bytes_request + bytes_reply) × bits_per_char / baud + turnaround (+ 2 × ZVZ for open-driver)

Bytes are whole frames (framing overhead and stx stuffing included), counted from the
message's length (`Framing.frame_length`), never by encoding the frame: only the stuffing of
a framing that stuffs looks at the bytes. A broadcast (address 0, the manual's ring call) has
no reply frame. (reading) It still costs the turnaround (and an open-driver line's gap after
the request): the master cannot send the next frame sooner, and gets no reply that would say
the modules are ready.

How long the master waits for a reply follows from the same figures (`LineCost.reply_deadline`):

    deadline = (request frame bytes + longest reply frame bytes) × bits_per_char / baud × (1 +
    DEADLINE_MARGIN)
               + turnaround  (+ 2 × ZVZ for open-driver)

with the longest reply the message can have — a read's data block, a write's code word — and on a
framing that stuffs, every byte after its start code stuffed. The plant file's `timeout` is waited
on top of it: a reply is never given up on while the line can still be carrying it, at any baud.

Owns the cost of exchanges, the deadline of their replies, and when exchanges that took longer than
priced say the line is slower than its settings (`slower_than_priced`). Does not own which exchanges
a plan makes (`prc3cfg.core.planner`). Pure.
"""

from __future__ import annotations

from dataclasses import dataclass

from prc3cfg.core import codec
from prc3cfg.core.framing import Direction, Framing, get_framing
from prc3cfg.core.line import LineSettings

#: A reply is waited for this fraction of its frames' time more than they take at the line's settings:
#: a UART's clock may run a few per cent slow, and a sender may leave a little idle time between characters.
DEADLINE_MARGIN = 0.10


@dataclass(frozen=True, slots=True)
class LineCost:
    """The settings of one line that price its exchanges."""

    framing: Framing
    line: LineSettings = LineSettings()
    turnaround: float = 0.010
    zvz: float = 0.020

    @classmethod
    def of(cls, framing: str, line: LineSettings, turnaround: float, zvz: float) -> LineCost:
        return cls(get_framing(framing), line, turnaround, zvz)

    def message_time(self, address: int, message: codec.Message) -> float:
        """Seconds an exchange of `message` holds the line: request frame, turnaround, reply frame
        (a read's data block, a write's code word)."""
        framing, reply = self.framing, codec.reply_length(message)
        chars = self._request(address, message) + framing.frame_length(reply)
        if framing.stuffs:
            chars += framing.stuffing(Direction.REPLY, address, bytes(reply))
        gaps = 2 * self.zvz if framing.name == "open-driver" else 0.0
        return chars * self.line.char_time + self.turnaround + gaps

    def reply_deadline(self, address: int, message: codec.Message) -> float:
        """Seconds from the frame of `message` to `address` leaving until the longest reply it can have
        has come: both frames at the character time with `DEADLINE_MARGIN` more, the turnaround, and on
        open-driver the ZVZ that ends each frame. What a plant file's `timeout` adds is the link's."""
        framing = self.framing
        reply = framing.frame_length(codec.reply_length(message))
        if framing.stuffs:
            # at worst every byte after the start code is stuffed: the reply's bytes are not known yet
            reply += reply - 1
        chars = self._request(address, message) + reply
        return chars * self.line.char_time * (1 + DEADLINE_MARGIN) + self.turnaround + self._gaps(2)

    def _gaps(self, frames: int) -> float:
        """The silence that ends `frames` frames on open-driver (none on a framing with a length)."""
        return frames * self.zvz if self.framing.name == "open-driver" else 0.0

    def _request(self, address: int, message: codec.Message) -> int:
        """Bytes of the request frame of `message` to `address`."""
        framing = self.framing
        chars = framing.frame_length(message.size())
        if not framing.stuffs:
            return chars
        return chars + framing.stuffing(Direction.REQUEST, address, message.encode())

    def silence_time(self, message: codec.Message, timeout: float) -> float:
        """Seconds an exchange with an address where nobody answers holds the line: the whole wait
        for a reply that never comes — its deadline, then `timeout` more (the plant file's, on top)."""
        return self.reply_deadline(1, message) + timeout

    def broadcast_time(self, message: codec.Message) -> float:
        """Seconds a broadcast of `message` holds the line: request frame and turnaround."""
        return self._request(0, message) * self.line.char_time + self.turnaround + self._gaps(1)


#: A line is slower than its settings when its exchanges took more than this many times their price …
SLOW_FACTOR = 1.25
#: … and more than this many seconds over it: a short command's few exchanges say nothing of the line.
SLOW_MARGIN = 0.5


def slower_than_priced(measured: float, priced: float) -> bool:
    """Whether exchanges that took `measured` seconds, priced at `priced` by the line's settings,
    show a line clearly slower than those settings (a longer turnaround, a lower baud, a gateway's
    delay): both more than `SLOW_FACTOR` times and more than `SLOW_MARGIN` over the price."""
    return measured > SLOW_FACTOR * priced and measured - priced > SLOW_MARGIN
