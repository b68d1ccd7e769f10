"""Running plans on the modules: steps in order, verification, repair, an exact account.

Owns execution: per module the steps in order, buses in parallel (a thread per line), the
modules of one line one after another. Afterwards every module is read back — always,
also after a refusal — and compared with what the steps should have left; what the account
says about a module comes from that read-back, not from the replies (on `open-driver` a
reply carries no checksum). A difference (a lost or damaged exchange, a module changed on
the floor meanwhile) is planned and repaired, at most `REPAIRS` times. Success means verified.

Verification reads exactly what the steps that went out could have changed
(`prc3cfg.core.what_to_read.verification_reads`): the system block if a system step went out, the programs the
steps write and the programs the module's own clamping changes — and the programs its plan took as the
factory's without reading them (`ModuleRun.assumed`: a factory-fresh module, `what_to_read.factory_fresh`) —
in the fewest 50h/51h/52h exchanges; a repair round reads what it repairs. `Verify.FULL` reads the system and
every program known from the first read-back instead, for the paranoid. A difference counts only when two
reads agree on it.

What may have reached a module counts, not only what it acknowledged: a 10h/20h whose
acknowledgement was lost released the axes all the same. Each module's outcome
(`ModuleRun.outcome`, a frozen `prc3cfg.core.outcome.ModuleOutcome`) says whether its axes were
released — certainly (acknowledged, or the read-back shows other system parameters than before),
possibly (a 10h/20h went out and no reply or read-back settles it), or not.

An error code stops that module for good (the link confirms codes on lines without a
checksum) — naming the step, the code, its meaning and what to do — while the other
modules go on. A module that stops answering (every retry lost) is not given up at once:
every PRC 3 message is idempotent, so it is read back and whatever still differs is sent
again. Ctrl-C (`prc3cfg.shell.cancel`) stops every module after the exchange in flight, and
its `failure` says where in words: before which step, broadcast or repair step, or while
verifying (how many of its steps were acknowledged).

What a module does next — its next step, a read-back, a repair, giving up — is the table's
(`prc3cfg.core.apply_states`): `ModuleRun` sends, reads and plans as it says, tells it what
happened, and keeps the account. Gating, snapshots and locks are the caller's.
"""

from __future__ import annotations

import contextlib
import enum
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace

from prc3cfg.core.apply_states import REPAIRS, Course, Coursed, Event, Next, State, repair_event, reply_event
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.error_codes import FAULT_STATES, describe, remedy
from prc3cfg.core.image import ModuleImage, Program
from prc3cfg.core.late_frames import settle_time, undone_by_late
from prc3cfg.core.outcome import INTERRUPTED, ModuleOutcome
from prc3cfg.core.planner import ModulePlan, Step, plan_module
from prc3cfg.core.render import plural
from prc3cfg.core.what_to_read import programs_in, verification_reads
from prc3cfg.errors import Interrupted, NotSent, UserError
from prc3cfg.shell import platform
from prc3cfg.shell.cancel import main_thread_only
from prc3cfg.shell.link.client import Link, LinkError, PossibleWrite
from prc3cfg.shell.readback import read_programs, read_system

#: Reads to confirm a difference: on a line without a checksum a damaged reply looks like
#: one, so a difference counts only when two reads in a row agree on it.
CONFIRMING_READS = 4


class Verify(enum.Enum):
    """How much the verifying read-back reads."""

    FLOOR = "floor"  # what the steps could have changed
    FULL = "full"  # the system and every program known from the first read-back


@dataclass(slots=True)
class ModuleRun(Coursed):
    """One module's part of an apply, and what happened to it."""

    bus: str
    address: int
    name: str
    before: ModuleImage  # the read-back the steps were planned from
    desired: ModuleImage
    steps: tuple[Step, ...]
    predicted: ModuleImage  # what the steps leave, by the device model
    broadcasts: int = 0  # the first steps are the bus's broadcasts: the bus sends them, once for all
    #: on a line without error detection (open-driver, no parity): a damaged frame meant for another
    #: module — or a read — can reach this one as a 10h/20h
    exposed: bool = False
    #: the managed programs its plan took as the factory's, not read (`what_to_read.assumed`): its first
    #: verification reads them whatever the steps wrote, so one another tool changed goes through the repair
    #: round
    assumed: frozenset[int] = frozenset()
    sent: list[Step] = field(default_factory=list)  # put on the line, over all rounds
    written: list[Step] = field(default_factory=list)  # acknowledged, over all rounds
    # it answered a read as a write is: it executed a damaged frame (`PossibleWrite`)
    possibly_written: bool = False
    watched: bool = False  # its system block was read because a release went out on its unprotected line
    system_unset: bool = False  # it answered E12 (system parameters not set): the next plan writes them first
    # it refused a write with another fault state's code (E09, E21, …: `FAULT_STATES`): kept, told
    fault: int | None = None
    final: ModuleImage | None = None  # the first read-back, updated by every verifying read since
    # time.monotonic() when its last round of steps ended: a late frame lands within the quiet period since
    wrote_at: float = 0.0
    problem: str | None = None  # the last thing that went wrong, in words: the outcome's `failure` says it
    course: Course = field(default_factory=Course)  # where the table has it, and what it does next

    @property
    def where(self) -> str:
        return f"bus {self.bus}, module {self.address} ({self.name})"

    def process(self, event: Event) -> None:
        """What happened to the module, told to the table (`prc3cfg.core.apply_states`)."""
        self.course = self.course.after(event)

    @property
    def release_sent(self) -> bool:
        """Whether a 10h/20h went out on the line (a broadcast one counts)."""
        return any(step.releases_axes for step in self.sent)

    def outcome(self, stopped: str | None = None) -> ModuleOutcome:
        """What its run came to, once it ended: the frozen value everything after the apply takes (`stopped`:
        why the lines were stopped, when not by a signal)."""
        return ModuleOutcome(self.bus, self.address, self.name, self.before, self.desired, self.steps,
                             self.broadcasts, tuple(self.sent),
                       tuple(self.written), self.final, self.course, self.exposed, self.possibly_written,
                             self.watched,
                       self.system_unset, self.fault, self.problem, stopped)

    def trespassed(self) -> str | None:
        """A program the plant does not manage that the last read-back shows other than the module's
        own clamping leaves it (a damaged frame on a line without a checksum can do that)."""
        assert self.final is not None
        for number, (have, want, kept) in enumerate(zip(self.final.programs, self.desired.programs,
                                                        self.predicted.programs), 1):
            if want is None and have is not None and have != kept:
                return (f"program {number}, which the plant file does not manage, reads back other than "
                        "before the apply (and than the module's clamping leaves it) — check the line and "
                        "restore it from the snapshot")
        return None

    def stopped_verifying(self) -> None:
        """Ctrl-C during the verifying read-back: `problem` says what was acknowledged, and that it
        was not verified (and what went wrong before, if anything did); the table is told by the caller."""
        written, sent = {step.message for step in self.written}, {step.message for step in self.sent}
        own = self.steps[self.broadcasts :]
        said = (f"{INTERRUPTED} while verifying: {sum(s.message in written for s in own)} of "
                f"{plural(len(own), 'step')} acknowledged")
        if self.broadcasts:
            broadcast = sum(s.message in sent for s in self.steps[: self.broadcasts])
            said += f", {plural(broadcast, 'broadcast')} sent"
        if self.repairs:
            said += f", after {plural(self.repairs, 'repair round')}"
        self.problem = f"{said}, not verified" + (f" (before that: {self.problem})" if self.problem else "")

    def run(self, link: Link, steps: Sequence[Step], tick: Callable[[], None]) -> None:
        """Send steps in order — the plan's own, or a repair's (the state says which) — while the
        table says to send the next (`problem` says why it stopped, naming the step)."""
        what = "repair step" if self.course.state is State.REPAIRING else "step"
        try:
            for index, step in enumerate(steps, start=1):
                self.process(self._send(link, step, f"{what} {index} of {len(steps)} ({step.summary})"))
                if self.course.action is not Next.SEND:
                    return
                tick()
            self.process(Event.ALL_SENT)
        finally:
            self.wrote_at = time.monotonic()

    def _send(self, link: Link, step: Step, where: str) -> Event:
        """One step on the line, and what came of it (`problem` says what went wrong)."""
        try:
            if link.cancel is not None and link.cancel.is_set():
                raise Interrupted()
            self.sent.append(step)  # from here on it may have reached the module
            reply = link.request(self.address, step.message)
        except Interrupted as stop:  # before this step, or between its attempts (then it counts as sent)
            if isinstance(stop, NotSent):  # its frame never left
                self.sent.pop()
            self.problem = f"{INTERRUPTED} before {where}"
            return Event.CANCELLED
        except LinkError as error:
            self.problem = f"{where}: {error}"
            return Event.NO_REPLY
        assert isinstance(reply, int)  # a write is answered with a code word only (decode_reply sees to it)
        event = reply_event(reply, after_broadcast=self.broadcasts > 0)
        if event is Event.ACKNOWLEDGED:
            self.written.append(step)
        elif event is Event.E12:
            self.system_unset = True
            self.problem = (f"{where} was refused: the module is in E12 (system parameters not set), which "
                            "only a 10h/20h "
                            "clears — plan again: the new plan writes its system parameters first (20h, "
                            "releasing its axes)")
        elif event is Event.RUNNING:
            self.problem = (f"running: {where} was refused with {describe(reply)} — stop it (STOP and "
                            "AUTOMATIC) and apply again")
        else:
            self.fault = reply if reply in FAULT_STATES else self.fault
            self.problem = f"{where} was refused with {describe(reply)} — {remedy(reply)}"
        return event

    def verify_read(self, link: Link, system: bool, programs: frozenset[int],
                    expected: ModuleImage) -> ModuleImage:
        """`known` with what the module holds now in `system`/`programs`: as soon as a read shows
        what is `expected` there, else once two reads in a row agree."""
        known = self.final or self.before

        def once() -> ModuleImage:
            read = (read_system(link, self.address, name=self.name, expected=expected.system) if system
                    else known.system)
            told = {n: p for n in programs if (p := expected.programs[n - 1]) is not None}
            found: dict[int, Program] = dict(read_programs(link, self.address, programs, name=self.name,
                                                           expected=told))
            return replace(known, system=read).with_programs(found)

        previous = once()
        for _ in range(CONFIRMING_READS):
            if _agree(previous, expected, system, programs):
                break
            current = once()
            if _agree(current, previous, system, programs):
                break
            previous = current
        return previous

    def converge(self, link: Link, cost: LineCost, tick: Callable[[], None],
                 consented: frozenset[tuple[str, int]],
                 verify: Verify = Verify.FLOOR, with_system: bool = False) -> None:
        """Read back what the steps could have changed; while the module differs from the desired
        image and may be repaired, plan, repair, and read back what the repair could have changed.

        A refused module is read back, for the account, and not repaired. A repair that would
        release the axes (10h/20h) is sent only to a module in `consented` — the modules whose
        release the operator agreed to with the plan shown; any other needs a plan of its own.
        """
        expected, sent_before, repair = self.predicted, 0, None
        known_programs = frozenset(programs_in(self.before))
        while True:
            action = self.course.action
            if action is Next.READ:
                # a late copy that could undo a step: wait for it, and read what every step sent
                # could have changed
                late = undone_by_late(expected, self.sent[sent_before:])
                quiet = 0.0
                if late:
                    waits = (link.wait(self.address, step.message) for step in self.sent)
                    quiet = self.wrote_at + settle_time(cost, max(waits))
                basis = self.before if late else self.final or self.before
                system, programs = verification_reads(self.before, basis, expected,
                                                      self.sent if late else self.sent[sent_before:],
                                                      full=verify is Verify.FULL,
                                                      watch_system=with_system)
                # not read yet: never taken as planned
                programs |= self.assumed if self.final is None else frozenset()
                self.watched |= with_system
                self.process(self._verify(link, system, programs, expected, known_programs, quiet))
            elif action is Next.PLAN_REPAIR:
                assert self.final is not None  # a difference was read
                repair = plan_module(self.final, self.desired, cost)
                self.process(self._consent(repair, consented))
            elif action is Next.SEND:
                assert repair is not None  # the table sends a repair once planned
                expected, sent_before = repair.predicted, len(self.sent)
                self.run(link, repair.steps, tick)
            else:
                if action is Next.GIVE_UP:
                    self.problem = self._gave_up()
                return

    def _verify(self, link: Link, system: bool, programs: frozenset[int], expected: ModuleImage,
                known_programs: frozenset[int],
                quiet: float = 0.0) -> Event:
        """One verifying read-back, once the line is quiet (`quiet`: time.monotonic()), and what it found
        (`problem` says what went wrong)."""
        try:
            _wait_until(link, quiet)
            self.final = self.verify_read(link, system, programs, expected)
        except Interrupted:
            self.stopped_verifying()
            return Event.CANCELLED
        except PossibleWrite:
            raise  # the line stops: `execute` says so for every module on it
        except LinkError as error:
            self.problem = f"verification: {error}"
            return Event.NO_REPLY
        except UserError as error:
            self.problem = f"verification: {error}"
            return Event.READ_REFUSED
        if not _agree(self.final, self.desired, True, known_programs):
            return Event.DIFFERS
        if trespass := self.trespassed():
            self.problem = trespass
            return Event.TRESPASSED
        return Event.AGREES

    def _consent(self, repair: ModulePlan, consented: frozenset[tuple[str, int]]) -> Event:
        """Whether the repair may go (`problem` says why not)."""
        event = repair_event(repair.releases_axes, (self.bus, self.address) in consented)
        if event is Event.REPAIR_UNCONSENTED:
            self.problem = (
                "the read-back shows other system parameters than the plan expected (changed on the floor "
                "meanwhile" + (", or by a damaged frame meant for another module" if self.exposed else "")
                            + "?); writing "
                "them would release the axes, which the plan agreed to did not — nothing more was sent to "
                "it: plan "
                "again and review the new plan"
            )
        return event

    def _gave_up(self) -> str:
        """Why a module that had every round is not verified."""
        if self.final is None:
            return (f"could not be read back to verify it ({self.problem}) — check the line and the module, "
                    "then apply again")
        return (
            f"still differs from the plant file after {REPAIRS} repairs"
            + (f" (last problem: {self.problem})" if self.problem else "")
            + " — check the line (damaged frames?) and the module, then apply again"
        )


def _wait_until(link: Link, when: float) -> None:
    """Until time.monotonic() is `when`; `Interrupted` as soon as the link's `cancel` event is set."""
    if (left := when - time.monotonic()) > 0:
        if link.cancel is None:
            time.sleep(left)
        elif link.cancel.wait(left):
            raise Interrupted()


def _agree(image: ModuleImage, other: ModuleImage, system: bool, programs: frozenset[int]) -> bool:
    """Whether two images agree on the system parameters (if `system`) and on `programs`
    (where `other` has a value: `None` in a desired image is a program the plant leaves alone)."""
    return (not system or image.system == other.system) and all(
        other.programs[n - 1] is None or image.programs[n - 1] == other.programs[n - 1] for n in programs
    )


def broadcast(link: Link, turnaround: float, runs: list[ModuleRun], tick: Callable[[], None]) -> None:
    """The bus's broadcasts, once each; every receiver counts them as sent (none answers: the
    verifying read-back tells whether they arrived, and addressed repairs follow where not)."""
    steps = next((run.steps[: run.broadcasts] for run in runs if run.broadcasts), ())
    receivers = [run for run in runs if run.broadcasts]
    for index, step in enumerate(steps, start=1):
        try:
            link.broadcast(step.message, turnaround)
        except Interrupted:
            for run in receivers:
                run.problem = f"{INTERRUPTED} before broadcast {index} of {len(steps)} ({step.summary})"
                run.process(Event.CANCELLED)
            return
        except LinkError as error:
            for run in receivers:
                run.problem = f"broadcast {index} of {len(steps)} ({step.summary}): {error}"
            return
        for run in receivers:
            run.sent.append(step)  # it may have reached every module: they count it as sent
        tick()


def stopped(link: Link, runs: list[ModuleRun], error: PossibleWrite) -> None:
    """A module of the line executed a damaged frame as a write: nothing more is sent on the line.
    That module's system block is read once more for the account; every module not verified yet
    says why it was left."""
    for run in runs:
        if run.address == error.address:
            run.possibly_written = True
            with contextlib.suppress(LinkError, UserError):  # not read back: `released` says "possibly"
                run.final = replace(run.final or run.before,
                                    system=read_system(link, run.address, name=run.name))
        if not run.verified:
            run.problem = str(error)
            run.process(Event.LINE_STOPPED)


def execute(
    runs: list[ModuleRun],
    links: dict[str, Link],
    costs: dict[str, LineCost],
    *,
    tick: Callable[[], None] = lambda: None,
    written: Callable[[], None] = lambda: None,
    verified: Callable[[], None] = lambda: None,
    consented: frozenset[tuple[str, int]] = frozenset(),
    verify: Verify = Verify.FLOOR,
) -> None:
    """Run every module's steps, then verify and repair; results are left in `runs`.

    `tick` is called at each write acknowledged, `written` when a line's writes ended, `verified`
    when a module's verification ended (`prc3cfg.shell.phases`).

    `consented`: the (bus, address) of every module whose axes the operator agreed to release —
    a repair may send a 10h/20h to those only.

    Buses run in parallel; on one bus, all modules are written first, then verified (so a
    module's verification also sees what a damaged frame for another did to it).
    """
    per_bus: dict[str, list[ModuleRun]] = {}
    for run in runs:
        per_bus.setdefault(run.bus, []).append(run)

    def on_bus(bus: str, bus_runs: list[ModuleRun]) -> None:
        link = links[bus]
        try:
            try:
                broadcast(link, costs[bus].turnaround, bus_runs, tick)
                for run in bus_runs:
                    if not run.interrupted:
                        run.run(link, run.steps[run.broadcasts :], tick)
            finally:
                written()
            # where a damaged frame can become a release of any module, every module's system block is read
            with_system = any(run.exposed for run in bus_runs) and any(run.release_sent for run in bus_runs)
            for run in bus_runs:
                if not run.interrupted:
                    run.converge(link, costs[bus], tick, consented, verify, with_system)
                verified()
        except PossibleWrite as error:
            stopped(link, bus_runs, error)

    with ThreadPoolExecutor(max_workers=max(1, len(per_bus)), initializer=main_thread_only) as pool:
        for future in [pool.submit(on_bus, bus, bus_runs) for bus, bus_runs in per_bus.items()]:
            platform.result_of(future)
