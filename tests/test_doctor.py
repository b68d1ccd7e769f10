"""The line measured, not assumed: emulators whose modules answer after turnarounds of their own,
with seeded jitter, and `prc3cfg doctor` finding the framing, baud and character format they speak
and measuring those turnarounds — across the real emulator and the real pyserial client."""

from __future__ import annotations

import logging
import math
import random
import time
from types import SimpleNamespace

import pytest
from emulated import Result, run_cli
from hypothesis import given
from hypothesis import strategies as st

from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.device import ModuleState
from prc3cfg.core.framing import Direction, get_framing
from prc3cfg.core.line import LineSettings
from prc3cfg.core.uart import received
from prc3cfg.shell.doctor import DEFAULT_TIMEOUT, Diagnosis, LineCandidate, Search, Timing
from prc3cfg.shell.emulator.server import Emulator, FaultInjection
from prc3cfg.shell.link.client import Link
from prc3cfg.shell.link.ports import open_link, open_port

lines = st.builds(LineSettings, st.sampled_from([1200, 2400, 4800, 9600, 19200]), st.just(8),
                  st.sampled_from(["none", "odd", "even"]), st.sampled_from([1, 1.5, 2]))


@given(st.binary(max_size=80), lines)
def test_a_uart_at_the_senders_settings_receives_what_was_sent(data, line):
    assert received(data, line, line) == data


@given(st.binary(max_size=80), lines, st.sampled_from([1, 1.5, 2]))
def test_a_uart_checks_one_stop_bit_so_stop_bits_cannot_be_told_apart(data, line, stop_bits):
    assert received(data, line, LineSettings(line.baud, 8, line.parity, stop_bits)) == data


def test_a_frame_at_other_settings_arrives_as_other_bytes():
    frame = get_framing("crc16").encode(Direction.REQUEST, 1, codec.ReadSystem().encode())
    at = LineSettings(9600, 8, "even", 1)
    for other in (LineSettings(19200, 8, "even", 1), LineSettings(4800, 8, "even", 1),
                  LineSettings(9600, 8, "none", 1),
                  LineSettings(9600, 8, "odd", 1)):
        assert received(frame, other, at) != frame
    # a character of 7 bits loses the top bit
    assert received(frame, at, LineSettings(9600, 7, "even", 1)) != frame
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
        with Emulator({1: ModuleState.factory(1)}, turnaround=0.020, jitter=0.004,
                      faults=FaultInjection(seed=seed)) as emulator:
            return [emulator.turnaround_of(1) for _ in range(50)]

    first = draws(7)
    assert first == draws(7)  # a test run is repeatable
    assert first != draws(8)
    assert all(0.016 <= t <= 0.024 for t in first) and len(set(first)) > 1


def test_each_module_answers_after_its_own_turnaround(tmp_path):
    bus = SimpleNamespace(name="b1",
                          port="emulator://slow?line-speed=9600&turnaround=0.002&module-turnaround=2:0.080",
                          framing="crc16", line=LineSettings(), zvz=0.020, turnaround=0.010, timeout=5.0,
                          modules=[SimpleNamespace(address=1), SimpleNamespace(address=2)])
    cost = LineCost.of("crc16", LineSettings(), 0.080, 0.020)
    with open_link(bus, tmp_path / "plant.yaml") as link:
        started = time.monotonic()
        assert isinstance(link.request(2, codec.ReadSystem()), codec.SystemReply)
        # 80 ms and the line: never sooner
        assert time.monotonic() - started >= cost.message_time(2, codec.ReadSystem())


def doctor_line(capsys, emulator: Emulator, *options: str) -> tuple[Result, dict[str, str]]:
    """`prc3cfg doctor` on the emulator's RFC 2217 port: the result and the plant-file keys it printed."""
    host, tcp = emulator.listen(rfc2217=True)
    result = run_cli(capsys, "doctor", "--port", f"rfc2217://{host}:{tcp}", *options)
    keys = result.out.partition("The plant file's keys for this bus:\n")[2]
    return result, dict(line.strip().split(": ", 1) for line in keys.splitlines())


def turnarounds(out: str) -> dict[int, tuple[float, float]]:
    """address → (median, worst) in s, from doctor's table."""
    rows = [line.split("│") for line in out.splitlines() if line.startswith("│") and "ms" in line]
    return {int(r[1]): (float(r[2].split()[0]) / 1000, float(r[3].split()[0]) / 1000) for r in rows}


def test_doctor_finds_the_settings_and_measures_each_modules_turnaround(capsys):
    line = LineSettings(19200, 8, "odd", 1)
    modules = {1: ModuleState.factory(1), 2: ModuleState.factory(2)}
    # turnarounds of tens of ms, as a PRC 3's; how close doctor measures them is bench/doctor_bench.py's (a
    # wall-clock figure)
    with Emulator(modules, framing="stx", line=line, line_speed=True, turnaround=0.050,
                  turnarounds={2: 0.100}, jitter=0.004,
                  faults=FaultInjection(seed=1)) as emulator:
        result, keys = doctor_line(capsys, emulator, "--baud", "19200", "--modules", "1-2")
    assert result.code == 0, result.err
    assert keys == {"framing": "stx", "baud": "19200", "parity": "odd", "data_bits": "8", "stop_bits": "1",
                    "turnaround": keys["turnaround"]}
    measured = turnarounds(result.out)
    assert set(measured) == {1, 2}
    for address, turnaround in ((1, 0.050), (2, 0.100)):
        median, worst = measured[address]
        # never short of the module's wait (a busy machine only adds to it)
        assert median >= 0.9 * turnaround, (address, median)
        assert worst >= median
    assert float(keys["turnaround"]) >= measured[2][1]  # a broadcast waits for the slowest module


def test_doctor_asks_before_probing_in_a_framing_without_a_checksum(capsys):
    with Emulator({1: ModuleState.factory(1)}, framing="open-driver",
                  line=LineSettings(9600, 8, "even", 1)) as emulator:
        refused, _ = doctor_line(capsys, emulator, "--baud", "9600", "--parity", "even", "--modules", "1")
        assert refused.code == 1 and refused.err.count("\n") == 1
        assert ("(2 probes); 1 probe in open-driver, which has no checksum, was not made — give "
                "--allow-unchecked-probes") in refused.err
        found, keys = doctor_line(capsys, emulator, "--baud", "9600", "--parity", "even", "--modules", "1",
                                  "--allow-unchecked-probes")
    assert found.code == 0, found.err
    assert keys["framing"] == "open-driver" and keys["zvz"] == "0.02"


def test_doctor_finds_the_baud_of_a_pty(capsys):
    with Emulator({1: ModuleState.factory(1)}, line=LineSettings(4800, 8, "none", 1)) as emulator:
        pty = emulator.open_pty()
        result = run_cli(capsys, "doctor", "--port", pty, "--framing", "crc16", "--modules", "1",
                         "--exchanges", "2")
    assert result.code == 0, result.err
    assert f"{pty} speaks crc16, 4800 baud, 8N1" in result.out


def test_doctor_tries_and_proposes_8_data_bits_only(capsys):
    """A PRC 3 frame is binary: every setting doctor tries has 8 data bits, and so has every bus it proposes —
    a line whose UART is set to 7 answers none of its probes, and no 7 is proposed for it."""
    assert {c.line.data_bits for c in Search().candidates()} == {8}
    with Emulator({1: ModuleState.factory(1)}, framing="crc16",
                  line=LineSettings(9600, 7, "even", 1)) as emulator:
        result, keys = doctor_line(capsys, emulator, "--baud", "9600", "--parity", "even", "--modules", "1",
                                   "--exchanges", "1")
    assert result.code == 1 and keys == {}, (result.out, result.err)


@pytest.mark.soak
@pytest.mark.parametrize("framing", ["crc16", "stx", "open-driver"])
@pytest.mark.parametrize("parity", ["none", "odd", "even"])
@pytest.mark.parametrize("baud", [4800, 19200])
def test_doctor_finds_every_framing_and_character_format(capsys, framing, parity, baud):
    with Emulator({7: ModuleState.factory(7)}, framing=framing,
                  line=LineSettings(baud, 8, parity, 1)) as emulator:
        result, keys = doctor_line(capsys, emulator, "--modules", "7", "--exchanges", "2",
                                   "--allow-unchecked-probes")
    assert result.code == 0, result.err
    assert (keys["framing"], keys["baud"], keys["parity"]) == (framing, str(baud), parity)


@pytest.mark.soak
@pytest.mark.parametrize("framing", ["crc16", "stx", "open-driver"])
def test_doctor_measures_each_module_s_turnaround_on_every_framing(capsys, framing):
    """Each module measured on its own, its median never short of its turnaround (90 % of it: the jitter and
    the line's time taken off); how close above it, a wall-clock figure, is bench/doctor_bench.py's."""
    # 10 % of them is more than the gap detection an open-driver line adds (a few ms)
    given = {1: 0.080, 2: 0.120, 3: 0.160}
    with Emulator({a: ModuleState.factory(a) for a in given}, framing=framing,
                  line=LineSettings(9600, 8, "even", 1), line_speed=True,
                  turnarounds=given, jitter=0.004, faults=FaultInjection(seed=3)) as emulator:
        result, _ = doctor_line(capsys, emulator, "--framing", framing, "--baud", "9600", "--parity", "even",
                                "--modules", "1-4",
                                "--exchanges", "15", "--allow-unchecked-probes")
    assert result.code == 0, result.err
    measured = turnarounds(result.out)
    assert set(measured) == set(given)
    for address, turnaround in given.items():
        assert measured[address][0] >= 0.9 * turnaround, (address, measured[address])


def test_over_rfc2217_an_exchange_does_not_ask_the_gateway_to_purge(caplog):
    """pyserial's reset_input_buffer on rfc2217:// asks the gateway to purge and waits for its answer,
    polling in 50 ms steps — more than a whole exchange at 9600 baud, on every frame: the link drops
    what reached this end instead, and the gateway hears no purge."""
    line = LineSettings(9600, 8, "even", 1)
    with Emulator({1: ModuleState.factory(1)}, line=line) as emulator:
        host, tcp = emulator.listen(rfc2217=True)
        port = open_port(f"rfc2217://{host}:{tcp}", line, bus="b")
        try:
            link = Link(port, get_framing("crc16"), bus="b", line=line, timeout=0.5, retries=0)
            with caplog.at_level(logging.INFO, logger="prc3cfg.shell.emulator.server"):
                replies = [link.request(1, codec.ReadSystem()) for _ in range(5)]
        finally:
            port.close()
    assert all(isinstance(reply, codec.SystemReply) for reply in replies)
    assert not [r for r in caplog.records if "purge" in r.getMessage()]


@pytest.mark.parametrize(("answers", "timeout"), [
    pytest.param({1: (0.050, 0.052, 0.054)}, None, id="steady: the turnaround alone, the default timeout"),
    pytest.param({1: (0.100, 0.900, 0.400), 2: (0.050, 0.060, 0.055)}, 0.8,
                 id="one module varies by 0.8 s: a timeout of 0.8 s"),
    pytest.param({1: (0.100, 0.6005)}, 0.501, id="just over the default: rounded up to the millisecond"),
    pytest.param({1: (0.100, 0.600)}, None, id="by the default exactly: the default"),
    pytest.param({1: (0.050, 0.900), 2: ()}, 0.85, id="a module that never answered varies by nothing"),
])
def test_doctor_proposes_a_timeout_only_where_answers_varied_more_than_the_default_allows(answers, timeout):
    """The wait for a reply is the line's own time, the turnaround (the slowest answer measured) and the
    bus's `timeout` on top: a module whose answers varied by more than the default `timeout` may next
    answer later than the slowest seen by as much — doctor proposes that much, and nothing otherwise."""
    found = LineCandidate("crc16", LineSettings(1200, 8, "even", 1))
    modules = tuple(Timing(address, turnarounds, 0, 0) for address, turnarounds in answers.items())
    keys = Diagnosis("/dev/ttyUSB0", found, 0.020, True, modules).plant_keys()
    assert keys.get("timeout") == timeout
    assert keys["turnaround"] == math.ceil(max(max(t) for t in answers.values() if t) * 1000) / 1000


def test_doctor_measures_a_module_slower_than_its_probes_allow_and_proposes_a_timeout(capsys):
    """A module answering in 0.1..0.9 s at 1200 baud (0.5 s ± a seeded 0.4 s): found by a probe (its first
    answer is quick), then every timed exchange answered however late — none counted lost — and a
    `timeout` proposed for answers that vary that much."""
    seed, jitter = 57, 0.400
    draws = random.Random(seed)  # the emulator's: `Emulator.turnaround_of`
    first, *timed = (0.500 + draws.uniform(-jitter, jitter) for _ in range(5))
    assert first < 0.2 and max(timed) - min(timed) > 0.55  # what the seed was chosen for
    line = LineSettings(1200, 8, "even", 1)
    with Emulator({1: ModuleState.factory(1)}, line=line, line_speed=True, turnaround=0.500, jitter=jitter,
                  faults=FaultInjection(seed=seed)) as emulator:
        result, keys = doctor_line(capsys, emulator, "--framing", "crc16", "--baud", "1200", "--parity",
                                   "even", "--modules", "1",
                                   "--exchanges", "4")
    assert result.code == 0, result.err
    ((_, worst),) = turnarounds(result.out).values()
    # no answer comes sooner than the emulator was told to give it; how much later a busy machine measures it
    # is bench/doctor_bench.py's (a wall-clock figure)
    assert worst >= max(timed) - 0.005 and "4/4" in result.out
    # a spread of the answers (at most the slowest), which varied by more than the default timeout allows
    assert DEFAULT_TIMEOUT < float(keys["timeout"]) <= worst + 0.001
    assert float(keys["turnaround"]) >= worst
