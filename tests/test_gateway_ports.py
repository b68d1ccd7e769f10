"""One device behind two ports of one gateway: a real ser2net serving one emulator's pseudo-terminal
on a raw TCP port (`socket://`) and an RFC 2217 port (`rfc2217://`). The two spellings are two
identities of the line (`prc3cfg.shell.locks.line_keys`), each with its own record; a plan through
one consults the records of the gateway's other ports (`prc3cfg.shell.bases`), so what an apply
through the other port wrote is never taken for what the module still holds."""

from __future__ import annotations

import contextlib
import os
import random
import shutil
import subprocess
import tempfile
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest
from emulated import Result, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_serial_setup import free_port, listening, served_pty

from prc3cfg.core.image import ModuleImage
from prc3cfg.core.what_to_read import Known
from prc3cfg.shell import bases, locks

SER2NET = shutil.which("ser2net")
needs_ser2net = pytest.mark.skipif(SER2NET is None, reason="ser2net is not installed (apt-get install -y ser2net)")

PLANT = """plant: p
buses:
  - name: line
    port: {port}
    parity: none
    modules:
      - address: 1
        name: m1
        system: {{upper_reversing_point: 2.2}}
        programs:
          1: {{position: {position}, speed: 0.35}}
"""


@contextlib.contextmanager
def one_device_two_ports(tmp_path: Path) -> Iterator[tuple[str, str]]:
    """ser2net 4 serving one emulated pty on a raw TCP port and an RFC 2217 port: the two ports' URLs."""
    raw, telnet = free_port(), free_port()
    with served_pty() as pty:
        config = tmp_path / "ser2net.yaml"
        config.write_text("".join(f"connection: &{name}\n  accepter: {accepter},127.0.0.1,{port}\n"
                                  f"  connector: serialdev,{pty},9600n81,local\n  options:\n    max-connections: 1\n"
                                  for name, accepter, port in (("raw", "tcp", raw), ("rfc", "telnet(rfc2217),tcp", telnet))))  # fmt: skip
        ser2net = subprocess.Popen([SER2NET, "-n", "-c", config], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            while not (listening(raw) and listening(telnet)):  # ser2net says nothing once it listens: the socket table does
                with contextlib.suppress(subprocess.TimeoutExpired):
                    ser2net.wait(0.01)
                assert ser2net.returncode is None, ser2net.stdout.read()
            yield f"socket://127.0.0.1:{raw}", f"rfc2217://127.0.0.1:{telnet}?ign_set_control"
        finally:
            ser2net.terminate()
            ser2net.wait()
            ser2net.stdout.close()


def let_go(*urls: str) -> None:
    """Until ser2net has closed every connection to these ports, as the kernel's socket table says: a
    connection it is still closing may hold the device open and take the next one's replies."""
    ports = {f"0100007F:{int(url.rpartition(':')[2].partition('?')[0]):04X}" for url in urls}
    while any(row.split()[1] in ports and row.split()[3] != "0A" for row in Path("/proc/net/tcp").read_text().splitlines()[1:]):
        os.sched_yield()


def through(capsys: pytest.CaptureFixture, ports: tuple[str, str], *args: object) -> Result:
    """`prc3cfg ARGS`, once ser2net let go of the device (`let_go`)."""
    let_go(*ports)
    return run_cli(capsys, *args)


def plant_file(path: Path, port: str, position: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(PLANT.format(port=port, position=position))
    return path


@needs_ser2net
@pytest.mark.parametrize("first", ["socket", "rfc2217"])
def test_an_apply_through_one_port_is_seen_by_a_plan_through_the_other(tmp_path, capsys, first):
    """The issue's case: applied through one port, planned through the other — not "No changes"."""
    with one_device_two_ports(tmp_path) as ports:
        this, other = ports if first == "socket" else ports[::-1]
        b = plant_file(tmp_path / "b" / "plant.yaml", this, "2.0")
        a = plant_file(tmp_path / "a" / "plant.yaml", other, "1.9")
        applied = through(capsys, ports, "apply", b, "--auto-approve", "--allow-axis-release")
        assert applied.code == 0, applied.err
        assert through(capsys, ports, "plan", b, "--detailed-exitcode").code == 0  # B's line record knows the module
        assert through(capsys, ports, "apply", a, "--auto-approve").code == 0  # through the other port: position 1.9
        planned = through(capsys, ports, "plan", b, "--detailed-exitcode")
        assert planned.code == 2, planned.out + planned.err
        assert "program 1: position 1.900 m → 2.000 m" in planned.out
        assert "read in full: line/m1 (a record of another port of this gateway is newer" in planned.out
        assert through(capsys, ports, "apply", b, "--auto-approve").code == 0
        back = through(capsys, ports, "plan", a, "--detailed-exitcode")  # and the other way round
        assert back.code == 2, back.out + back.err
        assert "program 1: position 2.000 m → 1.900 m" in back.out


@needs_ser2net
@pytest.mark.soak
@pytest.mark.parametrize("seed", range(8))
def test_applies_through_either_port_in_any_order_leave_no_silent_wrong_value(tmp_path, capsys, seed):
    """A seeded run of applies through either port, each of its own plant file's position: every plan
    afterwards shows a change exactly where the module holds another position than its plant file."""
    rng = random.Random(seed)
    with one_device_two_ports(tmp_path) as ports:
        plants = {(port, position): plant_file(tmp_path / f"{n}-{position}" / "plant.yaml", port, position)
                  for n, port in enumerate(ports) for position in ("1.9", "2.0", "2.1")}  # fmt: skip
        for _ in range(4):  # an apply, then two plans, each through either port
            (_, held), plant = rng.choice(list(plants.items()))
            assert through(capsys, ports, "apply", plant, "--auto-approve", "--allow-axis-release").code == 0
            for (_, position), plant in rng.sample(list(plants.items()), 2):
                planned = through(capsys, ports, "plan", plant, "--detailed-exitcode")
                assert planned.code == (2 if held != position else 0), planned.out + planned.err


# ---- the records of one gateway's ports, as files (`bases.read`) ---------------------------------

GATEWAY = {port: (f"tcp/127.0.0.1/{port}",) for port in (4001, 4002)}  # one ser2net: the same device behind both
ELSEWHERE = ("tcp/127.0.0.2/4001",)  # another gateway
DEVICE = ("dev/ttyUSB0",)  # a local device: no gateway


def image(address: int, position: int) -> ModuleImage:
    factory = ModuleImage.factory(address)
    return factory.with_programs({1: replace(factory.known(1), P=position)})


def wrote(keys: tuple[str, ...], address: int, position: int | None) -> None:
    """What an apply (a position) or its forget before the first write (None) leaves in the line's record."""
    bases.update(keys, {address: None if position is None else Known(image(address, position), bases.now(), "apply of p.yaml by ana@pc")})


def test_a_newer_record_of_another_port_of_the_gateway_makes_the_module_read():
    wrote(GATEWAY[4002], 1, 200)
    wrote(GATEWAY[4001], 1, 150)
    known, overruled = bases.read(GATEWAY[4002])
    assert 1 not in known
    assert overruled[1].startswith("a record of another port of this gateway is newer (tcp/127.0.0.1/4001: apply of p.yaml by ana@pc, ")
    assert overruled[1].endswith(") — one device may be behind both ports")
    assert bases.read(GATEWAY[4001])[0][1].image == image(1, 150)  # the newest is believed where it was written


@pytest.mark.parametrize("other, position", [
    (GATEWAY[4001], 200),  # another port, the same image: nothing changed that this record does not say
    (ELSEWHERE, 150),  # the same port number of another gateway
    (DEVICE, 150),  # a local device is no gateway's port
])  # fmt: skip
def test_a_record_that_says_nothing_new_of_this_port_s_module_leaves_it_known(other, position):
    wrote(GATEWAY[4002], 1, 200)
    wrote(other, 1, position)
    known, overruled = bases.read(GATEWAY[4002])
    assert known[1].image == image(1, 200) and overruled == {}


def test_an_older_record_of_another_port_or_another_module_s_leaves_this_one_known():
    wrote(GATEWAY[4001], 1, 150)
    wrote(GATEWAY[4001], 2, 150)
    wrote(GATEWAY[4002], 1, 200)
    known, overruled = bases.read(GATEWAY[4002])
    assert known[1].image == image(1, 200) and overruled == {}


def test_a_record_under_another_port_s_name_says_nothing_of_the_port_it_names(tmp_path):
    """A file whose key is not the one its name is made of (copied, planted) is no record of either port."""
    wrote(GATEWAY[4002], 1, 200)
    wrote(GATEWAY[4001], 1, 150)
    lines = tmp_path / "state" / bases.KIND
    (mine,) = lines.glob(f"{bases._stem(GATEWAY[4002][0])}.*.json")
    (theirs,) = lines.glob(f"{bases._stem(GATEWAY[4001][0])}.*.json")
    theirs.rename(lines / f"{bases._stem(ELSEWHERE[0])}.{theirs.name.partition('.')[2]}")
    assert bases.read(GATEWAY[4002])[0][1].image == image(1, 200)
    assert mine.exists()


def test_the_address_and_port_of_an_identity():
    assert locks.gateway_port("tcp/127.0.0.1/4001") == ("127.0.0.1", "4001")
    assert locks.gateway_port("tcp/::1/4001") == ("::1", "4001")
    assert locks.gateway_port("tcp/plc-gw.example/4001") == ("plc-gw.example", "4001")
    assert [locks.gateway_port(key) for key in ("dev/ttyUSB0", "emulator//s/a.json", "socket://h:x", "tcp//4001")] == [None] * 4


OPERATIONS = st.lists(st.tuples(st.sampled_from([*GATEWAY, "elsewhere"]), st.integers(1, 2), st.sampled_from([None, 150, 200, 250])),
                      max_size=12)  # fmt: skip


def no_silent_wrong_value(operations: list[tuple[int | str, int, int | None]]) -> None:
    """Writes through either port of one gateway (one device behind both) and through another gateway's:
    what a port's record says a module holds is what the last write through either port left, or not
    known; and a module last written through this port is known."""
    with tempfile.TemporaryDirectory() as state:
        os.environ["PRC3CFG_STATE_DIR"] = state
        held: dict[int, int | None] = {}
        last: dict[int, int | str] = {}
        for port, address, position in operations:
            wrote(ELSEWHERE if port == "elsewhere" else GATEWAY[port], address, position)  # type: ignore[index]
            if port != "elsewhere":
                held[address], last[address] = position, port
        for port, keys in GATEWAY.items():
            known, _ = bases.read(keys)
            for address, k in known.items():
                assert k.image == image(address, held[address])  # type: ignore[arg-type]
            assert all(address in known for address, through in last.items() if through == port and held[address] is not None)


@given(OPERATIONS)
@settings(max_examples=40, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_no_silent_wrong_value_through_either_port(operations):
    no_silent_wrong_value(operations)


@pytest.mark.soak
@given(OPERATIONS)
@settings(suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_no_silent_wrong_value_through_either_port_many(operations):
    no_silent_wrong_value(operations)
