"""The emulator as a service: a real `prc3cfg emulator serve` survives hostile and careless clients.

Acceptance (issue 10 item 7): it keeps answering correct replies during and after 1,100
connections at once, 100 MB of garbage and 20,000 connect/close cycles, and its RSS comes
back within 20 MB of where it stood after a warm-up; running out of file descriptors only
pauses it; a write it cannot save is neither answered nor applied. The acceptance's load is
the soak tier's; the fast tier's is a tenth of it, against a server with fewer files.

Nothing here waits by sleeping: a client knows the server has let go of a connection when,
after shutting down its own sending side, it reads the end of the stream — the server frees
a connection's slot before it closes it.
"""

from __future__ import annotations

import json
import random
import resource
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from typing import NamedTuple

import pytest
from emulator_client import Client, Served, answered, hang_up, serve

from prc3cfg.core import codec
from prc3cfg.core.framing import Direction, get_framing
from prc3cfg.core.image import DEFAULT_SYSTEM, Program

MAX_CONNECTIONS = 64
GARBAGE_CONNECTIONS = 4
CHURN_WORKERS = 8
RSS_SLACK_KIB = 20_000_000 // 1024  # 20 MB


class Load(NamedTuple):
    flood: int  # connections at once
    garbage: int  # bytes
    churn: int  # connect/close cycles
    server_files: int  # the server's RLIMIT_NOFILE: below the flood


LOADS = [
    pytest.param(Load(flood=300, garbage=10_000_000, churn=2_000, server_files=256), id="fast"),
    pytest.param(Load(flood=1_100, garbage=100_000_000, churn=20_000, server_files=1024), id="acceptance",
                 marks=pytest.mark.soak),
]
REPLY_TIMEOUT = 10.0  # s a client waits for a reply that must come: only a failing test waits it out


def factory_reply(client: Client, address: int) -> bool:
    """Whether a 50h read of `address` is answered, and with the factory's system parameters."""
    reply = client.send(address, codec.ReadSystem().encode())
    return (reply is not None
            and codec.decode_reply(codec.ReadSystem(), reply) == codec.SystemReply(DEFAULT_SYSTEM, address))


def connect(served: Served) -> socket.socket:
    conn = socket.create_connection(("127.0.0.1", served.port))
    conn.settimeout(REPLY_TIMEOUT)
    return conn


def is_open(conn: socket.socket) -> bool:
    """Whether the server still holds `conn` open (nothing to read, no end of stream)."""
    conn.setblocking(False)
    try:
        return conn.recv(1, socket.MSG_PEEK) != b""
    except BlockingIOError:
        return True
    finally:
        conn.settimeout(REPLY_TIMEOUT)


def garbage_block(seed: int, size: int = 1_000_000) -> bytes:
    """Bytes no crc16 receiver can take a request from: random bytes without the A5h start code,
    with a request frame every 4 KiB whose CRC is wrong."""
    rng = random.Random(seed)
    framing = get_framing("crc16")
    out = bytearray()
    while len(out) < size:
        out += rng.randbytes(4096).replace(b"\xa5", b"\xa4")
        frame = bytearray(framing.encode(Direction.REQUEST, rng.randrange(1, 31),
                                         rng.randbytes(rng.randrange(1, 65))))
        frame[-1] ^= 0x01
        out += frame
    return bytes(out[:size])


def while_running(workers: list[threading.Thread], good: Client) -> int:
    """Start `workers`, read module after module with `good` until they end; the number of reads."""
    for worker in workers:
        worker.start()
    reads = 0
    while any(worker.is_alive() for worker in workers):
        assert factory_reply(good, 1 + reads % 30)
        reads += 1
    for worker in workers:
        worker.join()
    return reads


def flood(served: Served, count: int, good: Client) -> None:
    """`count` connections at once: as many as there are free slots are served (the good client
    holds one), the rest closed at once; the good client is answered meanwhile and after."""
    conns = [connect(served) for _ in range(count)]
    kept, refused = conns[: MAX_CONNECTIONS - 1], conns[MAX_CONNECTIONS - 1 :]
    assert all(conn.recv(1) == b"" for conn in refused)
    assert all(is_open(conn) for conn in kept)
    assert factory_reply(good, 7)
    assert served.open_fds() <= MAX_CONNECTIONS + 16  # within its own limit, whatever the clients do
    assert served.threads() <= MAX_CONNECTIONS + 8
    for conn in refused:
        conn.close()
    for conn in kept:
        hang_up(conn)
    assert factory_reply(good, 8)


def churn(served: Served, cycles: int) -> None:
    for _ in range(cycles):
        hang_up(connect(served))


@pytest.fixture
def many_files(load: Load) -> Iterator[None]:
    """This process may hold the flood's sockets: the soft RLIMIT_NOFILE raised to the hard one if need be."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    needed = load.flood + 256
    if soft != resource.RLIM_INFINITY and soft < needed:
        if hard != resource.RLIM_INFINITY and hard < needed:
            pytest.skip(f"RLIMIT_NOFILE hard limit {hard} is below the {needed} this test needs")
        resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    yield
    resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))


@pytest.mark.parametrize("load", LOADS)
def test_keeps_answering_through_a_flood_garbage_and_churn_and_gives_its_memory_back(tmp_path, load,
                                                                                     many_files):
    with serve(tmp_path, "--modules", "1-30", "--max-connections", str(MAX_CONNECTIONS)) as served:
        _, hard = resource.prlimit(served.process.pid, resource.RLIMIT_NOFILE)
        resource.prlimit(served.process.pid, resource.RLIMIT_NOFILE, (load.server_files, hard))
        # before the flood: a low fd, which pyserial's select() needs
        good = Client(served.url, timeout=REPLY_TIMEOUT)
        try:
            # warm-up: every kind of work once, so the baseline holds what the server keeps for it
            flood(served, 200, good)
            churn(served, 500)
            conn = connect(served)
            conn.sendall(garbage_block(0))
            hang_up(conn)  # once the server has read it all: its slot is free for the flood
            assert factory_reply(good, 1)
            baseline = served.rss_kib()

            # the flood, all at once: the first 63 are served (the good client holds a slot), the rest closed
            # at once
            flood(served, load.flood, good)
            fresh = Client(served.url, timeout=REPLY_TIMEOUT)
            try:
                assert factory_reply(fresh, 9)
            finally:
                fresh.close()

            # garbage in a few connections, and a crc16 frame that never ends
            never_ends = connect(served)
            never_ends.sendall(b"\xa5\x05\xff" + bytes(100))  # announces 256 bytes, sends 100
            block = garbage_block(1)

            def send_garbage() -> None:
                conn = connect(served)
                for _ in range(load.garbage // GARBAGE_CONNECTIONS // len(block)):
                    conn.sendall(block)
                hang_up(conn)  # the server has read every byte

            reads = while_running([threading.Thread(target=send_garbage) for _ in range(GARBAGE_CONNECTIONS)],
                                  good)
            assert reads > 0
            assert is_open(never_ends)
            hang_up(never_ends)

            # connect/close cycles
            workers = [threading.Thread(target=churn, args=(served, load.churn // CHURN_WORKERS))
                       for _ in range(CHURN_WORKERS)]
            reads = while_running(workers, good)
            assert reads > 0

            write = codec.WriteProgram(3, Program(P=123, V=45))
            assert good.send(5, write.encode()) == b"\x00\x00"  # still a whole module behind the line
            after = served.rss_kib()
        finally:
            good.close()
        log = served.log.read_text()
    assert after - baseline <= RSS_SLACK_KIB, f"RSS {baseline} KiB after the warm-up, {after} KiB at the end"
    assert log.count("refused") >= load.flood - MAX_CONNECTIONS + 1
    assert "Traceback" not in log and "cannot accept" not in log  # it never ran out of file descriptors


def logged(served: Served, text: str, polls: int = 2_000) -> None:
    """Once the emulator's log says `text` (a bounded number of looks, 10 ms apart: on what the process
    printed)."""
    for _ in range(polls):
        if text in served.log.read_text():
            return
        time.sleep(0.01)
    raise AssertionError(f"the log never said {text!r}:\n{served.log.read_text()}")


def test_running_out_of_file_descriptors_only_pauses_accepting(tmp_path):
    with serve(tmp_path, "--modules", "1", "--max-connections", "16") as served:
        spare = 3
        _, hard = resource.prlimit(served.process.pid, resource.RLIMIT_NOFILE)
        resource.prlimit(served.process.pid, resource.RLIMIT_NOFILE, (served.open_fds() + spare, hard))
        # all connected; the kernel holds those not accepted
        waiting = [connect(served) for _ in range(3 * spare + 1)]
        read_system = codec.ReadSystem().encode()
        first = True
        while waiting:
            batch, waiting = waiting[:spare], waiting[spare:]
            for conn in batch:  # served while the next ones wait on a full descriptor table
                reply = answered(conn, 1, read_system)
                assert codec.decode_reply(codec.ReadSystem(), reply) == codec.SystemReply(DEFAULT_SYSTEM, 1)
            # the table is full now: held open until the server says it cannot accept the next — on a
            if first:
                # busy machine its accept may come after a hang-up else
                logged(served, "cannot accept a connection")
                first = False
            for conn in batch:
                hang_up(conn)
        log = served.log.read_text()
    assert "cannot accept a connection (Too many open files)" in log
    assert "accepting connections again" in log
    assert "Traceback" not in log


def test_a_write_that_cannot_be_saved_is_neither_answered_nor_applied(tmp_path):
    state = tmp_path / "bus.json"
    first, refused, last = (codec.WriteProgram(n, Program(P=p, V=100))
                            for n, p in ((4, 111), (4, 222), (6, 333)))
    read_4, read_system = codec.ReadProgram(4), codec.ReadSystem()
    with serve(tmp_path, "--state", str(state), "--modules", "1-3") as served:
        with connect(served) as conn:
            assert answered(conn, 2, first.encode()) == b"\x00\x00"
            state.unlink()
            state.mkdir()  # the state file is now a folder: root or not, nothing can be saved there
            conn.sendall(get_framing("crc16").encode(Direction.REQUEST, 2, refused.encode()))
            # the first reply is the read's behind the write, and shows program 4 as it was
            assert codec.decode_reply(read_4, answered(conn, 2, read_4.encode())).programs == (first.program,)
            log = served.log.read_text()
            assert f"{state}: cannot save the emulator state file (Is a directory)" in log
            assert "the write to module 2 is not answered and not applied" in log
            assert codec.decode_reply(read_system,
                                      answered(conn, 3, read_system.encode())).system == DEFAULT_SYSTEM
            state.rmdir()
            assert answered(conn, 2, last.encode()) == b"\x00\x00"
            hang_up(conn)
        assert served.process.poll() is None
    saved = {m["address"]: m for m in json.loads(state.read_text())["modules"]}
    assert sorted(saved) == [1, 2, 3]
    assert saved[2]["programs"][3] == first.program.to_json()
    assert saved[2]["programs"][5] == last.program.to_json()


ONE_MODULE_PLANT = """\
plant: busy
buses:
  - name: booth-a
    port: socket://127.0.0.1:{port}
    framing: crc16
    timeout: 0.2
    modules:
      - address: 1
        name: left
"""


def test_one_client_per_line_by_default_and_the_next_is_told_the_gateway_is_busy(tmp_path):
    """As ser2net's one connection per port: a second client is closed at once, and prc3cfg says
    why in one line; once the first hangs up, the next is served."""
    plant = tmp_path / "plant.yaml"
    read_system = codec.ReadSystem().encode()
    with serve(tmp_path, "--modules", "1") as served:
        plant.write_text(ONE_MODULE_PLANT.format(port=served.port))
        with connect(served) as holder:
            assert codec.decode_reply(codec.ReadSystem(),
                                      answered(holder, 1, read_system)).system == DEFAULT_SYSTEM
            with connect(served) as second:
                assert second.recv(1) == b""  # closed at once
            result = subprocess.run([sys.executable, "-m", "prc3cfg", "read", str(plant)],
                                    capture_output=True, text=True)
            assert result.returncode == 1, result
            busy = "error: bus booth-a: the gateway is busy: another client holds the line"
            assert result.stderr.count("\n") == 1 and result.stderr.startswith(busy), result.stderr
            hang_up(holder)
        result = subprocess.run([sys.executable, "-m", "prc3cfg", "read", str(plant)], capture_output=True,
                                text=True)
        assert result.returncode == 0, result.stderr
        log = served.log.read_text()
    assert log.count("refused — the most connections allowed (1) are open") == 2
