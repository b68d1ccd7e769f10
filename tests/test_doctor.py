"""The line measured, not assumed: emulators whose modules answer after turnarounds of their own,
with seeded jitter, and `prc3cfg doctor` finding the framing, baud and character format they speak
and measuring those turnarounds — across the real emulator and the real pyserial client."""

from __future__ import annotations

import time
from types import SimpleNamespace

from hypothesis import given
from hypothesis import strategies as st

from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.device import ModuleState
from prc3cfg.core.framing import Direction, get_framing
from prc3cfg.core.line import LineSettings
from prc3cfg.core.uart import received
from prc3cfg.shell.emulator import Emulator, FaultInjection
from prc3cfg.shell.link import Link, open_link, open_port

lines = st.builds(LineSettings, st.sampled_from([1200, 2400, 4800, 9600, 19200]), st.just(8),
                  st.sampled_from(["none", "odd", "even"]), st.sampled_from([1, 1.5, 2]))  # fmt: skip


@given(st.binary(max_size=80), lines)
def test_a_uart_at_the_senders_settings_receives_what_was_sent(data, line):
    assert received(data, line, line) == data


@given(st.binary(max_size=80), lines, st.sampled_from([1, 1.5, 2]))
def test_a_uart_checks_one_stop_bit_so_stop_bits_cannot_be_told_apart(data, line, stop_bits):
    assert received(data, line, LineSettings(line.baud, 8, line.parity, stop_bits)) == data


def test_a_frame_at_other_settings_arrives_as_other_bytes():
    frame = get_framing("crc16").encode(Direction.REQUEST, 1, codec.ReadSystem().encode())
    at = LineSettings(9600, 8, "even", 1)
    for other in (LineSettings(19200, 8, "even", 1), LineSettings(4800, 8, "even", 1), LineSettings(9600, 8, "none", 1),
                  LineSettings(9600, 8, "odd", 1)):  # fmt: skip
        assert received(frame, other, at) != frame
    assert received(frame, at, LineSettings(9600, 7, "even", 1)) != frame  # a character of 7 bits loses the top bit
    assert received(b"\xa5", LineSettings(9600, 7, "odd", 1), LineSettings(9600, 7, "odd", 1)) == b"\x25"


def answers(url: str, line: LineSettings, framing: str = "crc16") -> bool:
    """Whether module 1 answers a 50h sent with `line`'s settings from the real pyserial client."""
    port = open_port(url, line, bus="b")
    try:
        link = Link(port, get_framing(framing), bus="b", line=line, timeout=0.2, retries=0)
        return link.probe(1, codec.ReadSystem(), 0.2) is not None
    finally:
        port.close()


def test_over_rfc2217_the_emulator_answers_only_a_client_at_its_settings():
    at = LineSettings(4800, 8, "odd", 2)
    with Emulator({1: ModuleState.factory(1)}, line=at) as emulator:
        host, tcp = emulator.listen(rfc2217=True)
        url = f"rfc2217://{host}:{tcp}"
        assert answers(url, at) and answers(url, LineSettings(4800, 8, "odd", 1))  # one stop bit checked
        assert not answers(url, LineSettings(9600, 8, "odd", 2))
        assert not answers(url, LineSettings(4800, 8, "even", 2))
        assert not answers(url, LineSettings(4800, 7, "odd", 2))


def test_on_a_pty_the_emulator_answers_only_a_client_at_its_baud():
    with Emulator({1: ModuleState.factory(1)}, line=LineSettings(19200, 8, "none", 1)) as emulator:
        pty = emulator.open_pty()
        assert answers(pty, LineSettings(19200, 8, "none", 1))
        assert not answers(pty, LineSettings(9600, 8, "none", 1))


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
