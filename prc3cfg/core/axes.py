"""What an apply concludes of a module's axes: released, not, or possibly (`Release`).

A 10h/20h releases the axes, and a module whose axes were released must travel to its reference
point before it runs again. Which of the three a module's run is, is the apply's to conclude
(`prc3cfg.shell.apply.ModuleRun.released`) from what went out, what was acknowledged and what the
verifying read-back shows; the account says it (`prc3cfg.core.render`), and the API's result names
every module not `NO` (`prc3cfg.api.ApplyResult.released`). Pure.
"""

from __future__ import annotations

import enum


class Release(enum.Enum):
    """Whether a module's axes were released (10h/20h) and it must travel to its reference point."""

    NO = "no"
    YES = "yes"
    POSSIBLY = "possibly"  # a 10h/20h went out unacknowledged, and no read-back settles it
