"""Bus time: what one exchange costs on a line (link.md "Bus time — the cost a plan is judged by").

    t = (bytes_request + bytes_reply) × bits_per_char / baud + turnaround (+ 2 × ZVZ for open-driver)

Bytes are whole frames (framing overhead and stx stuffing included). A broadcast has no
reply frame. (reading) A broadcast still costs the turnaround (and both ZVZ gaps on an
open-driver line): the master cannot send the next frame sooner.

Owns the cost of exchanges. Does not own which exchanges a plan makes (`prc3cfg.planner`).
Pure.
"""

from __future__ import annotations

from dataclasses import dataclass

from prc3cfg import codec
from prc3cfg.framing import Direction, Framing, get_framing
from prc3cfg.line import LineSettings


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

    def frame_bytes(self, direction: Direction, address: int, message: bytes) -> int:
        return len(self.framing.encode(direction, address, message))

    def exchange_time(self, address: int, request: bytes, reply: bytes | None) -> float:
        """Seconds one exchange holds the line; `reply` None for a broadcast."""
        n = self.frame_bytes(Direction.REQUEST, address, request)
        if reply is not None:
            n += self.frame_bytes(Direction.REPLY, address, reply)
        gaps = 2 * self.zvz if self.framing.name == "open-driver" else 0.0
        return n * self.line.char_time + self.turnaround + gaps

    def message_time(self, address: int, message: codec.Message) -> float:
        """An exchange of `message` answered in full (a read's data block, a write's code word)."""
        reply = bytes(codec.reply_length(message))
        return self.exchange_time(address, message.encode(), reply)
