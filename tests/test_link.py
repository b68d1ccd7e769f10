"""The link client and read-back against the real emulator: their logic over an in-memory line
(`pair.PairPort`), and the link over socket:// and a pty where the test is about them."""

from __future__ import annotations

import io
import os
import socket
import threading
import time
import tty
from dataclasses import replace
from types import SimpleNamespace

import pytest
from pair import PairPort

from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.device import ModuleState
from prc3cfg.core.framing import Direction, get_framing
from prc3cfg.core.image import DEFAULT_SYSTEM, Program
from prc3cfg.core.line import LineSettings
from prc3cfg.core.what_to_read import read_messages
from prc3cfg.errors import UserError
from prc3cfg.shell.emulator.server import Emulator, FaultInjection
from prc3cfg.shell.link.client import Link, LinkError, PossibleWrite
from prc3cfg.shell.link.ports import EMULATOR_KEYS, open_link, open_port
from prc3cfg.shell.link.trace import Trace
from prc3cfg.shell.readback import ReadBackError, read_module

FRAMINGS = ["crc16", "open-driver", "stx"]


def teach(state: ModuleState, changes: dict[int, Program]) -> ModuleState:
    return replace(state, image=state.image.with_programs(changes))


def connect(emulator: Emulator, framing: str = "crc16", *, retries: int = 3, timeout: float = 0.3,
            **kw) -> Link:
    """A link to `emulator` over an in-memory line."""
    return Link(PairPort(emulator), get_framing(framing), bus="test", line=LineSettings(), timeout=timeout,
                retries=retries, **kw)


def test_a_link_reads_back_over_socket():
    """The link over pyserial's socket:// to the emulator's TCP server: what `connect` does in memory."""
    programs = {n: Program(P=100 + n, V=200, Vr=-n, T=n, F1=1000 + n, F2=n, A=(n % 64) + 1)
                for n in range(1, 9)}
    state = teach(ModuleState.factory(7), programs)
    with Emulator({7: state}) as emulator:
        host, port = emulator.listen()
        link = Link(open_port(f"socket://{host}:{port}", LineSettings(), bus="test"), get_framing("crc16"),
                    bus="test")
        try:
            image = read_module(link, 7, range(1, 9))
        finally:
            link.port.close()
    assert image.system == state.image.system and image.programs[:8] == state.image.programs[:8]
    assert link.exchanges == 3


@pytest.mark.parametrize("framing", FRAMINGS)
def test_read_back_of_a_full_module_takes_17_exchanges(framing):
    programs = {n: Program(P=100 + n, V=200, Vr=-n, T=n, F1=1000 + n, F2=n, A=(n % 64) + 1)
                for n in range(1, 65)}
    state = teach(ModuleState.factory(7), programs)
    with Emulator({7: state}, framing=framing) as emulator:
        link = connect(emulator, framing)
        image = read_module(link, 7, range(1, 65))
        link.port.close()
    assert image == state.image
    # over TCP no port checks parity: on open-driver every read is heard twice (`protects_replies`)
    assert link.exchanges == 17 * (1 if link.framing.checked else 2)


def test_read_back_reads_only_managed_programs():
    state = ModuleState.factory(1)
    with Emulator({1: state}) as emulator:
        link = connect(emulator)
        image = read_module(link, 1, [2, 3, 9])
        link.port.close()
    assert [n for n, p in enumerate(image.programs, start=1) if p is not None] == [2, 3, 9]
    assert link.exchanges == 3  # 50h, 52h 2..3, 51h 9


@pytest.mark.parametrize(
    ("programs", "expected"),
    [
        ([], ["5000"]),
        ([1], ["5000", "5101"]),
        (range(1, 65), ["5000"] + [f"5200{n:02x}{n + 3:02x}" for n in range(1, 65, 4)]),
        ([1, 2, 5, 6, 7, 8], ["5000", "52000102", "52000508"]),
        ([1, 4, 5, 40], ["5000", "52000104", "5105", "5128"]),
        ([3, 5, 6, 7, 8, 9], ["5000", "52000306", "52000709"]),
    ],
)
def test_read_messages_are_the_fewest(programs, expected):
    assert [m.hex() for m in read_messages(programs)] == expected


def test_retries_survive_lost_and_damaged_frames():
    with Emulator({1: ModuleState.factory(1)}, faults=FaultInjection(0.3, 0.2, seed=3)) as emulator:
        trace_text = io.StringIO()
        # in memory: every reply is there at once
        link = connect(emulator, retries=8, timeout=0.02, trace=Trace(trace_text))
        for n in range(1, 21):
            assert link.request(1, codec.WriteSpeeds(((n, 100 + n),))) == 0
        link.port.close()
        assert all(emulator.module(1).image.program(n).V == 100 + n for n in range(1, 21))
    assert link.exchanges > 20  # some were retried
    assert "retrying" in trace_text.getvalue()


def test_a_silent_module_names_bus_and_address():
    with Emulator({1: ModuleState.factory(1)}) as emulator:
        link = connect(emulator, retries=1, timeout=0.1)
        # the bus's 0.1 s on top of the line's own 0.053 s: a 50h's frames at 9600 baud 8E1 with the margin,
        # the turnaround
        with pytest.raises(LinkError,
                           match=r"^bus test, module 4: no reply within 0.153 s to 50h after 2 attempts"):
            link.request(4, codec.ReadSystem())
        link.port.close()


class LatePort(PairPort):
    """An in-memory line whose module answers the first `late` frames after the link stopped waiting:
    each of those replies arrives with the reply to the next frame, ahead of it (the input dropped
    before a frame leaves is what came before it)."""

    def __init__(self, emulator: Emulator, late: int) -> None:
        super().__init__(emulator)
        self.late, self.held = late, b""

    def write(self, data: bytes, /) -> int:
        waiting, self._replies = self._replies, bytearray(self.held)
        written = super().write(data)
        if self.late:
            self.late -= 1
            self.held, self._replies = bytes(self._replies), waiting
        else:
            self.held = b""
        return written


def test_a_read_answered_as_a_write_after_an_unanswered_write_names_the_late_reply_too():
    """A write whose acknowledgement comes after the time-out, and the next read answered by it: the
    line stops (`PossibleWrite`), and the error names the late reply — on crc16 no damage is likely."""
    with Emulator({1: ModuleState.factory(1)}) as emulator:
        link = Link(LatePort(emulator, late=1), get_framing("crc16"), bus="test", timeout=0.01, retries=0)
        with pytest.raises(LinkError, match="no reply within"):
            link.request(1, codec.WriteSpeeds(((1, 100),)))
        with pytest.raises(PossibleWrite) as stopped:
            link.request(1, codec.ReadSystem())
        assert str(stopped.value).startswith("bus test, module 1: a read (50h) was answered as a write is — "
                                             "likeliest the late "
                                             "acknowledgement of a write to it (41h) that went "
                                             "unanswered at first")
        assert "travel the module to its reference point" in str(stopped.value)


def test_a_read_answered_as_a_write_with_no_write_owed_blames_a_duplicate_alone():
    """A read answered with data settles every acknowledgement owed: a read answered as a write after
    it is, on a checksummed line, a duplicated acknowledgement — here another master's write's."""
    with Emulator({1: ModuleState.factory(1)}) as emulator:
        port = LatePort(emulator, late=1)
        link = Link(port, get_framing("crc16"), bus="test", timeout=0.01, retries=0)
        with pytest.raises(LinkError, match="no reply within"):
            link.request(1, codec.WriteSpeeds(((1, 100),)))
        assert link.request(1, codec.WriteSpeeds(((2, 100),))) == 0  # the first one's acknowledgement
        assert isinstance(link.request(1, codec.ReadSystem()), codec.SystemReply)
        port.late = 1
        port.write(get_framing("crc16").encode(Direction.REQUEST, 1, codec.WriteSpeeds(((3, 100),)).encode()))
        with pytest.raises(PossibleWrite) as stopped:
            link.request(1, codec.ReadSystem())
        assert str(stopped.value).startswith("bus test, module 1: a read (50h) was answered as a write is — "
                                             "likeliest a duplicated ack")


def test_an_unanswered_write_to_another_module_does_not_explain_an_acknowledged_read():
    """A link takes a reply only from the module asked: a write to module 2 that went unanswered owes
    module 1 nothing, so module 1's read answered as a write is blamed on a duplicate alone."""
    with Emulator({1: ModuleState.factory(1), 2: ModuleState.factory(2)}) as emulator:
        port = LatePort(emulator, late=1)
        link = Link(port, get_framing("crc16"), bus="test", timeout=0.01, retries=0)
        with pytest.raises(LinkError, match="no reply within"):
            link.request(2, codec.WriteSpeeds(((1, 100),)))
        port.late = 1
        # another master's
        port.write(get_framing("crc16").encode(Direction.REQUEST, 1, codec.WriteSpeeds(((3, 100),)).encode()))
        with pytest.raises(PossibleWrite) as stopped:
            # answered by module 2's late acknowledgement (ignored), then module 1's
            link.request(1, codec.ReadSystem())
        assert str(stopped.value).startswith("bus test, module 1: a read (50h) was answered as a write is — "
                                             "likeliest a duplicated ack")


def test_a_wrong_framing_is_a_silent_line():
    with Emulator({1: ModuleState.factory(1)}, framing="stx") as emulator:
        link = connect(emulator, "crc16", retries=0, timeout=0.1)
        with pytest.raises(LinkError, match="framing \\(crc16\\)"):
            link.request(1, codec.ReadSystem())
        link.port.close()


def test_s9_must_equal_the_configured_address():
    with Emulator({6: ModuleState.factory(6)}) as emulator:
        # A module whose S9 says 5 answering at address 6: a wiring or Address Init fault.
        emulator._bus.modules[6] = ModuleState.factory(5)
        link = connect(emulator)
        with pytest.raises(ReadBackError, match=r"^bus test, module 6: .* reports S9 = 5 — check"):
            read_module(link, 6, [])
        link.port.close()


def test_error_reply_to_a_read_is_a_clear_error():
    with Emulator({1: ModuleState.factory(1)}) as emulator:
        emulator.update(1, mode="stop")
        link = connect(emulator)
        assert link.request(1, codec.InitSystem()) == 0
        emulator.update(1, fault="E09")
        assert link.request(1, codec.InitSystem()) == 21  # writes refused in a fault ...
        assert read_module(link, 1, [1]).program(1) is not None  # ... reads still answered
        link.port.close()


def test_trace_has_both_directions_in_hex():
    with Emulator({1: ModuleState.factory(1)}) as emulator:
        text = io.StringIO()
        link = connect(emulator, trace=Trace(text))
        link.request(1, codec.ReadSystem())
        link.port.close()
    lines = [line.split("\t") for line in text.getvalue().splitlines()]
    assert [(line[1], line[2]) for line in lines] == [("test", ">"), ("test", "<")]
    assert lines[0][3] == "a5010150" + "00" + lines[0][3][10:]  # start code, address, N-1, message
    assert lines[0][3] == get_framing("crc16").encode(Direction.REQUEST, 1, b"\x50\x00").hex()
    assert len(bytes.fromhex(lines[1][3])) == 5 + 22  # the 50h data block in a crc16 reply frame


def test_pty_line():
    with Emulator({3: ModuleState.factory(3)}) as emulator:
        path = emulator.open_pty()
        line = LineSettings(parity="none")
        link = Link(open_port(path, line, bus="pty"), get_framing("crc16"), bus="pty", line=line, timeout=0.5)
        try:
            assert read_module(link, 3, [1]).system.S1 == 400
        finally:
            link.port.close()


def test_pty_with_parity_is_refused_in_one_line():
    with Emulator({3: ModuleState.factory(3)}) as emulator:
        path = emulator.open_pty()
        try:
            port = open_port(path, LineSettings(parity="even"), bus="pty")
        except Exception as error:  # noqa: BLE001 - the point is which error
            assert "parity" in str(error) and "\n" not in str(error)
        else:
            port.close()  # some kernels accept the setting silently; then there is nothing to refuse


def test_unreachable_port_is_one_line():
    with pytest.raises(Exception, match=r"^bus b1: cannot open port socket://127.0.0.1:1 .* — check"):
        open_port("socket://127.0.0.1:1", LineSettings(), bus="b1")


@pytest.mark.parametrize("use", ["first", "second"])
def test_a_fresh_pty_that_drops_parity_is_refused_at_once_in_one_line(use):
    """A pty takes parity without a word the first time, then refuses the next change with a bare
    termios.error: both uses must give the same one line."""
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        name = os.ttyname(slave)
        if use == "second":
            with pytest.raises(UserError):
                open_port(name, LineSettings(parity="even"), bus="b")
        with pytest.raises(UserError,
                           match=rf"^bus b: port {name} refuses 8 data bits, parity even, 1 stop bits — "):
            open_port(name, LineSettings(parity="even"), bus="b")
        open_port(name, LineSettings(parity="none"), bus="b").close()  # what a pty can carry
    finally:
        os.close(master)
        os.close(slave)


@pytest.mark.parametrize("framing", ["crc16", "stx"])
def test_a_reply_split_by_a_pause_over_tcp_is_taken_whole(framing):
    """Over socket:// the second half of a reply may come long after the first (a paused process,
    a busy machine): longer than the inter-character (crc16) or message (stx) time-out of a UART.
    It is one good reply — not a discarded frame, a time-out and a retry."""
    encoding = get_framing(framing)
    reply = encoding.encode(Direction.REPLY, 1, codec.SystemReply(DEFAULT_SYSTEM, 1).encode())
    paused = threading.Event()  # the link has read half the reply, then found nothing three times
    with socket.create_server(("127.0.0.1", 0)) as server:

        def module() -> None:
            conn, _ = server.accept()
            with conn:
                conn.recv(4096)  # the request
                conn.sendall(reply[:5])
                paused.wait()
                conn.sendall(reply[5:])

        threading.Thread(target=module, daemon=True).start()
        line = LineSettings()
        port = open_port(f"socket://127.0.0.1:{server.getsockname()[1]}", line, bus="test")
        read, heard, silent = port.read, [], []

        def read_and_count_silence(size: int = 1) -> bytes:
            # an empty read has waited a read slice (50 ms): 150 ms > 63 ms for stx, 5.7 ms for crc16
            data = read(size)
            heard.append(data) if data else silent.append(heard != [])
            if sum(silent) == 3:
                paused.set()
            return data

        port.read = read_and_count_silence
        text = io.StringIO()
        link = Link(port, encoding, bus="test", line=line, timeout=10, retries=0, trace=Trace(text))
        try:
            assert link.request(1, codec.ReadSystem()) == codec.SystemReply(DEFAULT_SYSTEM, 1)
        finally:
            paused.set()
            port.close()
    assert b"".join(heard) == reply and sum(silent) == 3
    assert [line.split("\t")[2] for line in text.getvalue().splitlines()] == [">", "<"]  # nothing discarded


def emulator_bus(port: str) -> SimpleNamespace:
    """A plant bus with one module, as `open_link` reads it."""
    return SimpleNamespace(name="b1", port=port, framing="crc16", line=LineSettings(), zvz=0.020,
                           turnaround=0.010,
                           timeout=5.0, modules=[SimpleNamespace(address=1)])


def test_an_emulator_at_line_speed_answers_no_sooner_than_the_line_would(tmp_path):
    with open_link(emulator_bus("emulator://rehearsal?line-speed=1200"), tmp_path / "plant.yaml") as link:
        started = time.monotonic()
        assert link.request(1, codec.ReadSystem()) == codec.SystemReply(DEFAULT_SYSTEM, 1)
        took = time.monotonic() - started
    line_time = LineCost.of("crc16", LineSettings(baud=1200), 0.010,
                            0.020).message_time(1, codec.ReadSystem())
    assert took >= line_time  # 34 bytes of 11 bits at 1200 baud and the turnaround: 0.32 s
    # the query is no part of the name
    assert (tmp_path / ".prc3cfg" / "emulators" / "rehearsal.json").exists()
    assert link.takes_line_time  # so a broadcast waits as on the line


def test_an_emulator_takes_frames_at_once_so_a_broadcast_waits_for_nothing(tmp_path):
    with open_link(emulator_bus("emulator://quick"), tmp_path / "plant.yaml") as link:
        assert not link.takes_line_time
        link.broadcast(codec.WriteSpeeds(((4, 123),)), turnaround=0.010)
        assert link.request(1, codec.ReadProgram(4)).programs[0].V == 123  # taken before the next frame


@pytest.mark.parametrize(
    ("query", "says"),
    [
        ("?speed=9600", f"unknown option 'speed' — emulator:// takes {EMULATOR_KEYS}"),
        ("?line-speed=9600&trace=1", f"unknown option 'trace' — emulator:// takes {EMULATOR_KEYS}"),
        ("?line-speed=fast",
         "line-speed 'fast' is not a baud rate — write a whole number, e.g. line-speed=9600"),
        ("?line-speed=0", "line-speed '0' is not a baud rate — write a whole number, e.g. line-speed=9600"),
        ("?line-speed", "line-speed '' is not a baud rate — write a whole number, e.g. line-speed=9600"),
        ("?line-speed=9600&line-speed=1200", "line-speed is given more than once — give it once"),
        ("?turnaround=10ms",
         "turnaround '10ms' is not a time of 0..10 s — write seconds, e.g. turnaround=0.010"),
        ("?jitter=-1", "jitter '-1' is not a time of 0..10 s — write seconds, e.g. jitter=0.010"),
        ("?module-turnaround=31:0.01",
         "module-turnaround '31:0.01' is not ADDRESS:SECONDS — write e.g. module-turnaround=3:0.040"),
        ("?seed=x", "seed 'x' is not a seed — write a whole number, e.g. seed=1"),
    ],
)
def test_an_emulator_port_takes_only_its_keys_and_says_so_in_one_line(tmp_path, query, says):
    port = f"emulator://rehearsal{query}"
    with pytest.raises(UserError) as refused, open_link(emulator_bus(port), tmp_path / "plant.yaml"):
        pass
    assert str(refused.value) == f"bus b1: port {port}: {says}"
    assert not (tmp_path / ".prc3cfg").exists()  # refused before the emulator starts
