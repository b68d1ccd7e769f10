"""The line measured, not assumed: emulators whose modules answer after turnarounds of their own,
with seeded jitter, and `prc3cfg doctor` finding the framing, baud and character format they speak
and measuring those turnarounds — across the real emulator and the real pyserial client."""

from __future__ import annotations

import time
from types import SimpleNamespace

from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.device import ModuleState
from prc3cfg.core.line import LineSettings
from prc3cfg.shell.emulator import Emulator, FaultInjection
from prc3cfg.shell.link import open_link


def test_jitter_is_seeded_and_within_its_bounds():
    def draws(seed: int) -> list[float]:
        with Emulator({1: ModuleState.factory(1)}, turnaround=0.020, jitter=0.004, faults=FaultInjection(seed=seed)) as emulator:
            return [emulator.turnaround_of(1) for _ in range(50)]

    first = draws(7)
    assert first == draws(7)  # a test run is repeatable
    assert first != draws(8)
    assert all(0.016 <= t <= 0.024 for t in first) and len(set(first)) > 1


def test_each_module_answers_after_its_own_turnaround(tmp_path):
    bus = SimpleNamespace(name="b1", port="emulator://slow?line-speed=9600&turnaround=0.002&module-turnaround=2:0.080",
                          framing="crc16", line=LineSettings(), zvz=0.020, turnaround=0.010, timeout=5.0,
                          modules=[SimpleNamespace(address=1), SimpleNamespace(address=2)])  # fmt: skip
    cost = LineCost.of("crc16", LineSettings(), 0.080, 0.020)
    with open_link(bus, tmp_path / "plant.yaml") as link:
        started = time.monotonic()
        assert isinstance(link.request(2, codec.ReadSystem()), codec.SystemReply)
        assert time.monotonic() - started >= cost.message_time(2, codec.ReadSystem())  # 80 ms and the line: never sooner
