"""What every test shares: a lock directory of its own, and the demo plant on emulators."""

from __future__ import annotations

import pytest
from emulated import emulated_plant


@pytest.fixture(autouse=True)
def private_locks(tmp_path, monkeypatch):
    """Line locks and records of untold axis releases in the test's own folder: tests running at
    once never wait for each other, and a test that kills an apply leaves nothing to the next."""
    monkeypatch.setenv("PRC3CFG_LOCK_DIR", str(tmp_path / "locks"))
    monkeypatch.setenv("PRC3CFG_STATE_DIR", str(tmp_path / "state"))


@pytest.fixture
def plant(tmp_path):
    """The demo plant (`plants/demo-line.yaml`) with every bus on an emulator, factory modules."""
    with emulated_plant(tmp_path) as emulated:
        yield emulated
