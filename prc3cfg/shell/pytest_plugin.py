"""The pytest plugin of prc3cfg (entry point `pytest11`): plant repositories test their plant files.

    from prc3cfg import api

    def test_the_plant_applies_and_then_has_nothing_to_do(prc3cfg_emulated):
        emulated = prc3cfg_emulated("plant.yaml")        # every bus on an emulator, factory modules
        plan = api.plan(emulated.plant)
        assert plan.changes
        result = api.apply(emulated.plant, gates=api.Gates(allow_axis_release=True))
        assert result.verified
        assert not api.plan(emulated.plant).changes

`prc3cfg_emulated(path, images=None, **bus_settings)` puts the plant file's buses on emulators
(`prc3cfg.shell.testing.emulate`): modules at factory defaults, or as a `prc3cfg read --json` file
says; a relative path (of either file) is taken from pytest's rootdir. The emulators stop when the test ends.

pytest loads this module in every session of every project whose environment has prc3cfg installed, and
rewrites the asserts of every module of prc3cfg it imports then (a plugin's distribution is rewritten whole).
So it imports nothing of prc3cfg until a test asks for the fixture: a session that never does pays for none
of it.
"""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from prc3cfg.shell.testing import EmulatedPlant


@pytest.fixture
def prc3cfg_emulated(request: pytest.FixtureRequest, tmp_path: Path,
                     monkeypatch: pytest.MonkeyPatch) -> Iterator[Callable[..., EmulatedPlant]]:
    """Put a plant file's buses on emulators: `prc3cfg_emulated("plant.yaml", images=None)`. The records
    of axis releases on them (`prc3cfg.shell.pending_records`) are kept in the test's own folder: an emulated
    release is no business of the machine's."""
    from prc3cfg.shell.testing import emulate

    monkeypatch.setenv("PRC3CFG_STATE_DIR", str(tmp_path / "prc3cfg-state"))
    numbers = itertools.count(1)
    with contextlib.ExitStack() as stack:

        def start(plant_path: str | Path, images: str | Path | None = None, **options: Any) -> EmulatedPlant:
            root = Path(request.config.rootpath)
            path = root / plant_path
            # both from the rootdir, wherever pytest runs
            options["images"] = None if images is None else root / images
            folder = tmp_path / f"emulated-{next(numbers)}"
            folder.mkdir()
            return stack.enter_context(emulate(path, folder, **options))

        yield start
