"""Policy as code: what a change may reach (envelopes) and when it may go on (windows), judged as values.

A policy (`Policy`, loaded by `prc3cfg.plant.policy` from the file the plant file names) holds rules, each
with a level as HashiCorp Sentinel has them (`LEVELS`): `advisory` is said and never refuses, `soft`
refuses unless overridden with a recorded reason, `hard` always refuses.

- An `Envelope` bounds the values of the modules it covers (buses and module names, by glob) in the plant
  file's human units (`KEYS`): a program field (`position`, `speed`, `relative_speed`, `dwell`, and
  `function_distance`, the distance of F1 and of F2) in every managed program, a system parameter
  (`upper_reversing_point`, `max_speed`, …), or what a chain's motion reaches (`CHAIN_KEYS`, worked out by
  `prc3cfg.core.motion` from the desired image): `stroke_length`, from its lowest to its highest reversing
  point, and `pass_time`, one turn of a loop in production or, for a chain that stops, its pass from the
  reference point.
- A `Window` is a cron expression (5 fields, `Cron`), a duration and an IANA time zone, `deny` or `allow`,
  over the buses it names. Deny wins: a deny window open at `now` refuses at its level; where allow windows
  cover a bus, being outside all of them refuses at the highest of their levels.

When a window starts: at every local wall-clock minute its cron matches, resolved to an instant as
`zoneinfo` does with `fold=0` — a time the clock skips (spring forward, 02:30 in Berlin) starts the window at
the instant that time would have been had the clock not jumped (03:30 on the wall), and a time the clock
repeats (fall back, 02:30 twice) starts it once, at the first. The window then lasts `duration` of real time.

`findings(values, buses, policy, now)` is the whole judgement: pure, no clock (now is a value), no files.
Where each value and rule is in its file is a path (`Path_`); the loader turns paths into file:line:col.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from datetime import UTC, date, datetime, timedelta
from decimal import Decimal
from typing import Literal
from zoneinfo import ZoneInfo

from prc3cfg.core.units import DISTANCE, QUANTITIES, Quantity

Level = Literal["advisory", "soft", "hard"]
#: The levels, weakest first (Sentinel's advisory, soft-mandatory, hard-mandatory).
LEVELS: tuple[Level, ...] = ("advisory", "soft", "hard")
#: The program fields an envelope may bound; every other key of `QUANTITIES` it may bound is a system
#: parameter.
PROGRAM_KEYS = ("position", "speed", "relative_speed", "dwell")
#: What a chain's motion reaches (`Value.chain`): in steps that say a pass as the plan's stroke charts do.
CHAIN_KEYS = {q.key: q
              for q in (Quantity("stroke_length", "", Decimal("0.001"), "m"),
                        Quantity("pass_time", "", Decimal("0.01"), "s"))}
#: Every key an envelope may bound, and its unit and step: F1's and F2's distance is `function_distance`.
KEYS: dict[str, Quantity] = QUANTITIES | {"function_distance": DISTANCE} | CHAIN_KEYS
Path_ = tuple[str | int, ...]

#: Each cron field: its name and the values it takes (day of week 0..7, 0 and 7 both Sunday).
CRON_FIELDS = (("minute", 0, 59), ("hour", 0, 23), ("day of month", 1, 31), ("month", 1, 12),
               ("day of week", 0, 7))


@dataclass(frozen=True, slots=True)
class Cron:
    """A 5-field cron expression as sets; `days_any`/`weekdays_any`: the field was `*` (cron's rule: when both
    day fields are restricted, a day matching either matches)."""

    minutes: frozenset[int]
    hours: frozenset[int]
    days: frozenset[int]
    months: frozenset[int]
    weekdays: frozenset[int]  # 0 Sunday .. 6 Saturday
    days_any: bool
    weekdays_any: bool

    def day_matches(self, day: date) -> bool:
        if day.month not in self.months:
            return False
        in_days, in_weekdays = day.day in self.days, day.isoweekday() % 7 in self.weekdays
        if self.days_any or self.weekdays_any:
            return in_days and in_weekdays
        return in_days or in_weekdays


def parse_cron(text: str) -> Cron:
    """`text` as a cron expression: 5 fields of `*`, `N`, `N-M`, each with an optional `/STEP`, joined by
    commas; ValueError saying what is wrong otherwise (names such as MON and JAN are not taken: numbers only).
    """
    fields = text.split()
    if len(fields) != len(CRON_FIELDS):
        raise ValueError("a cron expression has 5 fields (minute hour day-of-month month day-of-week), "
                         f"this has {len(fields)}")
    sets = [_cron_field(field, *spec) for field, spec in zip(fields, CRON_FIELDS)]
    minutes, hours, days, months, weekdays = sets
    return Cron(minutes, hours, days, months, frozenset(d % 7 for d in weekdays), days_any=fields[2] == "*",
                weekdays_any=fields[4] == "*")


def _cron_field(text: str, name: str, lo: int, hi: int) -> frozenset[int]:
    values: set[int] = set()
    for part in text.split(","):
        span, _, step_text = part.partition("/")
        try:
            step = int(step_text) if step_text else 1
            first, _, last = span.partition("-")
            start, end = (lo, hi) if span == "*" else (int(first), int(last) if last else int(first))
        except ValueError:
            raise ValueError(f"the {name} field '{text}' is not *, N, N-M or those with /STEP, "
                             "by commas") from None
        if step < 1 or not lo <= start <= end <= hi or (step_text and not last and span != "*"):
            raise ValueError(f"the {name} field '{text}' must stay within {lo}..{hi}, ranges low-high, "
                             "steps 1 or more")
        values.update(range(start, end + 1, step))
    return frozenset(values)


@dataclass(frozen=True, slots=True)
class Limit:
    """Bounds on one key (`QUANTITIES`), in human units; `at`: where the rule's limit is in the policy
    file."""

    key: str
    lo: Decimal | None
    hi: Decimal | None
    at: Path_


@dataclass(frozen=True, slots=True)
class Envelope:
    name: str
    level: Level
    buses: tuple[str, ...]
    modules: tuple[str, ...]
    limits: tuple[Limit, ...]
    at: Path_


@dataclass(frozen=True, slots=True)
class Window:
    name: str
    level: Level
    kind: Literal["deny", "allow"]
    cron: Cron
    duration: timedelta
    time_zone: ZoneInfo
    buses: tuple[str, ...]
    at: Path_


@dataclass(frozen=True, slots=True)
class Policy:
    envelopes: tuple[Envelope, ...]
    windows: tuple[Window, ...]

    @property
    def limited(self) -> frozenset[str]:
        """The keys some envelope bounds: the values a plan's judgement needs."""
        return frozenset(limit.key for envelope in self.envelopes for limit in envelope.limits)


@dataclass(frozen=True, slots=True)
class Value:
    """One value a plan's desired image reaches: `program` None for a system parameter; `chain` the chain's
    label ("chain 1 → 2 → 1", `motion.ChainMotion.label`) for what its motion reaches; `at` its place in the
    plant file."""

    bus: str
    module: str
    key: str
    program: int | None
    value: Decimal
    at: Path_
    chain: str | None = None

    @property
    def subject(self) -> str:
        """What the value is of, as a finding says it: "program 1 speed", "chain 1 → 2 → 1 pass_time",
        "max_speed"."""
        return (f"{self.chain} {self.key}" if self.chain else f"program {self.program} {self.key}"
                if self.program is not None else self.key)


@dataclass(frozen=True, slots=True)
class RuleFinding:
    """What a rule found: `value_at` the plant file's value (None for a window), `rule_at` the rule in the
    policy."""

    kind: Literal["envelope", "window"]
    rule: str
    level: Level
    message: str
    rule_at: Path_
    value_at: Path_ | None = None


def _covers(globs: tuple[str, ...], name: str) -> bool:
    return not globs or any(fnmatch.fnmatchcase(name, glob) for glob in globs)


def starts(window: Window, since: datetime, until: datetime) -> Iterator[datetime]:
    """The instants (UTC) in [since, until] at which `window` starts, in order, by the rule in the module's
    docstring."""
    zone = window.time_zone
    day = (since.astimezone(zone) - timedelta(days=1)).date()  # a day's margin: offsets are under a day
    last = (until.astimezone(zone) + timedelta(days=1)).date()
    while day <= last:
        if window.cron.day_matches(day):
            for hour in sorted(window.cron.hours):
                for minute in sorted(window.cron.minutes):
                    start = datetime(day.year, day.month, day.day, hour, minute, tzinfo=zone,
                                     fold=0).astimezone(UTC)
                    if since <= start <= until:
                        yield start
        day += timedelta(days=1)


def open_since(window: Window, now: datetime) -> datetime | None:
    """The start of the occurrence of `window` that `now` is in (the latest, if several overlap); None when it
    is shut."""
    found = list(starts(window, now - window.duration + timedelta(microseconds=1), now))
    return found[-1] if found else None


def findings(values: Iterable[Value], buses: Iterable[str], policy: Policy,
             now: datetime) -> list[RuleFinding]:
    """Every finding of `policy` on the `values` of a plan's desired images and on the `buses` it writes, at
    `now`."""
    found = [_outside(envelope, value, limit) for value in values for envelope in policy.envelopes
             if _covers(envelope.buses, value.bus) and _covers(envelope.modules, value.module)
             for limit in envelope.limits if limit.key == value.key]
    return [f for f in found if f is not None] + [f for bus in dict.fromkeys(buses)
                                                  for f in _windows(policy.windows, bus, now)]


def _outside(envelope: Envelope, value: Value, limit: Limit) -> RuleFinding | None:
    quantity = KEYS[value.key]
    for bound, word in ((limit.hi, "above"), (limit.lo, "below")):
        if bound is not None and (value.value > bound if word == "above" else value.value < bound):
            said = f"{value.subject} {_in_steps(value.value, quantity.step)} {quantity.unit}".rstrip()
            return RuleFinding("envelope", envelope.name, envelope.level,
                           f"module {value.module}: {said} is {word} {_in_steps(bound, quantity.step)} "
                           f"{quantity.unit}".rstrip()
                           + f", the limit of envelope '{envelope.name}'", limit.at, value.at)
    return None


def _in_steps(number: Decimal, step: Decimal) -> Decimal:
    """`number` with at least the digits of its quantity's step (0.35 m as 0.350 m), never fewer than
    written."""
    exponent, steps = number.as_tuple().exponent, step.as_tuple().exponent
    return (number.quantize(step) if isinstance(exponent, int) and isinstance(steps, int)
            and exponent > steps else number)


def _windows(windows: Iterable[Window], bus: str, now: datetime) -> Iterator[RuleFinding]:
    ours = [w for w in windows if _covers(w.buses, bus)]
    for window in ours:
        if window.kind == "deny" and (start := open_since(window, now)) is not None:
            until = (start + window.duration).astimezone(window.time_zone)
            yield RuleFinding("window", window.name, window.level,
                          f"bus {bus}: deny window '{window.name}' is open until {until:%Y-%m-%d %H:%M %Z}",
                              window.at)
    allowing = [w for w in ours if w.kind == "allow"]
    if allowing and all(open_since(w, now) is None for w in allowing):
        strongest = max(allowing, key=lambda w: LEVELS.index(w.level))
        names = ", ".join(f"'{w.name}'" for w in allowing)
        yield RuleFinding("window", strongest.name, strongest.level,
                          f"bus {bus}: outside every allow window ({names})", strongest.at)


def refusing(found: Iterable[RuleFinding], overridden: Iterable[str] = ()) -> list[RuleFinding]:
    """The findings that refuse: every hard one, and every soft one whose kind is not `overridden`."""
    kinds = set(overridden)
    return [f for f in found if f.level == "hard" or (f.level == "soft" and f.kind not in kinds)]


def fails_plan(found: Iterable[RuleFinding]) -> bool:
    """Whether findings fail a plan (`plan` exits 3) and a plant file (`validate`): a hard envelope. A window
    judges the moment of an apply, and a plan reviewed in a freeze may be applied after it: it never fails a
    plan."""
    return any(f.kind == "envelope" and f.level == "hard" for f in found)
