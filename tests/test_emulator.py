"""The emulator end to end: what modules answer over an in-memory line (`pair.PairPort`, where a
silence costs no time-out), and real server threads, real pyserial clients over socket:// and a pty."""

from __future__ import annotations

import itertools
import json
import os
import shutil
import socket
import subprocess
import sys
import time
from dataclasses import replace
from types import SimpleNamespace

import pytest
from emulated import run_cli
from emulator_client import Client, answered, hang_up, serve
from pair import PairPort

from prc3cfg.core import codec, device
from prc3cfg.core.device import ModuleState
from prc3cfg.core.framing import Direction, Frame, get_framing
from prc3cfg.core.image import DEFAULT_SYSTEM, Program
from prc3cfg.core.line import LineSettings
from prc3cfg.errors import UserError
from prc3cfg.shell.emulator import server
from prc3cfg.shell.emulator.server import Emulator, FaultInjection
from prc3cfg.shell.emulator.state import journal_path, load_state, state_document

WRITE_P10 = codec.WriteProgram(10, Program(P=150, V=300, Vr=53, T=20, F1=1010, F2=50, A=5))


def modules(*addresses: int) -> dict[int, ModuleState]:
    return {a: ModuleState.factory(a) for a in addresses}


@pytest.fixture
def bus(tmp_path):
    emulator = Emulator(modules(1, 3), state_path=tmp_path / "state.json")
    client = Client(PairPort(emulator))
    yield emulator, client, tmp_path / "state.json"
    client.close()
    emulator.close()


def test_write_is_answered_stored_and_saved(bus):
    emulator, client, state_path = bus
    assert client.send(1, WRITE_P10.encode()) == b"\x00\x00"
    assert emulator.module(1).image.program(10) == WRITE_P10.program
    saved = load_state(state_path)
    assert saved[1].image.program(10) == WRITE_P10.program
    assert json.loads(state_path.read_text())["format"] == "prc3-emulator/1"


def test_manual_example_read_of_system_parameters(bus):
    _, client, _ = bus
    reply = client.send(1, bytes.fromhex("5000"))
    assert reply == bytes.fromhex("0190003202F20258000A05DC03E800010247044C000A")


def test_absent_module_is_silent(bus):
    _, client, _ = bus
    assert client.send(2, bytes.fromhex("5000")) is None


def test_broadcast_is_processed_by_all_and_answered_by_none(bus):
    emulator, client, state_path = bus
    assert client.send(0, codec.WriteSpeeds(((4, 123),)).encode()) is None
    assert client.send(1, bytes.fromhex("5000")) is not None  # the line still works
    assert emulator.module(1).image.program(4).V == 123
    assert emulator.module(3).image.program(4).V == 123
    assert load_state(state_path)[3].image.program(4).V == 123


def test_rejected_write_answers_its_code_and_saves_nothing(bus):
    _, client, state_path = bus
    before = state_path.read_bytes()
    bad = codec.WriteProgram(10, replace(WRITE_P10.program, P=5000))  # P > S1 = 400
    assert client.send(1, bad.encode()) == bytes.fromhex("2000")
    assert state_path.read_bytes() == before


def test_bad_crc_is_silence(bus):
    _, client, _ = bus
    frame = bytearray(client.framing.encode(Direction.REQUEST, 1, bytes.fromhex("5000")))
    frame[-1] ^= 0xFF
    assert client.send_raw(bytes(frame)) is None
    assert client.send(1, bytes.fromhex("5000")) is not None  # and the next frame is heard


def test_operating_states_through_the_python_api(bus):
    emulator, client, _ = bus
    emulator.update(1, mode="manual")
    assert client.send(1, bytes.fromhex("5000")) is None
    emulator.update(1, mode="run", active_program=10)
    assert client.send(1, codec.InitSystem().encode()) == bytes([20, 0])
    assert client.send(1, WRITE_P10.encode()) == bytes([16, 0])
    emulator.update(1, mode="stop", fault="E09")
    assert client.send(1, codec.InitProgram(3).encode()) == bytes([21, 0])
    emulator.teach_in(3, 7, 321)
    reply = client.send(3, codec.ReadProgram(7).encode())
    assert codec.decode_reply(codec.ReadProgram(7), reply).programs[0].P == 321


@pytest.mark.parametrize("framing", ["crc16", "open-driver", "stx"])
def test_every_framing_over_socket(framing):
    with Emulator(modules(5), framing=framing) as emulator:
        host, port = emulator.listen()
        client = Client(f"socket://{host}:{port}", framing)
        try:
            assert client.send(5, WRITE_P10.encode()) == b"\x00\x00"
            reply = client.send(5, codec.ReadPrograms(9, 11).encode())
            decoded = codec.decode_reply(codec.ReadPrograms(9, 11), reply)
            assert decoded.programs[1] == WRITE_P10.program
        finally:
            client.close()


def test_pty_serves_any_serial_program():
    with Emulator(modules(2)) as emulator:
        path = emulator.open_pty()
        assert os.path.exists(path)
        client = Client(path, parity="N")
        try:
            reply = client.send(2, codec.ReadSystem().encode())
            assert codec.decode_reply(codec.ReadSystem(), reply) == codec.SystemReply(DEFAULT_SYSTEM, 2)
        finally:
            client.close()


def test_fault_injection_is_seeded_and_repeatable():
    def answered(seed: int) -> list[bool]:
        with Emulator(modules(1), faults=FaultInjection(drop_rate=0.5, seed=seed)) as emulator:
            client = Client(PairPort(emulator))
            try:
                return [client.send(1, b"\x50\x00") is not None for _ in range(12)]
            finally:
                client.close()

    first = answered(7)
    assert first == answered(7)
    assert 0 < sum(first) < 12


def test_corrupted_replies_fail_their_crc():
    with Emulator(modules(1), faults=FaultInjection(corrupt_rate=1.0, seed=1)) as emulator:
        client = Client(PairPort(emulator))
        try:
            replies = [client.send(1, b"\x50\x00") for _ in range(6)]
        finally:
            client.close()
    assert replies == [None] * 6  # a damaged request is discarded, a damaged reply fails its CRC


def test_serve_command_answers_and_saves(tmp_path):
    state = tmp_path / "bus.json"
    with serve(tmp_path, "--state", str(state), "--modules", "1,3-4", "--framing", "crc16") as served:
        client = Client(served.url)
        try:
            assert client.send(4, WRITE_P10.encode()) == b"\x00\x00"
            assert client.send(2, b"\x50\x00") is None
        finally:
            client.close()
        # the journal holds the tail meanwhile
        assert load_state(state)[4].image.program(10) == WRITE_P10.program
    saved = json.loads(state.read_text())  # after a clean exit the state file holds everything
    assert [m["address"] for m in saved["modules"]] == [1, 3, 4]
    assert saved["modules"][2]["programs"][9] == WRITE_P10.program.to_json()
    assert not journal_path(state).exists()


def test_serve_with_modules_and_state_serves_exactly_those_and_keeps_the_others(tmp_path):
    state = tmp_path / "bus.json"
    kept = replace(ModuleState.factory(2), mode="run")
    state.write_text(json.dumps(state_document({**modules(1, 3), 2: kept})))
    with serve(tmp_path, "--state", str(state), "--modules", "3-4") as served:
        client = Client(served.url)
        try:
            assert client.send(1, b"\x50\x00") is None  # in the state file, not named
            assert client.send(4, WRITE_P10.encode()) == b"\x00\x00"  # named, not in the file: factory
        finally:
            client.close()
    saved = load_state(state)
    assert sorted(saved) == [1, 2, 3, 4]
    assert saved[2] == kept and saved[1] == ModuleState.factory(1)
    assert saved[4].image.program(10) == WRITE_P10.program


def busy_port() -> socket.socket:
    return socket.create_server(("127.0.0.1", 0))


@pytest.mark.parametrize(
    ("options", "says"),
    [
        (["--listen", "127.0.0.1:{busy}"], "cannot listen (Address already in use) — choose a free port"),
        (["--state", "{tmp}"], "is a directory — give an emulator state file, or a path where none is yet"),
        (["--state", "{tmp}/broken.json"],
         "broken.json:1:43: not valid JSON (Expecting value) — fix or delete it"),
        (["--state", "{tmp}/odd.json"],
         "odd.json: module 3: program 7: P = 12000 is outside 0..9999 — fix or delete the entry"),
    ],
)
def test_serve_errors_are_one_line(tmp_path, options, says):
    (tmp_path / "broken.json").write_text('{"format": "prc3-emulator/1", "modules": [')
    odd = ModuleState.factory(3).to_json()
    odd["programs"][6]["P"] = 12000
    (tmp_path / "odd.json").write_text(json.dumps({"format": "prc3-emulator/1", "modules": [odd]}))
    with busy_port() as busy:
        arguments = [o.format(tmp=tmp_path, busy=busy.getsockname()[1]) for o in options]
        result = subprocess.run(
            [sys.executable, "-m", "prc3cfg", "emulator", "serve", *arguments], capture_output=True,
                                text=True, timeout=30
        )
    assert result.returncode == 1
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("error: "), result.stderr
    assert says in result.stderr


@pytest.mark.parametrize(("options", "says"), [
    (["--max-connections", "0"], "Invalid value for '--max-connections': must be 1 or more"),
    (["--idle-timeout", "0"], "Invalid value for '--idle-timeout': 0 is less than 1ms"),
    (["--parity", "weird"], "Invalid value for '--parity': 'weird' is not one of none, odd, even"),
    (["--framing", "xyz"], "Invalid value for '--framing': 'xyz' is not one of crc16, open-driver, stx"),
    (["--zvz", "-1"], "Invalid value for '--zvz': '-1' is not a time — write seconds (30, 0.5) or with a "
                      "unit: 500ms, 5s, 2m, 1h"),
    (["--zvz", "nan"], "Invalid value for '--zvz'"),
    (["--turnaround", "nan"], "Invalid value for '--turnaround'"),
    (["--module-turnaround", "3"], "Invalid value for '--module-turnaround': '3' is not ADDRESSES=TIME — for "
                                   "example 3-5=40ms"),
    (["--module-turnaround", "31=5ms"], "Invalid value for '--module-turnaround': '31' is outside 1..30"),
    (["--module-turnaround", "3=11s"], "Invalid value for '--module-turnaround': '11s' is not a turnaround "
                                       "of 0..10 s"),
    (["--jitter", "-1ms"], "Invalid value for '--jitter'"),
    (["--line-speed", "0"], "Invalid value for '--line-speed': must be 1 or more"),
    (["--data-bits", "9"], "Invalid value for '--data-bits': 9 data bits cannot carry a PRC 3 frame"),
    (["--data-bits", "7"], "Invalid value for '--data-bits': 7 data bits cannot carry a PRC 3 frame"),
    (["--modules", "0-40"], "Invalid value for '--modules': '0-40' is outside 1..30 — module addresses are "
                            "1..30"),
    (["--modules", "1,,2"], "Invalid value for '--modules': '1,,2' has an empty entry — write addresses and "
                            "ranges between commas, e.g. 1,3-5"),
    (["--modules", "1,2,"], "Invalid value for '--modules': '1,2,' has an empty entry"),
    (["--modules", ""], "Invalid value for '--modules': '' has an empty entry"),
    (["--listen", "nonsense"], "Invalid value for '--listen': 'nonsense' is not HOST:PORT — for example "
                               "127.0.0.1:7001"),
    (["--listen", "127.0.0.1:70000"], "Invalid value for '--listen': '127.0.0.1:70000' is not HOST:PORT"),
    (["--listen", ""], "Invalid value for '--listen': '' is not HOST:PORT — for example 127.0.0.1:7001"),
])
def test_a_bad_option_value_is_a_usage_error(capsys, options, says):
    """A value no emulator can take is a usage error (exit 64), before anything starts (in this process:
    test_a_bad_option_value_is_a_usage_error_of_the_process runs one as a command of its own)."""
    result = run_cli(capsys, "emulator", "serve", "--listen", "127.0.0.1:0", *options)
    assert result.code == 64
    assert result.err.count("\n") == 1, result.err
    assert result.err.startswith("error: prc3cfg emulator serve: "), result.err
    assert says in result.err and result.out == ""


def test_a_bad_option_value_is_a_usage_error_of_the_process():
    result = subprocess.run([sys.executable, "-m", "prc3cfg", "emulator", "serve", "--listen", "127.0.0.1:0",
                             "--turnaround", "nan"],
                            capture_output=True, text=True, timeout=30)
    assert (result.returncode, result.stdout) == (64, "")
    assert (result.stderr.startswith("error: prc3cfg emulator serve: Invalid value for '--turnaround'")
            and result.stderr.count("\n") == 1)


def state_file(path, *entries: dict):
    path.write_text(json.dumps({"format": "prc3-emulator/1", "modules": list(entries)}))
    return path


def module_3(change) -> dict:
    """Module 3's state-file entry at factory defaults, after `change(entry)`."""
    data = ModuleState.factory(3).to_json()
    change(data)
    return data


@pytest.mark.parametrize(
    ("change", "says"),
    [
        (lambda m: m["programs"][6].update(P=12000), "module 3: program 7: P = 12000 is outside 0..9999"),
        (lambda m: m["programs"][0].update(V=0), "module 3: program 1: V = 0 is outside 1..600"),
        (lambda m: m["programs"][1].update(Vr=-601), "module 3: program 2: Vr = -601 is outside -600..600"),
        (lambda m: m["programs"][63].update(A=65), "module 3: program 64: A = 65 is outside 0..64"),
        (lambda m: m["programs"][2].update(T=1.5),
         "module 3: program 3: T is 1.5, where a whole number belongs"),
        (lambda m: m["programs"][2].update(F1=True),
         "module 3: program 3: F1 is true, where a whole number belongs"),
        (lambda m: m["programs"][4].pop("F2"), 'module 3: program 5 has no "F2"'),
        (lambda m: m["programs"].__setitem__(8, None), "module 3: program 9 is null, where an "
                                                       "object belongs"),
        (lambda m: m["programs"].pop(), "module 3: programs is a list of 63, where a list of 64 belongs"),
        (lambda m: m["system"].update(S6=999), "module 3: system: S6 = 999 is outside 1000..1500"),
        (lambda m: m["system"].update(S1=70000), "module 3: system: S1 = 70000 is outside 100..9999"),
        (lambda m: m["system"].update(S1="400"),
         'module 3: system: S1 is the text "400", where a whole number belongs'),
        (lambda m: m["system"].pop("S12"), 'module 3: system has no "S12"'),
        (lambda m: m.update(address=40), "module entry 0: address S9 = 40 is outside 1..30"),
        (lambda m: m.update(mode="flying"),
         'module 3: mode is the text "flying", where "stop", "run" or "manual" belongs'),
        (lambda m: m.update(fault=["E09"]), "module 3: fault is a list, where text or null belongs"),
        (lambda m: m.update(fault="E99"),
         'module 3: fault is the text "E99", where "E09", "E10", "E12", "E20", "E21", "E22", "E23", "E24", '
                                          '"E25", "fault" or null belongs'),
        (lambda m: m.update(active_program=65), "module 3: active_program = 65 is outside 1..64"),
        (lambda m: m.update(active_program="3"),
         'module 3: active_program is the text "3", where a whole number or null belongs'),
        (lambda m: m.update(referenced="yes"),
         'module 3: referenced is the text "yes", where true or false belongs'),
    ],
)
def test_state_file_values_no_message_can_carry_are_refused_naming_module_and_field(tmp_path, change, says):
    path = state_file(tmp_path / "state.json", module_3(change))
    with pytest.raises(UserError) as refused:
        load_state(path)
    assert str(refused.value) == f"{path}: {says} — fix or delete the entry"


def test_state_file_may_hold_what_odd_history_leaves(tmp_path):
    """Only each value's own range is checked: a Teach In can leave P above S1, and so on."""

    def odd(m: dict) -> None:
        m["system"].update(S1=100, S4=20, S5=30)
        m["programs"][0].update(P=9999, V=600)
        m.update(mode="run", active_program=4, fault="E09", referenced=False)

    loaded = load_state(state_file(tmp_path / "state.json", module_3(odd)))
    assert loaded == {3: ModuleState.from_json(module_3(odd))}
    assert loaded[3].image.program(1) == Program(P=9999, V=600)


@pytest.mark.parametrize(("parity", "undetected"), [("even", False), ("none", True)])
def test_corruption_on_open_driver_respects_parity(parity, undetected):
    """A flipped bit on a line with parity is a parity error the UART drops: the module then sees a
    message one byte short (refused as damaged), never a valid different one. Without parity it can."""
    line = LineSettings(parity=parity)
    with Emulator(modules(1), framing="open-driver", line=line,
                  faults=FaultInjection(corrupt_rate=1.0, seed=5)) as emulator:
        outcomes = set()
        for n in range(1, 301):
            before = emulator.module(1).image
            message = codec.WriteSpeeds(((n % 64 + 1, 100 + n % 300),))
            emulator.exchange(Frame(Direction.REQUEST, 1, message.encode()), 0.0)
            after = emulator.module(1).image
            intended = device_after(before, message)
            outcomes.add("unchanged" if after == before else "intended" if after == intended else "other")
    assert outcomes >= {"unchanged", "intended"}  # damaged requests, and damaged replies to executed ones
    assert ("other" in outcomes) is undetected


def device_after(image, message):
    return device.execute(ModuleState(image), message).image


def test_a_damaged_reply_with_parity_is_a_character_short():
    with Emulator(modules(1), framing="open-driver",
                  faults=FaultInjection(corrupt_rate=1.0, seed=2)) as emulator:
        replies = [emulator.exchange(Frame(Direction.REQUEST, 1, b"\x50\x00"), 0.0) for _ in range(40)]
    whole = 1 + 2 * 11  # address and the 11 words of 50h's reply
    # a damaged reply lacks a character; a damaged request (one byte short) is answered with a code word
    assert {len(r) for r in replies if r is not None} == {whole - 1, 1 + 2}


class Scripted:
    """A connection as the server uses it, whose client sends `chunks` with a silence after each
    (a receive that times out), then hangs up; what the server sends back is kept in `sent`."""

    def __init__(self, *chunks: bytes) -> None:
        self.incoming: list[bytes | None] = [item for chunk in chunks for item in (chunk, None)]
        self.sent: list[bytes] = []

    def recv(self, size: int) -> bytes:
        if not self.incoming:
            return b""
        if (item := self.incoming.pop(0)) is None:
            raise TimeoutError
        return item

    def sendall(self, data: bytes) -> None:
        self.sent.append(data)

    def settimeout(self, timeout: float) -> None:
        pass

    def setsockopt(self, *option: int) -> None:
        pass

    def close(self) -> None:
        pass


@pytest.fixture
def slow_clock(monkeypatch):
    """The server's clock moves a second every time it is read: every silence is far longer than
    any inter-character or message time-out."""
    seconds = itertools.count()
    monkeypatch.setattr(server, "time",
                        SimpleNamespace(monotonic=lambda: float(next(seconds)), sleep=time.sleep))


@pytest.mark.parametrize("framing", ["crc16", "stx"])
def test_a_request_split_by_a_pause_over_tcp_is_answered(framing, slow_clock):
    """TCP connections are decoded with uart=False: half a request, a pause, the other half is one request."""
    encoding = get_framing(framing)
    frame = encoding.encode(Direction.REQUEST, 1, READ_SYSTEM.encode())
    conn = Scripted(frame[:4], frame[4:])
    with Emulator(modules(1), framing=framing) as emulator:
        emulator._serve_socket(conn, "scripted")
    assert conn.sent == [encoding.encode(Direction.REPLY, 1, codec.SystemReply(DEFAULT_SYSTEM, 1).encode())]


@pytest.mark.parametrize("framing", ["crc16", "stx"])
def test_a_request_split_by_a_pause_on_a_uart_is_discarded(framing, slow_clock):
    """The pty is a UART: there the same pause breaks the frame, which the module never answers."""
    frame = get_framing(framing).encode(Direction.REQUEST, 1, READ_SYSTEM.encode())
    conn = Scripted(frame[:4], frame[4:])

    def recv(timeout: float) -> bytes | None:
        try:
            return conn.recv(4096) or None
        except TimeoutError:
            return b""

    with Emulator(modules(1), framing=framing) as emulator:
        emulator._serve_stream(recv, conn.sendall, name="uart", uart=True)
    assert conn.sent == []


# -- the emulator as a service (the heavy acceptance tests are in test_emulator_service.py) ----

READ_SYSTEM = codec.ReadSystem()


def is_factory_system(conn: socket.socket, address: int) -> bool:
    reply = answered(conn, address, READ_SYSTEM.encode())
    return codec.decode_reply(READ_SYSTEM, reply) == codec.SystemReply(DEFAULT_SYSTEM, address)


def test_a_connection_beyond_the_limit_is_closed_at_once_and_a_freed_slot_serves_again(caplog):
    with Emulator(modules(1), max_connections=2) as emulator:
        address = emulator.listen()
        holders = [socket.create_connection(address, timeout=10) for _ in range(2)]
        assert all(is_factory_system(conn, 1) for conn in holders)  # both served: both slots taken
        with socket.create_connection(address, timeout=10) as third:
            assert third.recv(1) == b""
        hang_up(holders[0])
        with socket.create_connection(address, timeout=10) as fourth:
            assert is_factory_system(fourth, 1)
        hang_up(holders[1])
    assert "refused — the most connections allowed (2) are open" in caplog.text


def test_closed_connections_leave_no_threads_or_sockets_behind():
    with Emulator(modules(1)) as emulator:
        address = emulator.listen()
        for _ in range(200):
            conn = socket.create_connection(address, timeout=10)
            assert is_factory_system(conn, 1)
            hang_up(conn)
        assert not emulator._connections
        assert len(emulator._threads) < 10  # the accept loop, and perhaps a few threads finishing
        assert len(emulator._closers) == 1  # the listening socket


@pytest.mark.parametrize("sent", [b"", b"\xa5\x01"], ids=["silent", "stopped mid-frame"])
def test_an_idle_connection_is_closed_and_frees_its_slot(sent, caplog):
    with Emulator(modules(1), max_connections=1, idle_timeout=0.2) as emulator:
        address = emulator.listen()
        with socket.create_connection(address, timeout=10) as idle:
            idle.sendall(sent)
            assert idle.recv(1) == b""
        with socket.create_connection(address, timeout=10) as conn:
            assert is_factory_system(conn, 1)
    assert "nothing received for 0.2 s — closed (idle time-out)" in caplog.text


def test_a_client_that_takes_no_replies_is_disconnected():
    with Emulator(modules(1)) as emulator:
        with socket.socket() as conn:
            conn.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # replies pile up soon
            conn.settimeout(10)
            conn.connect(emulator.listen())
            request = get_framing("crc16").encode(Direction.REQUEST, 1, READ_SYSTEM.encode()) * 100
            with pytest.raises((BrokenPipeError, ConnectionResetError)):
                while True:
                    conn.sendall(request)


@pytest.mark.parametrize("breakage", ["state file is a folder", "folder is a file"])
def test_a_write_that_cannot_be_saved_is_not_answered_and_changes_nothing(tmp_path, caplog, breakage):
    folder = tmp_path / "emulators"
    state = folder / "bus.json"
    with Emulator(modules(1, 3), state_path=state) as emulator:
        with socket.create_connection(emulator.listen(), timeout=10) as conn:
            if breakage == "state file is a folder":
                state.unlink()
                state.mkdir()
            else:
                shutil.rmtree(folder)
                folder.write_text("")
            crc16 = get_framing("crc16")
            conn.sendall(crc16.encode(Direction.REQUEST, 0, codec.WriteSpeeds(((4, 123),)).encode()))
            conn.sendall(crc16.encode(Direction.REQUEST, 1, WRITE_P10.encode()))
            reply = answered(conn, 1, codec.ReadProgram(10).encode())  # the first reply: the read's
            assert codec.decode_reply(codec.ReadProgram(10),
                                      reply).programs == (ModuleState.factory(1).image.program(10),)
            assert emulator.modules() == modules(1, 3)
            with pytest.raises(OSError):
                emulator.update(1, mode="run")
            with pytest.raises(OSError):
                emulator.teach_in(3, 7, 321)
            assert emulator.modules() == modules(1, 3)
            if state.is_dir():
                state.rmdir()
            else:
                folder.unlink()
            assert answered(conn, 1, WRITE_P10.encode()) == b"\x00\x00"
    assert load_state(state) == {1: emulator.module(1), 3: ModuleState.factory(3)}
    assert load_state(state)[1].image.program(10) == WRITE_P10.program
    assert f"{state}: cannot save the emulator state file (" in caplog.text
    assert "the write to all modules (broadcast) is not answered and not applied" in caplog.text
    assert "the write to module 1 is not answered and not applied" in caplog.text
