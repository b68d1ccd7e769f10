"""The proof every plan passes before anything is sent: its steps, run on the device model.

`run_steps(actual, desired, messages)` runs one module's steps on `prc3cfg.core.device` from
its read-back and returns the predicted image, or raises `StepProblem` naming the first
step that breaks a rule:

1. a plan holds writes only (10h..46h), at most `MAX_STEPS` of them;
2. no step writes a program the desired image does not manage (`None` there);
3. at most one step releases the axes (10h, 20h), and only when the read-back's system
   parameters differ from the desired ones — never an axis release for nothing — or, first, for a
   module in E12 (`system_unset`), which takes no other write until one has cleared it;
4. the module accepts every step (the checks of §4.5, in the state the earlier steps leave);
5. afterwards the system parameters and every managed program are the desired ones.

The planner runs its own plans through this (a failure there is a planner bug), and
`apply --plan` runs a plan file's steps through it from the fresh read-back, so a plan file
edited to do anything else is refused before the first write. Programs that were not read
are filled with defaults to run the model; rule 2 keeps them untouched, and the read-back
reads every program a system step could clamp (`prc3cfg.core.what_to_read.after_system`). The predicted image
has every program that was read — an unmanaged one as the module's own clamping leaves
it — and `None` for the others. Pure.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from prc3cfg.core import codec, device
from prc3cfg.core.error_codes import describe
from prc3cfg.core.image import ModuleImage, default_program
from prc3cfg.core.planner.module_plan import program_list

#: More steps than any plan of one module needs (a full download is at most 65 messages).
MAX_STEPS = 128


class _StepName:
    """"step 3 (2100…)", as a message names it — encoded only when a problem is said."""

    def __init__(self, index: int, message: codec.Message) -> None:
        self.index, self.message = index, message

    def __str__(self) -> str:
        return f"step {self.index} ({self.message.hex()})"


class StepProblem(ValueError):
    """Step `index` (1-based; 0: the steps as a whole) breaks a rule; `str()` says which."""

    def __init__(self, index: int, text: str) -> None:
        super().__init__(text)
        self.index = index


def run_steps(actual: ModuleImage, desired: ModuleImage, messages: Sequence[codec.Message], *,
              system_unset: bool = False) -> ModuleImage:
    """The image the steps leave on the module (programs read or managed), or `StepProblem`.
    `system_unset`: the module is in E12, which only a 10h/20h clears — one may go for it, first.
    The rules are checked in the order the module docstring numbers them, each refusal with its own words."""
    if len(messages) > MAX_STEPS:
        raise StepProblem(MAX_STEPS + 1,
                          f"{len(messages)} steps for one module, more than any plan needs ({MAX_STEPS})")
    filler = default_program(actual.system)
    state = device.ModuleState(replace(actual, programs=tuple(filler if p is None else p
                                                              for p in actual.programs)))
    unmanaged = {n for n, p in enumerate(desired.programs, start=1) if p is None}
    releases = 0
    for index, message in enumerate(messages, start=1):
        step = _StepName(index, message)
        _check_write(step, unmanaged)
        if message.RELEASES_AXES:
            releases += 1
            _check_release(step, releases, matching=actual.system == desired.system
                           and not (system_unset and index == 1))
        try:
            state = device.execute(state, message)
        except codec.Rejected as rejected:
            raise StepProblem(index, f"{step} would be refused by the module with "
                                     f"{describe(rejected.code)}") from None
    image = state.image
    _check_reached(image, desired)
    known = tuple(p if (a is not None or w is not None) else None
                  for p, a, w in zip(image.programs, actual.programs, desired.programs))
    return replace(image, programs=known)


def _check_write(step: _StepName, unmanaged: set[int]) -> None:
    """A step is a write, of managed programs only."""
    message = step.message
    if message.IS_READ:
        raise StepProblem(step.index, f"{step} is a read ({message.ID:02X}h), not a write")
    trespass = unmanaged.intersection(message.touched_programs())
    if trespass:
        which = (f"program {program_list(trespass)}" if len(trespass) == 1
                 else f"programs {program_list(trespass)}")
        raise StepProblem(step.index, f"{step} writes {which}, which the plant file does not manage")


def _check_release(step: _StepName, releases: int, matching: bool) -> None:
    """A step that releases the axes (the `releases`-th) is the only one, and goes only where the system
    parameters differ from the plant file's (`matching`: they do not, and no E12 asks for it)."""
    if matching:
        raise StepProblem(step.index,
                          f"{step} releases the axes, but the system parameters already match the plant file")
    if releases > 1:
        raise StepProblem(step.index, f"{step} releases the axes a second time")


def _check_reached(image: ModuleImage, desired: ModuleImage) -> None:
    """After the steps, the system parameters and every managed program are the plant file's."""
    if image.system != desired.system:
        raise StepProblem(0, "after the steps the system parameters differ from the plant file's")
    wrong = [n for n, (have, want) in enumerate(zip(image.programs, desired.programs), 1)
             if want is not None and have != want]
    if wrong:
        which = f"program {wrong[0]} differs" if len(wrong) == 1 else f"programs {program_list(wrong)} differ"
        raise StepProblem(0, f"after the steps {which} from the plant file")
