"""The API's values: what its functions take and give back, and the errors they raise.

`Gates` (what an apply asks before it writes), `ApplyResult` (what an apply did), `Pairs` (the
modules chosen) and the errors an apply raises. Owns no workflow: the functions that fill these
are in the other modules of `prc3cfg.api`. `LineOptions` (how a command uses its lines) and
`Progress` are the line sessions' (`prc3cfg.shell.sessions`, `prc3cfg.shell.phases`), which take them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from prc3cfg.core.outcome import ModuleOutcome, to_travel
from prc3cfg.core.plant_plan import PlantPlan
from prc3cfg.core.render import plural
from prc3cfg.errors import Interrupted, UserError
from prc3cfg.plant import Bus, Module
from prc3cfg.shell import pending_records
from prc3cfg.shell.platform import command_line

#: (bus, module) pairs of a plant, as `select` gives them
Pairs = list[tuple[Bus, Module]]


class AxisReleaseRefused(UserError):
    """The plan releases axes and `allow_axis_release` was not given: nothing was written."""


class NotApproved(UserError):
    """`approve` said no: nothing was written."""


class ApplyFailed(UserError):
    """Some module did not verify; `result` has the account of every module."""

    def __init__(self, result: ApplyResult) -> None:
        failed = [r for r in result.runs if not r.verified]
        said = [*result.unread]  # lines not written: what stopped their read-back or plan, one line each
        restore = command_line("prc3cfg", "restore", str(result.snapshot))
        if failed or not said:
            said.append(f"apply failed on {len(failed)} of {plural(len(result.runs), 'module')} (see above) "
                        f"— restore with: {restore}")
        else:
            written = len(result.runs)
            said[-1] += (f"; the {plural(written, 'module')} of the other lines "
                         f"{'was' if written == 1 else 'were'} written and "
                         f"verified (see above) — restore {'it' if written == 1 else 'them'} with: {restore}")
        super().__init__("\n".join(said))
        self.result = result


class RecordsFailed(ApplyFailed):
    """A record the apply keeps — its journal, the record of an axis release, its snapshot, a line's
    record, the copy of the plant file applied in full — could not be written (a full disk): every
    line stopped before its next frame; `result` says what each module was sent and holds. The one
    line says which record (`trouble`: its file and the OS error), that the records on disk are
    incomplete (`lost`: each record not kept) and how to go on."""

    def __init__(self, result: ApplyResult, trouble: str, lost: tuple[str, ...] = ()) -> None:
        super().__init__(result)
        incomplete = f"the records on disk are incomplete ({_listed(lost)} not kept)"
        if not any(run.sent for run in result.runs) and not result.verified:
            said = "nothing was written to any module — free the space (or fix the folder), then apply again"
        elif result.verified:
            said = (f"every module was written and verified (see above), but {incomplete} — free the space "
                    "(or fix the folder)")
        else:
            then = ("plan and apply again"
                    + (f", or restore: {command_line('prc3cfg', 'restore', str(result.snapshot))}"
                       if result.snapshot else ""))
            said = ("every line stopped before its next frame — the account above says what each module "
                    "was sent and holds; "
                    f"{incomplete}; free the space (or fix the folder), then {then}")
        self.args = (f"{trouble}: {said}",)


def _listed(names: tuple[str, ...]) -> str:
    """"a", "a and b", "a, b and c"."""
    return " and ".join([", ".join(names[:-1]), names[-1]] if len(names) > 1 else list(names))


class ApplyInterrupted(Interrupted):
    """Ctrl-C or SIGTERM stopped the apply after the exchange in flight; `result` has the account."""

    def __init__(self, result: ApplyResult) -> None:
        super().__init__()
        self.result = result


@dataclass(frozen=True)
class ApplyResult:
    """What an apply did: the plan it ran, every module's outcome, the snapshot and journal it left."""

    plan: PlantPlan
    runs: tuple[ModuleOutcome, ...]
    snapshot: Path | None
    journal: Path
    #: axis releases earlier applies on these lines left untold (killed after a 10h/20h): this
    #: apply's account lists them too
    earlier: tuple[pending_records.Pending, ...] = ()
    #: the file of this apply's records of axis releases, not yet told (None: it made none) —
    #: `prc3cfg.api.told`
    records: Path | None = None
    #: seconds each phase took — reading back (and planning), writing, verifying — beside the plan's estimate
    took: dict[str, float] = field(default_factory=dict)
    #: lines written as soon as their own plan was whole, while another's read-back or plan failed (or
    #: Ctrl-C stopped it): what stopped that one, one line each, saying nothing was written there
    unread: tuple[str, ...] = ()
    #: every line it talked on answers at once (the embedded emulator without a line-speed): the time it
    #: took says nothing of a line's
    at_once: bool = False

    @property
    def verified(self) -> bool:
        return not self.unread and all(run.verified for run in self.runs)

    @property
    def released(self) -> tuple[ModuleOutcome, ...]:
        """Every module whose axes were — or may have been — released: it must travel to its reference
        point."""
        return tuple(to_travel(self.runs))


@dataclass(frozen=True)
class Gates:
    """What an apply asks before it writes, in this order, each seeing the plan:

    - `show(plan)`: the plan is ready (to print it);
    - `allow_axis_release`: True, False, or a question — called with the modules whose axes
      the plan releases, True to allow — else `AxisReleaseRefused`; the answer also decides
      whether a repair may release axes;
    - `approve(plan)`: False stops with `NotApproved`.

    Without a question (`asks`) each line is written as soon as its own plan is whole, while the
    other lines are still read — `show_line` sees that line's plan before its first write — and
    `show` sees the plant's plan once it is whole, writes going on. Every gate is called from the
    thread that called `apply` (or `restore`), between the stages: never from a line's thread.
    """

    show: Callable[[PlantPlan], None] | None = None
    allow_axis_release: bool | Callable[[list[str]], bool] = False
    approve: Callable[[PlantPlan], bool] | None = None
    #: without a question: each line's own plan, before that line's first write (the line waits for it)
    show_line: Callable[[PlantPlan], None] | None = None

    @property
    def asks(self) -> bool:
        """Whether a question may stand between the plan and the writes — a confirmation, or an axis
        release not allowed up front — so that a person reviews the plan of the whole plant first."""
        return self.approve is not None or self.allow_axis_release is not True
