"""`prc3cfg doctor`: the line measured, not assumed — which framing, baud and parity a line speaks,
found by probing, and each answering module's turnaround, measured.

The search is bounded and tries the most likely first: the plant file's defaults (crc16, 9600
baud, even parity; none on a pseudo-terminal), then the other framings at those settings, then
the other baud rates and parities (`Search.candidates`). Only 50h (read the system parameters)
is sent, to each address until one answers; the modules found then get `exchanges` more 50h
each, timed. A frame sent at the wrong settings arrives as other bytes (`prc3cfg.core.uart`): on
a framing without a checksum those bytes can read as a write, so a probe in such a framing is
made only once `allow_unchecked()` said yes. Data bits are 8: a PRC 3 frame is binary, and a
character of fewer bits loses its top bits. Stop bits cannot be found: a UART checks one.

A turnaround is what the bus-time model (`prc3cfg.core.bustime`) must add to the line's time to
give the time an exchange took — from its frame leaving to its reply having come, less the frames'
transmission (and on open-driver the two ZVZ gaps) — so a plan priced with it is priced as the
line measured, and a reply is waited for as long as the slowest module measured takes
(`LineCost.reply_deadline`). A timed exchange waits `MEASURE_ALLOWANCE` beyond the line's time, so
a module slower than the probes allow is measured, not counted lost; one whose answers varied by
more than a plant file's default `timeout` gets that spread proposed as its `timeout`, the wait on
top of the slowest answer seen.

Owns the search and the measuring. Does not own locking the line (`prc3cfg.api.doctor`), the
port (`prc3cfg.shell.link.ports`) nor the output (`prc3cfg.cli`).
"""

from __future__ import annotations

import contextlib
import math
import statistics
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field

from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.framing import get_framing
from prc3cfg.core.line import LineSettings
from prc3cfg.plant.models import BusLine
from prc3cfg.shell.link.client import Exchange, Link, Port
from prc3cfg.shell.probe import probe

#: Baud rates in the order they are tried after the first: PRC 3 lines run 9600; a CP 524 19200 at most.
BAUDS = (9600, 19200, 4800, 2400, 1200, 38400, 57600, 600, 300)
#: Framings with a checksum first: a probe in one cannot become a write where it arrives garbled.
FRAMINGS = ("crc16", "stx", "open-driver")
#: The longest a module may take to start its answer, on top of the frames' own time, while probing.
PROBE_ALLOWANCE = 0.2
#: … and once found, in a timed exchange: a module that slow is measured, not counted lost.
MEASURE_ALLOWANCE = 2.0
#: The plant file's `timeout` when it gives none: the wait on top of the line's own time it already allows.
DEFAULT_TIMEOUT: float = BusLine.model_fields["timeout"].default


@dataclass(frozen=True)
class LineCandidate:
    framing: str
    line: LineSettings

    @property
    def unchecked(self) -> bool:
        """A framing without a checksum: a probe at the wrong settings could arrive as a write."""
        return not get_framing(self.framing).checked

    def said(self) -> str:
        line = self.line
        return f"{self.framing}, {line.baud} baud, {line.data_bits}{line.parity[0].upper()}{line.stop_bits:g}"


@dataclass(frozen=True)
class Search:
    """What to try: each tuple in the order tried (`candidates`)."""

    framings: tuple[str, ...] = FRAMINGS
    bauds: tuple[int, ...] = BAUDS
    parities: tuple[str, ...] = ("even", "none", "odd")
    stop_bits: float = 1

    def candidates(self) -> Iterator[LineCandidate]:
        """Line settings outer, framings inner: at the right settings a frame of the wrong framing
        arrives whole, and is no frame at all to the modules."""
        for baud in self.bauds:
            for parity in self.parities:
                line = LineSettings(baud, 8, parity, self.stop_bits)
                for framing in self.framings:
                    yield LineCandidate(framing, line)


@dataclass(frozen=True)
class Timing:
    """One module's exchanges: the turnarounds measured (s), and the frames damaged and lost."""

    address: int
    turnarounds: tuple[float, ...]
    damaged: int
    lost: int

    @property
    def median(self) -> float:
        return statistics.median(self.turnarounds) if self.turnarounds else math.nan

    @property
    def worst(self) -> float:
        return max(self.turnarounds, default=math.nan)

    @property
    def spread(self) -> float:
        """How much the answers varied: the slowest less the quickest (0 with none)."""
        return self.worst - min(self.turnarounds) if self.turnarounds else 0.0


@dataclass(frozen=True)
class Diagnosis:
    """What a line speaks and how its modules answer. `settings_found`: baud and parity were probed
    (False over `socket://`, where the gateway fixes them and the probes could try framings only)."""

    port: str
    found: LineCandidate | None
    zvz: float
    settings_found: bool
    modules: tuple[Timing, ...] = ()
    probes: int = 0
    skipped_unchecked: int = 0

    def plant_keys(self) -> dict[str, object]:
        """The bus keys of a plant file for this line; `turnaround` the slowest answer measured,
        rounded up to the millisecond — a broadcast waits it for the slowest module; `timeout` only
        where a module's answers varied by more than `DEFAULT_TIMEOUT`: by that much, the next may come
        later than the slowest seen."""
        if self.found is None:
            return {}
        line = self.found.line
        keys: dict[str, object] = {"framing": self.found.framing, "baud": line.baud, "parity": line.parity,
                                   "data_bits": line.data_bits, "stop_bits": line.stop_bits}
        if self.found.framing == "open-driver":
            keys["zvz"] = self.zvz
        worst = [t.worst for t in self.modules if t.turnarounds]
        if worst:
            keys["turnaround"] = _millis(max(worst))
        spread = max((t.spread for t in self.modules), default=0.0)
        if spread > DEFAULT_TIMEOUT:
            keys["timeout"] = _millis(spread)
        return keys


def _millis(seconds: float) -> float:
    """Seconds rounded up to the millisecond (a plant file's times are written so)."""
    return math.ceil(round(seconds * 1000, 6)) / 1000


@dataclass
class _Counts:
    """The attempts a link made, as its observer saw them."""

    attempts: list[Exchange] = field(default_factory=list)

    def __call__(self, exchange: Exchange) -> None:
        self.attempts.append(exchange)


def diagnose(
    port_name: str,
    search: Search,
    open_line: Callable[[LineSettings], contextlib.AbstractContextManager[Port]],
    *,
    addresses: Iterable[int],
    zvz: float,
    settings_found: bool,
    exchanges: int,
    allow_unchecked: Callable[[], bool],
    progress: Callable[[LineCandidate], None] = lambda _: None,
) -> Diagnosis:
    """Probe `search`'s candidates in order until a module answers; then measure every module that
    answers there (`exchanges` timed 50h each). `open_line` opens the port at a line's settings."""
    wanted = list(addresses)
    probes = skipped = 0
    consent: bool | None = None
    by_line: dict[LineSettings, list[LineCandidate]] = {}
    for candidate in search.candidates():
        by_line.setdefault(candidate.line, []).append(candidate)
    for line, candidates in by_line.items():
        with open_line(line) as port:
            for candidate in candidates:
                if candidate.unchecked:
                    if consent is None:
                        consent = allow_unchecked()
                    if not consent:
                        skipped += 1
                        continue
                progress(candidate)
                link = Link(port, get_framing(candidate.framing), bus=port_name, line=line,
                            timeout=PROBE_ALLOWANCE, zvz=zvz, retries=0)
                probes += len(wanted)
                found = [address for address in wanted if _answers(link, address)]
                if found:
                    timings = tuple(_measure(link, candidate, address, zvz, exchanges) for address in found)
                    return Diagnosis(port_name, candidate, zvz, settings_found, timings, probes, skipped)
    return Diagnosis(port_name, None, zvz, settings_found, (), probes, skipped)


def _answers(link: Link, address: int) -> bool:
    """Whether a module at these settings answers at `address` (heard but garbled: nothing such a module would
    answer)."""
    heard = probe(link, address, link.timeout)
    return heard is not None and isinstance(heard.reply, codec.SystemReply)


def _measure(link: Link, candidate: LineCandidate, address: int, zvz: float, exchanges: int) -> Timing:
    """`exchanges` single attempts of a 50h: each one answered gives a turnaround, each without a
    valid reply counts as damaged (bytes came back, or a frame was discarded) or lost (silence)."""
    counts = _Counts()
    link.observer = counts
    line_time = LineCost.of(candidate.framing, candidate.line, 0.0,
                            zvz).message_time(address, codec.ReadSystem())
    turnarounds, damaged, lost = [], 0, 0
    for _ in range(exchanges):
        discarded, before = link.discarded, len(counts.attempts)
        heard = probe(link, address, MEASURE_ALLOWANCE)
        reply = heard.reply if heard is not None else None
        attempts = counts.attempts[before:]
        if isinstance(reply, codec.SystemReply):
            attempts.pop()
            turnarounds.append(max(0.0, link.replied_at - link.sent_at - line_time))
        for attempt in attempts:  # each attempt without a usable reply: bytes that were no reply, or none
            if attempt.reply is not None or link.discarded > discarded:
                damaged += 1
            else:
                lost += 1
    link.observer = None
    return Timing(address, tuple(turnarounds), damaged, lost)
