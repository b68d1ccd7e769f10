"""When a verification reads: after every frame still on its way has landed.

A verification waits first (`settle_time`) where a copy of a step that went out, arriving late — held
by a gateway past its time-out and retried, or delivered twice — would undo what a later step did
(`undone_by_late`: a 10h–14h initialisation before the writes that follow it, a broadcast that an
addressed step overrides): every frame still on its way lands before the read-back, which then reads
what every step sent to the module could have changed (`prc3cfg.core.what_to_read.verification_reads`).
A copy of any other step, arriving whenever, leaves what the plan left: no wait.

Owns the bound on a held frame and the quiet period; `prc3cfg.shell.apply` waits it. Pure.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from prc3cfg.core import codec, device
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.image import ModuleImage, default_program
from prc3cfg.core.planner import Step

#: A frame reaches its module within this many reply deadlines of leaving, or never: the bound prc3cfg
#: takes for a frame a gateway, a radio link or a proxy holds (TCP retransmitting a lost segment once,
#: Linux's 200 ms at the least, stays within it at a deadline of 0.2 s and more). A link that holds frames
#: longer needs a longer `timeout` on its bus.
HELD_DEADLINES = 2


def undone_by_late(final: ModuleImage, steps: Sequence[Step]) -> bool:
    """Whether a copy of one of `steps`, executed once more after all of them (a late or duplicated
    frame), would leave the module other than `final` (what they leave, by the device model): a 10h–14h
    before the writes that follow it, or a broadcast an addressed step overrides. A copy landing between
    the steps is seen by the read-back that follows them all; only one landing after it does harm."""
    filler = default_program(final.system)
    state = device.ModuleState(replace(final, programs=tuple(filler if p is None else p
                                                             for p in final.programs)))
    for step in steps:
        try:
            again = device.execute(state, step.message)
        except codec.Rejected:  # refused: a copy changes nothing
            continue
        if again.image != state.image:
            return True
    return False


def settle_time(cost: LineCost, deadline: float) -> float:
    """Seconds after a line's last write until every frame still on its way has landed: `HELD_DEADLINES` reply
    deadlines (`deadline`: the longest wait for a reply to the steps sent — the line's time and the bus's
    `timeout` — as the link waits it), the longest request frame's transmission, the modules' turnaround (and
    on open-driver the gap that ends a frame)."""
    framing = cost.framing
    longest = framing.frame_length(codec.MAX_MESSAGE_BYTES) * (2 if framing.stuffs else 1)
    gap = cost.zvz if framing.name == "open-driver" else 0.0
    return HELD_DEADLINES * deadline + cost.line.transmission_time(longest) + cost.turnaround + gap
