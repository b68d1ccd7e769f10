"""What a change touches: the values a targeted read-back reads, from a base to the plant file.

A *base* is a plant file the modules are taken to hold (`plan --previous PLANT`, or the copy
of the plant file last applied in full on the line). Between the base's desired image of a
module and the plant file's, a module is *untouched* when the two are equal: it is not read
at all. A touched module is read as little as the change allows: its system block (one 50h,
always: it also proves the module is the one expected, S9) and the managed programs whose
desired values differ from the base's. Every program a system change could clamp is read
too (`prc3cfg.shell.readback.Target.clamped_by`: decided on the system block just read).

What is not read is not written: the desired image a targeted plan aims at is cut to the
programs the read-back holds (`within_read`), so the planner — which never writes a program
its desired image leaves `None` (`prc3cfg.core.planner.check`, rule 2), and so never sends an
11h/13h/14h across one — cannot write, initialise or rely on a program it did not read.
Pure.
"""

from __future__ import annotations

from dataclasses import replace

from prc3cfg.core.image import ModuleImage


def touched(before: ModuleImage | None, after: ModuleImage) -> tuple[int, ...] | None:
    """The programs to read of a module whose plant-file image goes from `before` (the base's;
    None: the base does not know the module) to `after`: None when nothing changed (the module is
    not read), else the managed programs whose desired values differ — all of them without a base."""
    if before is not None and before == after:
        return None
    return tuple(n for n, p in enumerate(after.programs, start=1) if p is not None and (before is None or before.program(n) != p))


def within_read(desired: ModuleImage, actual: ModuleImage) -> ModuleImage:
    """`desired` cut to the programs `actual` (a read-back) holds: the others are not the plan's."""
    return replace(desired, programs=tuple(None if a is None else d for d, a in zip(desired.programs, actual.programs)))


def not_read(desired: ModuleImage, actual: ModuleImage) -> tuple[int, ...]:
    """The programs `desired` manages that the read-back `actual` does not hold: taken as last verified."""
    return tuple(n for n, (d, a) in enumerate(zip(desired.programs, actual.programs), start=1) if d is not None and a is None)
