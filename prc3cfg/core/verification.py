"""What a verifying read-back must read, and what it costs: the fewest reads, and the reach of steps.

- `read_messages(programs)`: 50h, then the fewest 51h/52h that read exactly the programs
  wanted — a greedy cover from the lowest unread program, which is the fewest exchanges
  for any set of programs; each read ends at the last wanted program of its window, so no
  byte is read for nothing at the end of a run. A fully managed module takes 1 + 16.
- `reach(before, predicted, steps)`: what steps can have changed on a module — the system
  block if a system step is among them; the programs they write; after a system step, the
  programs the module's own clamping changes.
- `verification_time`: the bus time of reading that reach back (the floor of a verification).

Used by the read-back, by `apply`'s verification and by the planning of broadcasts, which
must pay for reading back every module a broadcast reaches. `Release`: what the verification
concludes of a module's axes. Pure.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Sequence
from math import fsum

from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.image import ModuleImage
from prc3cfg.core.planner import Step


class Release(enum.Enum):
    """Whether a module's axes were released (10h/20h) and it must travel to its reference point."""

    NO = "no"
    YES = "yes"
    POSSIBLY = "possibly"  # a 10h/20h went out unacknowledged, and no read-back settles it


def read_messages(programs: Iterable[int]) -> list[codec.Message]:
    """50h, then the fewest 51h/52h that read exactly the programs wanted (and between them)."""
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
        programs |= {n for n, (b, p) in enumerate(zip(before.programs, predicted.programs), 1) if b is not None and p != b}
    return system, frozenset(programs)


def verification_time(before: ModuleImage, predicted: ModuleImage, steps: Sequence[Step], cost: LineCost) -> float:
    """Seconds the fewest reads of what `steps` can change take on the line."""
    system, programs = reach(before, predicted, steps)
    reads = read_messages(programs)[0 if system else 1 :]
    return fsum(cost.message_time(before.address, m) for m in reads)
