"""What to read of the modules — for a plan, a plan file, a restore and a verification — and what the
line's record of them becomes from what was read: the one answer, from the record, the change and the
evidence. Pure: the callers read the record and the lines (`prc3cfg.api`, `prc3cfg.shell.readback`,
`prc3cfg.shell.apply`) and hand over plain values.

The *record* of a line (`prc3cfg.shell.line_record`) says what prc3cfg last read or verified each of its
modules to hold — whichever plant file, checkout or user it was — with when and by whom (`Known`).

- A full read (`in_full`: `read`, a plan with `--full-read` or with no record, a plan file made from
  one, a restore) reads every program the plant file manages — for a restore, every program the
  snapshot holds — and its system block.
- A plan (`for_plan`) reads every module's system block (one 50h: it proves the module is there and
  the one expected, S9, and catches a 10h from another tool and most spares), and of the managed
  programs those whose desired values the record does not show the module holding (`to_read`): a
  program the record shows as the plant file wants it is taken as known, not read. A module the record
  does not know, knows only from longer ago than the bus's `record_max_age`, or that reported E12
  since, is read in full.
- Rolling evidence (`with_rolling`): a plan also reads, per line, the programs whose values on record
  are the oldest, a few windows of four (`rolling`, `ROLLED_WINDOWS`: the budget, and the bound it
  gives), with the record to agree with: the read is evidence like any other, and those values are as
  new as the plan after it (`Known.read_at`), so the next plan rolls the next oldest. A program another
  tool changed is found within a bounded number of whole-line plans, not only once the record outgrows
  `record_max_age`.
- A plan file (`for_plan_file`) reads again exactly what its plan read — and is stale when the record
  no longer shows a module holding what the plan took as known without reading it.
- Each read widens on what it finds (`after_system`, `after_programs`): every program a system change
  could clamp (decided on the system block just read: the module's own clamping reaches programs the
  plant does not manage), and what is read is evidence (`contradiction`) — a system block or a program
  other than the record's means someone else changed the module, and it is read in full and planned
  in full — and so is every other module of its line, in that run (`opens_line`): a module that
  contradicts the record is evidence of another hand on the line (two controllers swapped: the other
  one's system block agrees with the record, its programs do not). What no read can see: a program
  the change does not read, changed by another tool on a module whose system block is unchanged, on a
  line no module of which the change reads contradicts the record — until rolling evidence reads it.
- A verification (`verification_reads`) reads what the steps that went out could have changed
  (`reach`), or with `Verify.FULL` everything the first read-back held; `read_messages` is the fewest
  50h/51h/52h for any of these, `verification_time` what reading back the reach costs (the floor of a
  verification, which the planning of broadcasts must pay for every module a broadcast reaches).
- When a verification reads — after every frame still on its way has landed — is `prc3cfg.core.late_frames`'s.

On a line where nothing protects a data reply (`protects_replies`: a framing without a checksum, and no parity
the port checks), every read is confirmed — by what the line's record or the write being verified says the
module holds, else read again until two in a row agree (`CONFIRMATIONS` at most; `prc3cfg.shell.readback`):
one damaged reply is never believed once, by a plan, a snapshot, a record or `read`.

A factory-fresh module (`factory_fresh`: its 50h reads the factory's system parameters, the plant file wants
others, and nothing in the line's record says otherwise) is where an apply commissions: what it holds is very
likely the factory's programs — not certainly (another tool may have written programs and left the system
block). An apply (`fresh` targets, `commissioning`; not `plan`, `read`, a plan file or a restore) reads no
program the plant file manages there before writing: it plans them from the factory's (`assumed`,
`from_factory`) and the verification reads every one of them back after the writes, whether a step wrote it
or not (`prc3cfg.shell.apply`), so one another tool changed is found and goes through the repair round. What
the plant file leaves unmanaged is read as before — where the plant's system parameters can clamp it — or
not at all; the planner never writes, initialises or relies on a program its desired image leaves `None`, so
an unmanaged program is never changed unread. The plan says which programs it did not read (its `evidence`).

What is not read is not written: the desired image a targeted plan aims at is cut to the programs
the read-back holds (`within_read`), so the planner — which never writes a program its desired
image leaves `None` (`prc3cfg.core.planner.check`, rule 2), and so never sends an 11h/13h/14h across
one — cannot write, initialise or rely on a program it did not read.

It is long because it is the one answer to "what to read" for all four callers, in the record's
terms (`Known`, `Target`): split by caller, each part would restate the rules the others rely on.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime, timedelta
from math import fsum
from typing import Protocol, TypeVar

from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.device import can_clamp
from prc3cfg.core.image import (
    DEFAULT_SYSTEM,
    PROGRAM_NUMBERS,
    Key,
    ModuleImage,
    Placed,
    SystemParameters,
    Wanted,
    default_program,
)
from prc3cfg.core.planner import Step
from prc3cfg.core.text import number_runs

#: Why a module that reported E12 (system parameters not set) is read in full: its record says nothing.
UNSET = "it reported E12 (system parameters not set)"


@dataclass(frozen=True, slots=True)
class Known:
    """What a line's record says a module holds: its image (a program not known: None), since when
    the oldest value in it was read or verified (ISO 8601, UTC), and by which command, file and user;
    and when each program read or verified later than that was (`read_at`: by number; the rest, `since`)."""

    image: ModuleImage
    since: str
    by: str
    read_at: Mapping[int, str] = field(default_factory=dict)

    def age(self, number: int) -> datetime:
        """When program `number`'s value on record was last read or verified."""
        return datetime.fromisoformat(self.read_at.get(number, self.since))

    def said(self) -> str:
        """"apply of /p/a.yaml by ana@pc-3 (since 2026-11-26 03:27 UTC)": whose read or verification, to the
        minute."""
        return f"{self.by} (since {to_the_minute(self.since)})"


def to_the_minute(when: str) -> str | None:
    """An ISO 8601 time as the record's words say it: "2026-11-26 03:27 UTC"; None for a text that is none."""
    try:
        return f"{datetime.fromisoformat(when).astimezone(UTC):%Y-%m-%d %H:%M} UTC"
    except ValueError:
        return None


@dataclass(frozen=True, slots=True)
class Target:
    """A module to read: where it is, what it is called, which programs, and the system
    parameters a plan may write there (every program is read when they can clamp: `after_system`)."""

    bus: str
    address: int
    name: str
    programs: tuple[int, ...]
    clamped_by: SystemParameters | None = None
    # a targeted read's evidence, and the programs it reads in full then: `after_programs`
    known: ModuleImage | None = None
    managed: tuple[int, ...] = ()
    # an apply's: a factory-fresh module's managed programs are planned from the factory's,
    # not read (`after_system`)
    fresh: bool = False


def programs_in(image: ModuleImage) -> tuple[int, ...]:
    """The programs `image` holds: of a desired image those the plant manages, of a read-back those read."""
    return tuple(n for n, p in enumerate(image.programs, start=1) if p is not None)


#: Reads of one message, at most, on a line where nothing protects a data reply, to hear the same reply twice
#: in a row.
CONFIRMATIONS = 4


def protects_replies(checked: bool, parity: str, parity_checked: bool) -> bool:
    """Whether a damaged data reply is refused on a line: by the framing's checksum (`checked`), or by
    a `parity` the port itself checks (`parity_checked`: a character of bad parity dropped, its frame
    too short to decode). Else a flipped bit is a believable value, and a read is heard twice."""
    return checked or (parity != "none" and parity_checked)


# -- what a command reads -----------------------------------------------------------------------


def in_full(modules: Iterable[Wanted]) -> list[Target]:
    """Every module read in full: each program its desired image holds (managed, or a snapshot's), and
    every program its desired system parameters could clamp."""
    return [Target(m.bus, m.address, m.name, programs_in(m.desired), m.desired.system,
                   managed=programs_in(m.desired)) for m in modules]


@dataclass(frozen=True, slots=True)
class ToRead:
    """A module's read: the programs beyond its system block, the record the read must agree with
    (None: read in full), and why it is read in full (None: it is not)."""

    programs: tuple[int, ...]
    known: ModuleImage | None
    why: str | None


def to_read(known: Known | None, desired: ModuleImage, now: datetime, max_age: float) -> ToRead:
    """What to read of a module the plant file wants as `desired`, given the line's record of it."""
    managed = programs_in(desired)
    if known is None:
        return ToRead(managed, None, "not on the line's record")
    if now - datetime.fromisoformat(known.since) > timedelta(seconds=max_age):
        return ToRead(managed, None,
                      f"its record ({known.since}) is older than record_max_age ({max_age:g} s)")
    return ToRead(tuple(n for n in managed if known.image.program(n) != desired.program(n)), known.image,
                  None)


def for_plan(modules: Sequence[Wanted], known: Mapping[Key, Known], overruled: Mapping[Key, str],
             unset: frozenset[Key],
             max_age: Mapping[str, float], now: datetime) -> tuple[list[Target], dict[Key, str]] | None:
    """What a plan reads of `modules` (each with the plant file's image), given the lines' record
    (`known`), the modules another user's newer entry took off it (`overruled`, with whose claim), those
    that reported E12 since (`unset`) and each bus's `record_max_age`: the targets, and why each module
    read in full before any evidence is — None when the record knows none of them: read `in_full`."""
    if not any(m.key in known or m.key in overruled for m in modules):
        return None
    targets, why = [], {}
    for m in modules:
        decision = to_read(None if m.key in unset else known.get(m.key), m.desired, now, max_age[m.bus])
        targets.append(Target(m.bus, m.address, m.name, decision.programs, m.desired.system, decision.known,
                              programs_in(m.desired)))
        if decision.why is not None:
            why[m.key] = UNSET if m.key in unset else overruled.get(m.key, decision.why)
    return targets, why


#: Rolling evidence, the budget: per line and per targeted plan, the `ROLLED_WINDOWS` windows of four
#: programs (one 52h each: 1–4, 5–8, …, 61–64) whose values on record are the oldest (`rolling`) are read
#: besides what the change reads — 0.73 s of line time at 9600 baud on crc16, 0.06 s at 115200. What they
#: read is as new as the plan after it (`Known.read_at`), so the next plan rolls the next oldest: every
#: program the plant file declares on a line is read again within ⌈W / 8⌉ plans of the whole line, W the
#: windows of its modules that hold a managed program or one on record (at most 16 a module: 60 plans for
#: 30 fully managed modules, 6 for a line of 3), whatever `record_max_age`.
ROLLED_WINDOWS = 8


def with_rolling(targets: Sequence[Target], why: Mapping[Key, str],
                 known: Mapping[Key, Known]) -> tuple[list[Target], dict[Key, str]]:
    """A targeted plan's `targets` (`for_plan`) and why a module is read in full, with rolling evidence:
    the programs `rolling` picks read too, with the record to agree with (what they find is evidence like
    any other: `opens_line`); a module whose every program is read then is said to be read in full for it."""
    roll = rolling(targets, known)
    rolled = [replace(t, programs=tuple(sorted(set(t.programs) | set(roll[(t.bus, t.address)][0]))))
              if (t.bus, t.address) in roll else t
              for t in targets]
    return rolled, dict(why) | {(t.bus, t.address): roll[(t.bus, t.address)][1] for t in rolled
                                if (t.bus, t.address) in roll and set(t.managed) <= set(t.programs)}


def rolling(targets: Sequence[Target], known: Mapping[Key, Known]) -> dict[Key, tuple[tuple[int, ...], str]]:
    """The programs a targeted plan reads for rolling evidence, by module, with why: per line the
    `ROLLED_WINDOWS` windows of four programs (1–4, 5–8, …) whose oldest value on record (`Known.age`)
    is the oldest — ties by address, then window — of those holding a program the plant file manages or
    the record holds that the plan does not read anyway (a module not on record is read in full anyway)."""
    windows: dict[str, list[tuple[datetime, int, int, tuple[int, ...]]]] = {}
    for t in targets:
        record = known.get((t.bus, t.address))
        if t.known is None or record is None:
            continue
        left = (set(t.managed) | set(programs_in(record.image))) - set(t.programs)
        for first in range(1, len(PROGRAM_NUMBERS) + 1, codec.MAX_READ_PROGRAMS):
            numbers = tuple(n for n in range(first, first + codec.MAX_READ_PROGRAMS) if n in left)
            if numbers:
                windows.setdefault(t.bus, []).append((min(record.age(n) for n in numbers), t.address, first,
                                                      numbers))
    picked: dict[Key, list[tuple[datetime, tuple[int, ...]]]] = {}
    for bus, line in windows.items():
        for age, address, _, numbers in sorted(line)[:ROLLED_WINDOWS]:
            picked.setdefault((bus, address), []).append((age, numbers))
    return {key: (tuple(n for _, numbers in chosen for n in numbers),
                  f"rolling evidence: programs {number_runs([n for _, numbers in chosen for n in numbers])}, "
                  "the oldest on its line, "
                  f"since {to_the_minute(min(age for age, _ in chosen).isoformat())}")
            for key, chosen in picked.items()}


class PlanEntry(Placed, Protocol):
    """A module's entry of a plan file, as much of it as `for_plan_file` reads
    (`prc3cfg.core.plan_file.PlannedModule`, which imports this module: what is read decides what a plan file
    is proved against)."""

    @property
    def programs_read(self) -> tuple[int, ...] | None: ...


Entry = TypeVar("Entry", bound=PlanEntry)


def for_plan_file(entries: Sequence[Entry], desired: Mapping[Key, ModuleImage], known: Mapping[Key, Known],
                  max_age: Mapping[str, float], now: datetime) -> tuple[list[Target], Entry | None]:
    """What `apply --plan` reads for the modules of a plan made from a targeted read-back: exactly the
    programs its plan read, with the record as evidence — and the first module the record no longer shows
    holding what the plan took as known without reading it (None: none): the plan is stale then."""
    targets: list[Target] = []
    for e in entries:
        key = (e.bus, e.address)
        decision = to_read(known.get(key), desired[key], now, max_age[e.bus])
        if not set(decision.programs) <= set(e.programs_read or ()):
            return targets, e
        targets.append(Target(e.bus, e.address, e.name, e.programs_read or (), None, decision.known,
                              programs_in(desired[key])))
    return targets, None


# -- what a read widens to, on what it finds ------------------------------------------------------


def after_system(system: SystemParameters, programs: Iterable[int], clamped_by: SystemParameters | None,
                 known: ModuleImage | None, managed: Iterable[int], *, fresh: bool = False) -> frozenset[int]:
    """The programs to read once the 50h answered `system`: `programs` — every program, when writing
    `clamped_by` (the system parameters a plan will write) can clamp programs here; and every `managed`
    program too when `system` is not the record's (`known`): the module was changed by another hand.
    With `fresh` (an apply's), none of the `managed` ones on a factory-fresh module (`factory_fresh`)."""
    wanted = (set(PROGRAM_NUMBERS) if clamped_by is not None and can_clamp(system, clamped_by)
              else set(programs))
    if fresh and clamped_by is not None and factory_fresh(system, clamped_by, known):
        return frozenset(wanted - set(managed))
    if known is not None and system != known.system:
        wanted |= set(managed)
    return frozenset(wanted)


def factory_fresh(system: SystemParameters, wanted: SystemParameters, known: ModuleImage | None) -> bool:
    """Whether a module whose 50h answered `system` is commissioned from the factory: it holds the factory's
    system parameters, the plant file wants others (`wanted`: a 10h/20h will go out, and a verification after
    it), and the line's record (`known`) says nothing else — neither other system parameters nor a program
    other than the factory's."""
    if system != DEFAULT_SYSTEM or wanted == DEFAULT_SYSTEM:
        return False
    factory = default_program(DEFAULT_SYSTEM)
    return known is None or (known.system == DEFAULT_SYSTEM
                             and all(p is None or p == factory for p in known.programs))


def commissioning(targets: Iterable[Target]) -> list[Target]:
    """An apply's targets: a factory-fresh module's managed programs planned from the factory's, not read
    (`after_system`)."""
    return [replace(t, fresh=True) for t in targets]


def assumed(desired: ModuleImage, actual: ModuleImage) -> tuple[int, ...]:
    """The managed programs of `desired` an apply plans from the factory's, not read: those `actual` (the
    read-back) lacks where it holds the factory's system parameters and the plant file wants others —
    what `after_system` left unread there (or, on a line whose record it took them from, what the record
    showed: planned from the factory's all the same, and read back after the writes)."""
    if actual.system != DEFAULT_SYSTEM or desired.system == DEFAULT_SYSTEM:
        return ()
    return not_read(desired, actual)


def from_factory(actual: ModuleImage, programs: Iterable[int]) -> ModuleImage:
    """`actual` with `programs` holding the factory's: what the plan is made from where they were not read."""
    factory = default_program(DEFAULT_SYSTEM)
    return actual.with_programs({n: factory for n in programs})


def after_programs(read: ModuleImage, known: ModuleImage | None, managed: Iterable[int]) -> frozenset[int]:
    """The programs still to read once `read` holds what was read: where it contradicts the record
    (`known`), every `managed` program not read yet — nothing of the record is taken then; else none."""
    if known is None or contradiction(known, read) is None:
        return frozenset()
    return frozenset(managed) - set(programs_in(read))


def contradiction(known: ModuleImage, read: ModuleImage) -> str | None:
    """How a read-back contradicts the record of its module (None: it does not): the module was
    changed by something other than prc3cfg since, or is another module."""
    if read.system != known.system:
        return "its system parameters are not those on record"
    for number, (was, now) in enumerate(zip(known.programs, read.programs), start=1):
        if was is not None and now is not None and was != now:
            return f"program {number} is not as on record"
    return None


def opens_line(target: Target, read: ModuleImage) -> str | None:
    """Why the read-back of `target` opens its whole line ("bus/name: why"; None: it does not): it
    contradicts the record. Someone other than prc3cfg had their hands on that line — two controllers
    swapped hold each other's programs under system blocks that agree, so the other one's 50h proves
    nothing — and nothing of the record is taken for any module of it in that run (`opened`, `still_to_read`).
    """
    said = None if target.known is None else contradiction(target.known, read)
    return None if said is None else f"{target.bus}/{target.name}: {said}"


def opened(target: Target) -> Target:
    """`target` on a line opened before it is read: every managed program, with no record to agree with, none
    planned from the factory's."""
    return replace(target, programs=tuple(sorted(set(target.programs) | set(target.managed))), known=None,
                   fresh=False)


def still_to_read(target: Target, read: ModuleImage) -> frozenset[int]:
    """The managed programs of `target`, read as `read` before its line opened, that are still to read."""
    return frozenset(target.managed) - set(programs_in(read))


def read_in_full(modules: Iterable[Wanted], targets: Iterable[Target], images: Mapping[Key, ModuleImage],
                 why: Mapping[Key, str]) -> tuple[str, ...]:
    """"bus/name (why)" of each of `modules` a targeted read read in full: for what its read-back
    contradicted of the record, for `why` (before any evidence: not on record, too old, E12; or rolling
    evidence, `rolling`), or for the first module of its line (in the line's order) that contradicted it
    (`opens_line`)."""
    targets = list(targets)
    evidence = {(t.bus, t.address): said for t in targets if t.known is not None
                and (t.bus, t.address) in images
                and (said := contradiction(t.known, images[(t.bus, t.address)])) is not None}
    lines: dict[str, str] = {}
    for t in targets:
        if (t.bus, t.address) in evidence:
            lines.setdefault(t.bus, f"{t.bus}/{t.name} on its line: {evidence[(t.bus, t.address)]}")
    return tuple(f"{m.bus}/{m.name} ({said})" for m in modules
                 if (said := evidence.get(m.key) or why.get(m.key) or lines.get(m.bus)) is not None)


# -- what is read decides what is planned, and what the record becomes ------------------------------


def within_read(desired: ModuleImage, actual: ModuleImage) -> ModuleImage:
    """`desired` cut to the programs `actual` (a read-back) holds: the others are not the plan's."""
    return replace(desired, programs=tuple(None if a is None else d
                                           for d, a in zip(desired.programs, actual.programs)))


def not_read(desired: ModuleImage, actual: ModuleImage) -> tuple[int, ...]:
    """The programs `desired` manages that the read-back `actual` does not hold: taken as last verified."""
    return tuple(n for n, (d, a) in enumerate(zip(desired.programs, actual.programs), start=1)
                 if d is not None and a is None)


def with_known(image: ModuleImage, desired: ModuleImage) -> ModuleImage:
    """`image` (a read-back, or what a plan leaves of one) with the managed programs it did not read
    filled in with the plant file's values — what the line's record showed them holding, which is why
    they were not read (`to_read`): the values a picture of the module's chains must use, never a
    chain cut where a program was not read."""
    pairs = enumerate(zip(desired.programs, image.programs), start=1)
    return image.with_programs({n: d for n, (d, a) in pairs if d is not None and a is None})


def merged(known: Known | None, read: ModuleImage, when: str, by: str) -> Known:
    """The record of a module after `read` was read (or verified) `when` by `by`: what was read,
    with the values of the record it did not read again — unless it contradicts the record, which
    then goes whole. Its `since` stays the record's while any value of the record is kept."""
    return verified(None if known is None or contradiction(known.image, read) is not None else known, read,
                    when, by)


def verified(known: Known | None, held: ModuleImage, when: str, by: str) -> Known:
    """The record of a module prc3cfg wrote and verified `when`, by `by`, to hold `held` (what it read
    back, and what its steps wrote): that, with the values of the record it neither wrote nor read —
    what the writes changed is no contradiction. Its `since` is the oldest time of the values it keeps
    (`read_at`, else the record's `since`; none kept: `when`), and every program of `held` is as of `when`."""
    if known is None:
        return Known(held, when, by)
    programs = tuple(now if now is not None else was for was, now in zip(known.image.programs, held.programs))
    kept = {n: known.read_at.get(n, known.since)
            for n, (was, now) in enumerate(zip(known.image.programs, held.programs), start=1)
            if now is None and was is not None}
    if not kept:
        return Known(replace(held, programs=programs), when, by)
    since = min(kept.values(), key=datetime.fromisoformat)
    read_at = {n: at for n, at in kept.items() if at != since} | {n: when for n in programs_in(held)}
    return Known(replace(held, programs=programs), since, known.by, read_at)


# -- what a verification reads, and what it costs ---------------------------------------------------


def read_messages(programs: Iterable[int]) -> list[codec.Message]:
    """50h, then the fewest 51h/52h that read exactly the programs wanted (and between them): a greedy
    cover from the lowest unread program, which is the fewest exchanges for any set of programs; each
    read ends at the last wanted program of its window, so no byte is read for nothing at the end of a
    run. A fully managed module takes 1 + 16."""
    wanted = sorted(set(programs))
    messages: list[codec.Message] = [codec.ReadSystem()]
    i = 0
    while i < len(wanted):
        first = wanted[i]
        while i < len(wanted) and wanted[i] <= first + codec.MAX_READ_PROGRAMS - 1:
            i += 1
        last = wanted[i - 1]
        messages.append(codec.ReadProgram(first) if first == last else codec.ReadPrograms(first, last))
    return messages


def reach(before: ModuleImage, predicted: ModuleImage, steps: Sequence[Step]) -> tuple[bool, frozenset[int]]:
    """What `steps` (those that went out) could have changed on a module: whether the system
    parameters, and which programs — those they write, and, after a system step, those whose
    prediction differs from the read-back (the module's own clamping)."""
    system = any(step.releases_axes for step in steps)
    programs = {n for step in steps for n in step.message.touched_programs()}
    if system:
        programs |= {n for n, (b, p) in enumerate(zip(before.programs, predicted.programs), 1)
                     if b is not None and p != b}
    return system, frozenset(programs)


def verification_reads(first: ModuleImage, last: ModuleImage, predicted: ModuleImage, sent: Sequence[Step], *,
                       full: bool, watch_system: bool) -> tuple[bool, frozenset[int]]:
    """What a verifying read-back reads — whether the system block, and which programs: with `full`
    (`Verify.FULL`) the system and every program the first read-back (`first`) held; else what the steps
    `sent` since the module read as `last` could have changed (`reach`), and the system block where a
    release went out on a line without error detection (`watch_system`: a damaged frame can release any
    module's axes)."""
    if full:
        return True, frozenset(programs_in(first))
    system, programs = reach(last, predicted, sent)
    return system or watch_system, programs


def verification_time(before: ModuleImage, predicted: ModuleImage, steps: Sequence[Step], cost: LineCost,
                      unread: Iterable[int] = ()) -> float:
    """Seconds the fewest reads of what `steps` can change take on the line — and of the programs planned
    from the factory's, not read (`unread`: `assumed`), which the verification reads whatever the steps."""
    system, programs = reach(before, predicted, steps)
    return reading_time(before.address, programs | set(unread), system, cost)


def reading_time(address: int, programs: Iterable[int], system: bool, cost: LineCost) -> float:
    """Seconds the fewest reads of `programs` (and of the system block, with `system`) take on the line:
    summed with `math.fsum`, correctly rounded, so that every place that prices a read-back agrees to the bit.
    """
    reads = read_messages(programs)[0 if system else 1 :]
    return fsum(cost.message_time(address, m) for m in reads)
