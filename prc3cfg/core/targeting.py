"""What a targeted read-back reads, from the line's record to the plant file, and what evidence overrules it.

The *record* of a line (`prc3cfg.shell.bases`) says what prc3cfg last read or verified each of its
modules to hold — whichever plant file, checkout or user it was — with when and by whom (`Known`).
Every plan reads every module's system block (one 50h: it proves the module is there and the one
expected, S9, and catches a 10h from another tool and most spares), and of the managed programs
those whose desired values the record does not show the module holding (`to_read`): a program the
record shows as the plant file wants it is taken as known, not read. A module the record does not
know, or knows only from longer ago than the bus's `record_max_age`, is read in full. What is read
is evidence (`contradiction`): a system block or a program other than the record's means someone
else changed the module, and it is read in full and planned in full (`prc3cfg.shell.readback`).
Every program a system change could clamp is read too (`prc3cfg.shell.readback.Target.clamped_by`:
decided on the system block just read). What no read can see: a program the change does not read,
changed by another tool on a module whose system block is unchanged, within the record's age.

What is not read is not written: the desired image a targeted plan aims at is cut to the
programs the read-back holds (`within_read`), so the planner — which never writes a program
its desired image leaves `None` (`prc3cfg.core.planner.check`, rule 2), and so never sends an
11h/13h/14h across one — cannot write, initialise or rely on a program it did not read.
Pure.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from datetime import UTC, datetime, timedelta

from prc3cfg.core.image import ModuleImage


@dataclass(frozen=True, slots=True)
class Known:
    """What a line's record says a module holds: its image (a program not known: None), since when
    the oldest value in it was read or verified (ISO 8601, UTC), and by which command, file and user."""

    image: ModuleImage
    since: str
    by: str

    def said(self) -> str:
        """"apply of /p/a.yaml by ana@pc-3 (since 2026-11-26 03:27 UTC)": whose read or verification, to the minute."""
        return f"{self.by} (since {datetime.fromisoformat(self.since).astimezone(UTC):%Y-%m-%d %H:%M} UTC)"


@dataclass(frozen=True, slots=True)
class ToRead:
    """A module's read: the programs beyond its system block, the record the read must agree with
    (None: read in full), and why it is read in full (None: it is not)."""

    programs: tuple[int, ...]
    known: ModuleImage | None
    why: str | None


def to_read(known: Known | None, desired: ModuleImage, now: datetime, max_age: float) -> ToRead:
    """What to read of a module the plant file wants as `desired`, given the line's record of it."""
    managed = tuple(n for n, p in enumerate(desired.programs, start=1) if p is not None)
    if known is None:
        return ToRead(managed, None, "not on the line's record")
    if now - datetime.fromisoformat(known.since) > timedelta(seconds=max_age):
        return ToRead(managed, None, f"its record ({known.since}) is older than record_max_age ({max_age:g} s)")
    return ToRead(tuple(n for n in managed if known.image.program(n) != desired.program(n)), known.image, None)


def contradiction(known: ModuleImage, read: ModuleImage) -> str | None:
    """How a read-back contradicts the record of its module (None: it does not): the module was
    changed by something other than prc3cfg since, or is another module."""
    if read.system != known.system:
        return "its system parameters are not those on record"
    for number, (was, now) in enumerate(zip(known.programs, read.programs), start=1):
        if was is not None and now is not None and was != now:
            return f"program {number} is not as on record"
    return None


def merged(known: Known | None, read: ModuleImage, when: str, by: str) -> Known:
    """The record of a module after `read` was read (or verified) `when` by `by`: what was read,
    with the values of the record it did not read again — unless it contradicts the record, which
    then goes whole. Its `since` stays the record's while any value of the record is kept."""
    return verified(None if known is None or contradiction(known.image, read) is not None else known, read, when, by)


def within_read(desired: ModuleImage, actual: ModuleImage) -> ModuleImage:
    """`desired` cut to the programs `actual` (a read-back) holds: the others are not the plan's."""
    return replace(desired, programs=tuple(None if a is None else d for d, a in zip(desired.programs, actual.programs)))


def not_read(desired: ModuleImage, actual: ModuleImage) -> tuple[int, ...]:
    """The programs `desired` manages that the read-back `actual` does not hold: taken as last verified."""
    return tuple(n for n, (d, a) in enumerate(zip(desired.programs, actual.programs), start=1) if d is not None and a is None)


def verified(known: Known | None, held: ModuleImage, when: str, by: str) -> Known:
    """The record of a module prc3cfg wrote and verified `when`, by `by`, to hold `held` (what it read
    back, and what its steps wrote): that, with the values of the record it neither wrote nor read —
    what the writes changed is no contradiction. Its `since` stays the record's while any of those is kept."""
    if known is None:
        return Known(held, when, by)
    programs = tuple(now if now is not None else was for was, now in zip(known.image.programs, held.programs))
    kept = any(now is None and was is not None for was, now in zip(known.image.programs, held.programs))
    return Known(replace(held, programs=programs), known.since if kept else when, known.by if kept else by)


def with_known(image: ModuleImage, desired: ModuleImage) -> ModuleImage:
    """`image` (a read-back, or what a plan leaves of one) with the managed programs it did not read
    filled in with the plant file's values — what the line's record showed them holding, which is why
    they were not read (`to_read`): the values a picture of the module's chains must use, never a
    chain cut where a program was not read."""
    return image.with_programs({n: d for n, (d, a) in enumerate(zip(desired.programs, image.programs), start=1) if d is not None and a is None})
