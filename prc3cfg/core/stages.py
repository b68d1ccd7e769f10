"""The values an apply's stages hand each other.

An apply runs, per line — or for every line at once, when the whole plan is reviewed first — read → plan →
gate → write and verify → record (`prc3cfg.shell.planning.read_lines`, `prc3cfg.shell.planning.line_plan`,
`prc3cfg.api._apply.gate`, `prc3cfg.shell.engine.Writing.write`); each stage takes values and gives values,
and the questions are asked between them, on the caller's thread. Owns nothing but these values: a line's
read-back (`ReadBack`), its plan (`LinePlan`) and the consent to release axes the gate gives for it
(`Consent`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from prc3cfg.core.image import Key, ModuleImage
from prc3cfg.core.plant_plan import ModuleChange


@dataclass(frozen=True)
class ReadBack:
    """What the read stage gives for a line, once its last module is read: every module's image by (bus,
    address)."""

    bus: str
    images: Mapping[Key, ModuleImage]


@dataclass(frozen=True)
class LinePlan:
    """What the write stage writes: a line's changes — or every line's — and the read-back they were planned
    from (what the snapshot keeps of each module before its first write)."""

    changes: tuple[ModuleChange, ...]
    images: Mapping[Key, ModuleImage]

    @property
    def releasing(self) -> frozenset[Key]:
        """The modules whose axes the changes release (10h/20h): what the write stage needs a consent to."""
        return frozenset((c.bus, c.address) for c in self.changes if c.releases_axes)


@dataclass(frozen=True)
class Consent:
    """The modules whose axes the operator agreed to release, the gate's answer: the write stage refuses a
    10h/20h to any other (`prc3cfg.shell.engine.NotConsented`), and a repair may release only those a change
    releases."""

    releases: frozenset[Key] = frozenset()
