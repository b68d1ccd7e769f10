"""The link client: PRC 3 messages to modules over a real line, with retries.

A `Link` *holds* a pyserial port, a framing and a retry policy (composition, not
inheritance). `request()` sends one message to one module and returns its decoded reply;
what came back to each attempt is judged by `prc3cfg.core.exchange` (an answer, a lost or
damaged reply to ask for again, a code to confirm, a line to stop) and the link does what
the verdict says; every retry is logged and traced. The reply's address is checked here, its
length by the codec. Time-outs are detected here, with the port's timeout fixed at the framing's gap
(docs/line.md: `inter_byte_timeout` does nothing on Linux). How long a reply is waited for comes from the
line (`LineCost.reply_deadline`: the frames at its baud and character format, the turnaround, a
margin), with the link's `timeout` — a plant file's — on top: a reply is never given up on while the
line can still be carrying it, at any baud.

The link decodes replies as the port delivers them: from a UART (a device path, a pty)
with the framing's inter-character or message time-out; over TCP (a `socket://` or
`rfc2217://` URL, and so `emulator://`) with `uart=False` (`prc3cfg.core.framing.base`): a
reply split and delayed by the network or a paused process is taken whole by its length,
never discarded and asked for again.

Every attempt has an overall
deadline, so a line that never goes quiet ends in a time-out, not a hang. Before each
attempt the link looks at its `cancel` event (Ctrl-C, SIGTERM: `prc3cfg.shell.cancel`) and
stops with `Interrupted` — so work stops after the exchange in flight, never inside one.

A TCP gateway that ends the connection before a byte came back has refused this client —
a gateway serves one client per serial line (ser2net's default, and `prc3cfg emulator
serve`'s): the link says "the gateway is busy: another client holds the line".

Does not own what the messages mean (`prc3cfg.core.codec`), what a reply means and whether
to ask again (`prc3cfg.core.exchange`), how frames look (`prc3cfg.core.framing`) or which port
to open (`prc3cfg.shell.link.ports`).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol
from urllib.parse import urlsplit

import serial
from serial import rfc2217

from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.exchange import ACK_TO_READ, FIRMWARE_ADDED, LinkStep, Protection, Reply, judge, protection
from prc3cfg.core.framing import NEED_DATA, Direction, Discarded, Framing
from prc3cfg.core.line import TCP_SCHEMES, LineSettings
from prc3cfg.errors import Interrupted, NotSent, UserError
from prc3cfg.shell import platform
from prc3cfg.shell.link.trace import Trace

log = logging.getLogger(__name__)

READ_SLICE = 0.05  # s: longest single read on framings that do not end frames by a gap
#: The longest reply frame any framing makes of a PRC 3 reply (64 bytes, stx stuffing doubled).
LONGEST_REPLY_FRAME = 2 * (codec.MAX_MESSAGE_BYTES + 8)


class Port(Protocol):
    """A port as a link uses it: what every port pyserial opens has (its `SerialBase` alone has
    no `in_waiting` or `reset_input_buffer`: each platform's class and URL handler gives them)."""

    @property
    def port(self) -> str | None: ...
    @property
    def timeout(self) -> float | None: ...
    @timeout.setter
    def timeout(self, timeout: float | None) -> None: ...
    @property
    def in_waiting(self) -> int: ...
    def read(self, size: int = 1, /) -> bytes: ...
    def write(self, b: bytes, /) -> int | None: ...
    def flush(self) -> None: ...
    def reset_input_buffer(self) -> None: ...


class LinkError(UserError):
    """A module could not be reached, or answered nonsense, after every retry."""


class PortFailed(LinkError):
    """The port itself failed to read or write: no module is to blame, and no retry helps."""


class OldFirmware(LinkError):
    """A module answered a message a later firmware added as an unknown one (`FIRMWARE_ADDED`): its
    firmware predates it; asking again will not help."""

    def __init__(self, bus: str, address: int, message: codec.Message) -> None:
        version, what = FIRMWARE_ADDED[message.ID]
        super().__init__(
            f"bus {bus}, module {address}: answers {message.ID:02X}h ({what}) as an unknown message — its "
            "firmware is older "
            f"than PRC {version}, which added them: update the module's firmware, or leave "
            f"{message.FIELD.lower()} out of "
            "this module's programs in the plant file" if isinstance(message, codec.WriteField) else
            f"bus {bus}, module {address}: answers {message.ID:02X}h as an unknown message — its firmware "
            "has no read "
            f"messages (they came with PRC {version}), so prc3cfg can neither plan nor verify it: update "
            "the module's firmware"
        )


class NoReadMessages(OldFirmware):
    """A read answered as an unknown message: firmware before PRC 3.03.1, which added 50h..52h. prc3cfg
    can neither plan nor verify such a module."""


class PossibleWrite(LinkError):
    """A read was answered with an acknowledgement: a write's late or duplicated acknowledgement, or a
    damaged frame the module executed as a write — likeliest first by the line's protection and by
    whether writes to that module went unanswered (`owed` attempts): `exchange.ACK_TO_READ`. Either
    way nothing more may be sent on the line until a person has looked; never retried."""

    def __init__(self, bus: str, address: int, message: codec.Message, owed: tuple[int, ...] = (),
                 protection: Protection = Protection.NONE) -> None:
        cause = ACK_TO_READ[protection, bool(owed)]
        writes = "a write" if len(owed) == 1 else f"one of {len(owed)} writes"
        likeliest = cause.likeliest.format(owed=writes,
                                           write=", ".join(f"{i:02X}h" for i in dict.fromkeys(owed)))
        super().__init__(
            f"bus {bus}, module {address}: a read ({message.ID:02X}h) was answered as a write is — "
            f"likeliest {likeliest}"
            f"{'; ' + cause.also if cause.also else ''}: nothing more is sent on this line; travel the "
            "module to its reference "
            f"point, read it back, and {cause.remedy}"
        )
        self.bus, self.address = bus, address


@dataclass(frozen=True, slots=True)
class Exchange:
    """One attempt on the line, for journals: what went out, what came back."""

    bus: str
    address: int
    request: bytes  # the message
    reply: bytes | None  # the reply message, None when nothing (valid) came back
    attempt: int
    started: float  # time.time()
    duration: float  # s


class Link:
    """One line: a port, a framing, a reply time-out and a retry policy. `timeout` is the wait beyond
    the line's own time for a reply (`wait`); `cost` prices exchanges and gives the turnaround the
    deadlines allow (else `LineCost`'s default)."""

    def __init__(
        self,
        port: Port,
        framing: Framing,
        *,
        bus: str,
        line: LineSettings = LineSettings(),
        timeout: float = 0.5,
        zvz: float = 0.020,
        retries: int = 3,
        trace: Trace | None = None,
        observer: Callable[[Exchange], None] | None = None,
        announce: Callable[[Exchange], None] | None = None,
        cancel: threading.Event | None = None,
        takes_line_time: bool = True,
        cost: LineCost | None = None,
        port_name: str | None = None,
    ) -> None:
        self.port = port
        self.framing = framing
        self.bus = bus
        self.line = line
        self.timeout = timeout
        self.zvz = zvz
        self.retries = retries
        self.trace = trace
        self.observer = observer
        #: told of every attempt before its frame leaves (`reply` None): a journal, a release record
        self.announce = announce
        self.cancel = cancel
        #: Whether frames take their time on a line at the far end; False for an emulator that takes
        #: every frame at once and in order, where a broadcast needs no wait before the next frame.
        self.takes_line_time = takes_line_time
        self._gap_ends_frame = framing.name == "open-driver"
        #: Whether the bytes come from a UART, or over TCP, where their arrival times say nothing.
        self.uart = urlsplit(str(port.port)).scheme.lower() not in TCP_SCHEMES
        port.timeout = zvz if self._gap_ends_frame else min(READ_SLICE, timeout)
        #: whether the port refuses a character of bad parity (set after the timeout: pyserial's set-up clears
        #: it)
        self.parity_checked = platform.check_parity(port)
        #: Once a reply started, the longest it can take to end; past it the line is not quiet.
        self._longest_reply = line.transmission_time(LONGEST_REPLY_FRAME) + 2 * zvz
        self._heard = False  # whether a byte ever came back on this port
        self.exchanges = 0  # attempts made, for benchmarks and summaries
        self.repeated = 0  # attempts that failed (lost, damaged, unconfirmed) and were made again
        # pieces of bytes the framing threw away (damaged frames, garbage), for `prc3cfg doctor`
        self.discarded = 0
        #: time.monotonic() when the last frame had left, and when the last reply had come: the line's part
        #: of an exchange, without what the port adds before sending (RFC 2217's purge waits 50 ms)
        self.sent_at = self.replied_at = 0.0
        #: the line's settings as a plant file gives them, pricing each exchange (`prc3cfg.core.bustime`)
        self.cost = cost
        #: the same settings giving each reply its deadline (a port without a plant file's: the default
        #: turnaround)
        self._timing = cost if cost is not None else LineCost(framing, line, zvz=zvz)
        #: the port as the operator names it (a plant file's `port`), for what is said about the line
        self.port_name = port_name or str(port.port)
        #: exchanges answered, the seconds they took (frame out to reply in) and what `cost` priced them at
        self.answered = 0
        self.answered_time = self.priced_time = 0.0
        #: per module, the IDs of write attempts that went unanswered since its reply last carried data (a
        #: read's): their acknowledgements may still come, late, as the reply to a later frame to it (a
        #: reply from another address is never taken: `PossibleWrite` says so)
        self.owed: dict[int, list[int]] = {}

    def _possible_write(self, address: int, message: codec.Message) -> PossibleWrite:
        """A read to `address` answered as a write is, named by what this line protects and what was owed."""
        return PossibleWrite(self.bus, address, message, tuple(self.owed.get(address, ())),
                             protection(self.framing, parity_checked=self.parity_checked))

    def _where(self, address: int) -> str:
        return f"bus {self.bus}, module {address}"

    def request(self, address: int, message: codec.Message) -> Reply:
        """Send `message` to the module at `address`; its error code (0 = accepted) or data block.

        Each attempt's reply goes by `prc3cfg.core.exchange.VERDICTS`: a lost reply, a damaged one, and a
        structural error code (the module got our message damaged) are retried — but a read answered with an
        acknowledgement is `PossibleWrite`, and one answered as unknown is `NoReadMessages` (a write a later
        firmware added: `OldFirmware`; on a line without a checksum once heard twice). On a framing without a
        checksum an error code is asked for again until two agree. After the last attempt a `LinkError` names
        the bus and module. `Interrupted` when the link's `cancel` event is set before an attempt (`NotSent`
        before the first: the frame never left; `announce` may raise it too, to keep a frame back).
        """
        data, attempts, wait = message.encode(), 1 + self.retries, self.wait(address, message)
        # a code heard once on a line without a checksum, for the next attempt to confirm
        heard: int | None = None
        for attempt in range(1, attempts + 1):
            if self.cancel is not None and self.cancel.is_set():
                raise NotSent() if attempt == 1 else Interrupted()
            raw = self._attempt(address, message, data, attempt, wait)
            verdict = judge(message, raw, checked=self.framing.checked, heard=heard,
                            attempts_left=attempts - attempt, timeout=wait)
            if verdict.step is LinkStep.ANSWER:
                assert verdict.reply is not None  # an answer is a reply decoded
                return self._answered(address, verdict.reply)
            if verdict.step is LinkStep.POSSIBLE_WRITE:  # the verdicts that stop the line
                raise self._possible_write(address, message)
            if verdict.step is LinkStep.OLD_FIRMWARE:
                raise (NoReadMessages if message.IS_READ else OldFirmware)(self.bus, address, message)
            if verdict.step is LinkStep.GIVE_UP:
                break
            heard = verdict.unconfirmed
            note = (f"{self._where(address)}: {verdict.problem} to {message.ID:02X}h, retrying "
                    f"({attempt + 1} of {attempts})")
            self.repeated += 1
            log.info(note)
            if self.trace:
                self.trace.remark(self.bus, note)
        raise LinkError(
            f"{self._where(address)}: {verdict.problem} to {message.ID:02X}h after {attempts} attempts — "
            "check that "
            f"the module is powered, in STOP and AUTOMATIC, at address {address}, and that the bus's framing "
            f"({self.framing.name}) and line settings ({self.line.baud} baud, {self.line.data_bits}"
            f"{self.line.parity[0].upper()}{self.line.stop_bits:g}) match the line"
        )

    def wait(self, address: int, message: codec.Message, timeout: float | None = None) -> float:
        """Seconds to wait for the reply to `message` from its frame leaving: its deadline on this line
        (none where the far end takes no line time), then `timeout` — the link's own by default — more;
        rounded up to the millisecond, as it is said."""
        line = self._timing.reply_deadline(address, message) if self.takes_line_time else 0.0
        return math.ceil(round((line + (self.timeout if timeout is None else timeout)) * 1000, 6)) / 1000

    def probe(self, address: int, message: codec.Message, timeout: float) -> Reply | None:
        """Whether a module answers at `address`: one attempt, waiting the line's time and `timeout`
        more (`wait`); silence is None — an absent address is normal on a scan, and is not asked
        again. Something heard but not usable (a damaged reply) gets the usual retries (`request`)."""
        if self.cancel is not None and self.cancel.is_set():
            raise Interrupted()
        wait = self.wait(address, message, timeout)
        raw = self._attempt(address, message, message.encode(), 1, wait)
        if raw is None:
            return None
        verdict = judge(message, raw, checked=self.framing.checked, heard=None, attempts_left=0, timeout=wait)
        if verdict.step is LinkStep.POSSIBLE_WRITE:
            raise self._possible_write(address, message)
        if verdict.step is LinkStep.ANSWER:
            assert verdict.reply is not None  # an answer is a reply decoded
            return self._answered(address, verdict.reply)
        # heard, not usable (even a read answered as unknown): the usual retries
        return self.request(address, message)

    def broadcast(self, message: codec.Message, turnaround: float) -> None:
        """Send `message` to address 0: every module processes it, none answers. Where frames take
        line time, waits the frame's transmission, the modules' `turnaround` (and on open-driver the
        gap that ends the frame) before returning, so the next frame does not arrive while they
        work; `Interrupted` when cancelled first."""
        if self.cancel is not None and self.cancel.is_set():
            raise Interrupted()
        data = message.encode()
        frame = self.framing.encode(Direction.REQUEST, 0, data)
        started = time.time()
        self._announce(0, data, 1, started)
        self._send(frame)
        if self.takes_line_time:
            gap = self.zvz if self._gap_ends_frame else 0.0
            time.sleep(self.line.transmission_time(len(frame)) + turnaround + gap)
        self._observe(0, data, None, 1, started)

    def _attempt(self, address: int, message: codec.Message, data: bytes, attempt: int,
                 wait: float) -> bytes | None:
        """One attempt, told to `announce` before its frame leaves and to `observer` after: the reply
        message, or None (`_exchange`)."""
        started = time.time()
        self._announce(address, data, attempt, started)
        raw = self._exchange(address, data, wait)
        if raw is None and not message.IS_READ:
            self.owed.setdefault(address, []).append(message.ID)
        self._observe(address, data, raw, attempt, started)
        self._timed(address, message, raw)
        return raw

    def _answered(self, address: int, reply: Reply) -> Reply:
        if not isinstance(reply, int):  # a data block: no reply still owed by `address` was taken for it
            self.owed.pop(address, None)
        return reply

    def _announce(self, address: int, data: bytes, attempt: int, started: float) -> None:
        if self.announce:
            self.announce(Exchange(self.bus, address, data, None, attempt, started, 0.0))

    def _observe(self, address: int, data: bytes, raw: bytes | None, attempt: int, started: float) -> None:
        self.exchanges += 1
        if self.observer:
            self.observer(Exchange(self.bus, address, data, raw, attempt, started, time.time() - started))

    def _timed(self, address: int, message: codec.Message, raw: bytes | None) -> None:
        """An answered exchange's time on the line, beside its price (an unanswered one is a repeat, said
        apart)."""
        if raw is not None and self.cost is not None:
            self.answered += 1
            self.answered_time += self.replied_at - self.sent_at
            self.priced_time += self.cost.message_time(address, message)

    def _send(self, frame: bytes) -> None:
        try:
            self._discard()
            self.port.write(frame)
            self.port.flush()
        except Exception as error:  # noqa: BLE001 — pyserial's URL handlers (alt://…) fail in ways of their own
            raise self._failed("write to", error) from None
        self.sent_at = time.monotonic()
        if self.trace:
            self.trace.sent(self.bus, frame)

    def _discard(self) -> None:
        """What arrived since the last exchange is dropped before a frame leaves: pyserial's
        `reset_input_buffer` — but on rfc2217:// that asks the gateway to purge and waits for its
        answer, polling in 50 ms steps (more than a whole exchange at 9600 baud, on every frame):
        there what reached this end is read and dropped. Either way a byte still on its way is not,
        as on any port: the framing hunts past a partial frame, and a reply is taken only from the
        module asked and of the kind asked."""
        if isinstance(self.port, rfc2217.Serial):
            if waiting := self.port.in_waiting:
                self.port.read(waiting)
        else:
            self.port.reset_input_buffer()

    def _failed(self, doing: str, error: Exception) -> PortFailed:
        """The port failed `doing` ("read from", "write to"): a TCP gateway that ended the
        connection before any byte came back refused this client, another holding the line."""
        if not self.uart and not self._heard:
            return PortFailed(f"bus {self.bus}: the gateway is busy: another client holds the line (it "
                              "ended the connection "
                              f"before any reply: {_said(error)}) — wait for that client to finish, then "
                              "try again")
        return PortFailed(f"bus {self.bus}: cannot {doing} the port ({_said(error)}) — check the adapter "
                          "and cable")

    def _exchange(self, address: int, data: bytes, wait: float) -> bytes | None:
        """One attempt: the reply message from `address`, or None (nothing valid within `wait` s)."""
        self._send(self.framing.encode(Direction.REQUEST, address, data))
        decoder = self.framing.decoder(Direction.REPLY, self.line, zvz=self.zvz, uart=self.uart)
        deadline = time.monotonic() + wait
        last_call = deadline + self._longest_reply  # even a line that never goes quiet ends here
        pending = False  # bytes of a frame that only a gap can end
        while True:
            try:
                chunk = self.port.read(max(1, self.port.in_waiting))
            except Exception as error:  # noqa: BLE001 — as in _send
                raise self._failed("read from", error) from None
            now = time.monotonic()
            if chunk:
                self._heard = True
                decoder.receive_data(chunk, now)
                pending = self._gap_ends_frame
            elif pending:
                decoder.line_idle()
                pending = False
            while (event := decoder.next_event(now)) is not NEED_DATA:
                if isinstance(event, Discarded):
                    self.discarded += 1
                    if self.trace:
                        self.trace.discarded(self.bus, event.data, event.reason)
                    continue
                if self.trace:
                    self.trace.received(self.bus,
                                        self.framing.encode(Direction.REPLY, event.address, event.message))
                if event.address == address:
                    self.replied_at = now
                    return event.message
                if self.trace:
                    self.trace.remark(self.bus,
                                      f"reply from address {event.address}, expected {address}: ignored")
            if now >= deadline and not pending:
                if self.trace:
                    self.trace.remark(self.bus, f"timeout after {wait:g} s waiting for module {address}")
                return None
            if now >= last_call:
                if self.trace:
                    self.trace.remark(self.bus,
                                      f"the line did not go quiet within {last_call - deadline + wait:.3f} s")
                return None


def _said(error: Exception) -> str:
    """A port's failure in one line: pyserial's own errors as they say it, others with their kind."""
    if isinstance(error, (serial.SerialException, OSError)):
        return str(error)
    return f"{type(error).__name__}: {error}"
