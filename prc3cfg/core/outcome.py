"""A module's outcome of an apply (`ModuleOutcome`): what was sent to it, what it acknowledged, what it reads
back, how its course through the apply ended, why it failed and whether its axes were released.

One frozen value, built once when the module's run ends (`prc3cfg.shell.apply.ModuleRun.outcome`; the run's
working state stays in the shell while it is in progress), and taken as it is by everything that comes after:
the API's result, the account (`prc3cfg.core.render`), the journal and the JSON events
(`prc3cfg.core.events`). Its constructor says the two things the run's facts conclude, each once: `released`
(`prc3cfg.core.axes.released`) and `failure` (`said_failure`). Does not own how a module is written and
verified (`prc3cfg.shell.apply`) nor the words of the account. Pure.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import InitVar, dataclass, field

from prc3cfg.core import axes
from prc3cfg.core.apply_states import Course, Coursed, State
from prc3cfg.core.axes import Release
from prc3cfg.core.image import ModuleImage
from prc3cfg.core.planner import Step

#: How a module's `failure` begins when the lines were stopped — by Ctrl-C, SIGTERM, or (`ModuleOutcome`'s
#: `stopped`) another reason.
INTERRUPTED = "interrupted"


@dataclass(frozen=True, slots=True)
class ModuleOutcome(Coursed):
    """One module's part of an apply, once it ended. `problem` is the last thing that went wrong in the run's
    words; `stopped`, why the lines were stopped when not by a signal (a record that could not be kept)."""

    bus: str
    address: int
    name: str
    before: ModuleImage  # the read-back the steps were planned from
    desired: ModuleImage
    steps: tuple[Step, ...]
    broadcasts: int  # the first steps are the bus's broadcasts, sent once for all
    sent: tuple[Step, ...]  # put on the line, over all rounds
    written: tuple[Step, ...]  # acknowledged, over all rounds
    final: ModuleImage | None  # the last read-back (None: never read back)
    course: Course  # where the table left it: verified, failed or interrupted, after how many repairs
    #: on a line without error detection: a damaged frame meant for another module can reach this one as a
    #: 10h/20h
    exposed: bool = False
    possibly_written: bool = False  # it answered a read as a write is: it executed a damaged frame
    watched: bool = False  # its system block was read because a release went out on its unprotected line
    system_unset: bool = False  # it answered E12 (system parameters not set): the next plan writes them first
    fault: int | None = None  # it refused a write with another fault state's code (E09, E21, …)
    problem: InitVar[str | None] = None
    stopped: InitVar[str | None] = None
    failure: str | None = field(init=False)
    released: Release = field(init=False)

    def __post_init__(self, problem: str | None, stopped: str | None) -> None:
        changed = self.final is not None and self.final.system != self.before.system
        released = axes.released(acknowledged=any(step.releases_axes for step in self.written),
                                 sent=any(step.releases_axes for step in self.sent),
                                 possibly_written=self.possibly_written,
                                 exposed=self.exposed, read_back=self.final is not None, changed=changed)
        # a frozen value's own constructor: the one place it is set
        object.__setattr__(self, "released", released)
        object.__setattr__(self, "failure", said_failure(self.course.state, problem, stopped))

    @property
    def unchanged(self) -> bool:
        """Whether the last read-back shows the module as it was before the apply."""
        final = self.final
        return final is not None and final.system == self.before.system and all(
            have is None or have == was for have, was in zip(final.programs, self.before.programs)
        )

    @property
    def unacknowledged(self) -> tuple[Step, ...]:
        """Steps that went out but no reply acknowledged (their effect may be there: see `final`)."""
        written = {step.message for step in self.written}
        return tuple(dict.fromkeys(step for step in self.sent if step.message not in written))

    @property
    def unsent(self) -> tuple[Step, ...]:
        """Planned steps that never went out."""
        sent = {step.message for step in self.sent}
        return tuple(step for step in self.steps if step.message not in sent)


def said_failure(state: State, problem: str | None, stopped: str | None) -> str | None:
    """Why a module that ended in `state` is not verified: none where it is; else the run's last `problem` —
    which says "interrupted" where the lines were stopped, and "stopped (`stopped`)" there instead when they
    were stopped for that reason, not by a signal."""
    if state is State.VERIFIED:
        return None
    if (stopped is not None and state is State.INTERRUPTED and problem is not None
        and problem.startswith(INTERRUPTED)):
        return f"stopped ({stopped}){problem.removeprefix(INTERRUPTED)}"
    return problem


def to_travel(outcomes: Iterable[ModuleOutcome]) -> list[ModuleOutcome]:
    """The modules whose axes were — or may have been — released: they must travel to their reference
    point."""
    return [outcome for outcome in outcomes if outcome.released is not Release.NO]
