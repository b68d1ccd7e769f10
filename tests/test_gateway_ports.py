"""One device behind two ports of one gateway: a real ser2net serving one emulator's pseudo-terminal
on a raw TCP port (`socket://`) and an RFC 2217 port (`rfc2217://`). Nothing the modules answer tells
two lines apart, so the machine says which ports are one line: `PRC3CFG_PORTS` lists the spellings of
one line with `|` between them (`prc3cfg.shell.sessions.machine_lines`), and a bus named by either has
the identities of both (`bus_line_keys`) — one lock, one record of what its modules hold: what an apply
through one port wrote is never taken for what the module still holds through the other."""

from __future__ import annotations

import contextlib
import os
import random
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from emulated import Result, run_cli
from test_serial_setup import free_port, listening, served_pty
from tools import needs, which

from prc3cfg.errors import UserError
from prc3cfg.shell.locks import line_keys
from prc3cfg.shell.plant_files import load_plant
from prc3cfg.shell.sessions import PORTS_VARIABLE, bus_line_keys, refuse_other_lines

SER2NET = which("ser2net")
needs_ser2net = needs("ser2net")

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
                                  f"  connector: serialdev,{pty},9600n81,local\n  options:\n    "
                                  "max-connections: 1\n"
                                  for name, accepter, port in (("raw", "tcp", raw),
                                                               ("rfc", "telnet(rfc2217),tcp", telnet))))
        ser2net = subprocess.Popen([SER2NET, "-n", "-c", config], stdout=subprocess.PIPE,
                                   stderr=subprocess.STDOUT, text=True)
        try:
            # ser2net says nothing once it listens: the socket table does
            while not (listening(raw) and listening(telnet)):
                with contextlib.suppress(subprocess.TimeoutExpired):
                    ser2net.wait(0.01)
                assert ser2net.returncode is None, ser2net.stdout.read()
            urls = (f"socket://127.0.0.1:{raw}", f"rfc2217://127.0.0.1:{telnet}?ign_set_control")
            SERVING[urls] = (ser2net.pid, os.path.realpath(pty))
            yield urls
        finally:
            SERVING.pop(urls, None)
            ser2net.terminate()
            ser2net.wait()
            ser2net.stdout.close()


#: The ser2net serving each pair of ports (`one_device_two_ports`): its pid and the device it opens for a
#: connection.
SERVING: dict[tuple[str, ...], tuple[int, str]] = {}


def holds(pid: int, device: str) -> bool:
    """Whether process `pid` has `device` open, as /proc says."""
    fds = Path(f"/proc/{pid}/fd")
    with contextlib.suppress(OSError):
        return any(os.path.realpath(fd) == device for fd in fds.iterdir())
    return False


def let_go(*urls: str) -> None:
    """Until ser2net has closed every connection to these ports, as the kernel's socket table says, and the
    device behind them, as /proc says: a connection it is still closing may hold the device open and take
    the next one's replies, and one accepted while it still holds it is dropped (a broken pipe)."""
    ports = {f"0100007F:{int(url.rpartition(':')[2].partition('?')[0]):04X}" for url in urls}
    while any(row.split()[1] in ports and row.split()[3] != "0A"
              for row in Path("/proc/net/tcp").read_text().splitlines()[1:]):
        os.sched_yield()
    if (serving := SERVING.get(urls)) is not None:
        while holds(*serving):
            os.sched_yield()


def through(capsys: pytest.CaptureFixture, ports: tuple[str, str], *args: object) -> Result:
    """`prc3cfg ARGS`, once ser2net let go of the device (`let_go`)."""
    let_go(*ports)
    return run_cli(capsys, *args)


def plant_file(path: Path, port: str, position: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(PLANT.format(port=port, position=position))
    return path


def one_line(monkeypatch: pytest.MonkeyPatch, ports: tuple[str, str]) -> None:
    """The machine's list of its lines says the two ports are one line."""
    monkeypatch.setenv(PORTS_VARIABLE, "|".join(ports))


@needs_ser2net
@pytest.mark.parametrize("first", ["socket", "rfc2217"])
def test_an_apply_through_one_port_is_seen_by_a_plan_through_the_other(tmp_path, capsys, monkeypatch, first):
    """The issue's case: applied through one port, planned through the other — not "No changes"."""
    with one_device_two_ports(tmp_path) as ports:
        one_line(monkeypatch, ports)
        this, other = ports if first == "socket" else ports[::-1]
        b = plant_file(tmp_path / "b" / "plant.yaml", this, "2.0")
        a = plant_file(tmp_path / "a" / "plant.yaml", other, "1.9")
        applied = through(capsys, ports, "apply", b, "--auto-approve", "--allow-axis-release")
        assert applied.code == 0, applied.err
        # the line's record knows the module
        assert through(capsys, ports, "plan", b, "--detailed-exitcode").code == 0
        # through the other port: position 1.9
        assert through(capsys, ports, "apply", a, "--auto-approve").code == 0
        planned = through(capsys, ports, "plan", b, "--detailed-exitcode")
        assert planned.code == 2, planned.out + planned.err
        assert "program 1: position 1.900 m → 2.000 m" in planned.out
        assert through(capsys, ports, "apply", b, "--auto-approve").code == 0
        back = through(capsys, ports, "plan", a, "--detailed-exitcode")  # and the other way round
        assert back.code == 2, back.out + back.err
        assert "program 1: position 2.000 m → 1.900 m" in back.out


@needs_ser2net
@pytest.mark.soak
@pytest.mark.parametrize("seed", range(8))
def test_applies_through_either_port_in_any_order_leave_no_silent_wrong_value(tmp_path, capsys, monkeypatch,
                                                                              seed):
    """A seeded run of applies through either port, each of its own plant file's position: every plan
    afterwards shows a change exactly where the module holds another position than its plant file."""
    rng = random.Random(seed)
    with one_device_two_ports(tmp_path) as ports:
        one_line(monkeypatch, ports)
        plants = {(port, position): plant_file(tmp_path / f"{n}-{position}" / "plant.yaml", port, position)
                  for n, port in enumerate(ports) for position in ("1.9", "2.0", "2.1")}
        for _ in range(4):  # an apply, then two plans, each through either port
            (_, held), plant = rng.choice(list(plants.items()))
            assert through(capsys, ports, "apply", plant, "--auto-approve", "--allow-axis-release").code == 0
            for (_, position), plant in rng.sample(list(plants.items()), 2):
                planned = through(capsys, ports, "plan", plant, "--detailed-exitcode")
                assert planned.code == (2 if held != position else 0), planned.out + planned.err


# ---- the spellings of one line, as the machine lists them (`sessions.machine_lines`) ----------------

RAW, TELNET, ELSEWHERE = "socket://127.0.0.1:4001", "rfc2217://127.0.0.1:4002", "socket://127.0.0.1:4003"


def keys_of(tmp_path: Path, port: str) -> tuple[str, ...]:
    plant = load_plant(plant_file(tmp_path / "plant.yaml", port, "2.0"))
    return bus_line_keys(plant, plant.buses[0])


def test_spellings_the_machine_lists_as_one_line_share_their_identities(tmp_path, monkeypatch):
    """Listed as one line, either port's bus has both ports' identities (one lock, one record); another
    line of the list, or no list, keeps a port's own."""
    assert keys_of(tmp_path, TELNET) == line_keys(TELNET)
    monkeypatch.setenv(PORTS_VARIABLE, f"{RAW} | {TELNET}; {ELSEWHERE}")
    both = set(line_keys(RAW) + line_keys(TELNET))
    assert set(keys_of(tmp_path, RAW)) == set(keys_of(tmp_path, TELNET)) == both
    assert keys_of(tmp_path, ELSEWHERE) == line_keys(ELSEWHERE)
    plant = load_plant(tmp_path / "plant.yaml")
    # either spelling is a line of the machine
    refuse_other_lines(plant, {plant.buses[0].name: keys_of(tmp_path, TELNET)})


def test_a_spelling_in_the_list_that_is_no_port_is_refused_in_one_line(tmp_path, monkeypatch):
    monkeypatch.setenv(PORTS_VARIABLE, f"{RAW} | {TELNET}\x1b[2J")
    with pytest.raises(UserError, match=rf"^{PORTS_VARIABLE}: ") as refused:
        keys_of(tmp_path, RAW)
    assert "\n" not in str(refused.value)
