"""What an apply concludes of a module's axes: released, not, or possibly (`Release`).

A 10h/20h releases the axes, and a module whose axes were released must travel to its reference
point before it runs again. Which of the three a module's run is, `released` decides from what went
out, what was acknowledged and what the verifying read-back shows — once, as the module's outcome is
built (`prc3cfg.core.outcome.ModuleOutcome`, which names those facts); the account says it
(`prc3cfg.core.render`), and the journal and the API's result name every module not `NO`
(`prc3cfg.core.outcome.to_travel`). Pure.
"""

from __future__ import annotations

import enum


class Release(enum.Enum):
    """Whether a module's axes were released (10h/20h) and it must travel to its reference point."""

    NO = "no"
    YES = "yes"
    POSSIBLY = "possibly"  # a 10h/20h went out unacknowledged, and no read-back settles it


def released(*, acknowledged: bool, sent: bool, possibly_written: bool, exposed: bool, read_back: bool,
             changed: bool) -> Release:
    """Whether a module's axes were released, by the first of these that holds:

    1. a 10h/20h to it was acknowledged (`acknowledged`): YES;
    2. a read to it was answered as a write (`possibly_written`), or its line detects no damage (`exposed`)
       and its system block reads back changed: a damaged frame executed as a write — YES where the block
       changed (a 10h leaves a module at defaults as it was, so an unchanged block is no proof): else
       POSSIBLY;
    3. no 10h/20h to it went out (`sent`): NO;
    4. one went out unacknowledged and no read-back came (`read_back`): POSSIBLY;
    5. a 10h/20h is only sent where the system parameters differ: a block read back as before (`changed`
       false) means none was executed — YES where it changed, else NO.
    """
    if acknowledged:
        return Release.YES
    if possibly_written or (exposed and changed):
        return Release.YES if changed else Release.POSSIBLY
    if not sent:
        return Release.NO
    if not read_back:
        return Release.POSSIBLY
    return Release.YES if changed else Release.NO
