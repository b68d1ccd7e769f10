"""The reply deadline comes from the line: each exchange waits as long as its frames take at the line's baud
and character format, the module's turnaround and a margin — the plant file's `timeout` only adds to that. The
deadline as a table of cases (`LineCost.reply_deadline`), and the workflow of the README and docs/commands.md
(plan, apply, read, import, doctor) on a real `prc3cfg emulator serve --rfc2217` that answers at line speed,
with zero exchanges lost."""

from __future__ import annotations

from pathlib import Path

import pytest
from emulated import run_cli
from emulator_client import serve
from hypothesis import given, settings
from hypothesis import strategies as st
from test_codec_properties import MESSAGE_STRATEGIES
from test_framing_properties import lines

from prc3cfg.core import codec
from prc3cfg.core.bustime import DEADLINE_MARGIN, LineCost
from prc3cfg.core.device import ModuleState
from prc3cfg.core.framing import Direction, get_framing
from prc3cfg.core.image import Program
from prc3cfg.core.line import LineSettings
from prc3cfg.shell.emulator.server import Emulator
from prc3cfg.shell.link.client import Link
from prc3cfg.shell.link.ports import open_port

READ_FOUR = codec.ReadPrograms(1, 4)
WRITE_ONE = codec.WriteProgram(1, Program(P=100, V=200, Vr=0, T=0, F1=0, F2=0, A=0))
L_8E1, L_8N1, L_8O2 = LineSettings(1200, 8, "even", 1), LineSettings(9600, 8, "none",
                                                                     1), LineSettings(300, 8, "odd", 2)


def seconds(chars: int, bits: float, baud: int, turnaround: float = 0.010, gaps: float = 0.0) -> float:
    """What a deadline must be: the characters at their bits and baud, with the margin, the turnaround and the
    gaps."""
    return chars * bits / baud * (1 + DEADLINE_MARGIN) + turnaround + gaps


@pytest.mark.parametrize(("message", "framing", "line", "expected"), [
    # 52h of four programs: a 9-byte request frame (4 + crc16's 5), a 69-byte reply (64 + 5)
    pytest.param(READ_FOUR, "crc16", L_8E1, seconds(9 + 69, 11, 1200), id="52h x4, crc16, 1200 8E1: 0.80 s"),
    pytest.param(codec.ReadSystem(), "crc16", L_8E1, seconds(7 + 27, 11, 1200), id="50h, crc16, 1200 8E1"),
    pytest.param(codec.ReadProgram(5), "crc16", L_8N1, seconds(7 + 21, 10, 9600), id="51h, crc16, 9600 8N1"),
    # a write's reply is its code word: 2 bytes in the frame
    pytest.param(WRITE_ONE, "crc16", L_8O2, seconds(WRITE_ONE.size() + 5 + 2 + 5, 12, 300),
                 id="21h, crc16, 300 8O2"),
    # stx: 4 bytes of overhead; the request's stuffing as its bytes make it (none here), the reply's at worst
    # every byte after 7Eh
    pytest.param(READ_FOUR, "stx", L_8E1, seconds(8 + 68 + 67, 11, 1200), id="52h x4, stx, 1200 8E1"),
    pytest.param(codec.ReadSystem(), "stx", L_8N1, seconds(6 + 26 + 25, 10, 9600), id="50h, stx, 9600 8N1"),
    # open-driver: the address byte only, and a ZVZ of silence after each frame
    pytest.param(READ_FOUR, "open-driver", L_8E1, seconds(5 + 65, 11, 1200, gaps=2 * 0.020),
                 id="52h x4, open-driver, 1200 8E1"),
    pytest.param(codec.ReadSystem(), "open-driver", L_8O2, seconds(3 + 23, 12, 300, gaps=2 * 0.020),
                 id="50h, open-driver, 300 8O2"),
])
def test_the_deadline_of_each_message_kind_comes_from_the_line(message, framing, line, expected):
    cost = LineCost.of(framing, line, 0.010, 0.020)
    assert cost.reply_deadline(1, message) == pytest.approx(expected, abs=1e-9)


def no_reply_comes_later(framing: str, line: LineSettings, address: int, message: codec.Message,
                         reply: bytes) -> None:
    """The deadline is never shorter than what any reply the message can have takes on the line — its
    frame as the framing encodes those bytes (stx stuffing them as they are), after the request frame
    and the turnaround: as long as the emulator at line speed takes to answer."""
    cost = LineCost.of(framing, line, 0.010, 0.020)
    encoded = get_framing(framing)
    taken = (len(encoded.encode(Direction.REQUEST, address, message.encode()))
             + len(encoded.encode(Direction.REPLY, address, reply)))
    gaps = 2 * 0.020 if framing == "open-driver" else 0.0
    assert cost.reply_deadline(address, message) >= taken * line.char_time + 0.010 + gaps


messages = st.sampled_from(list(MESSAGE_STRATEGIES)).flatmap(lambda kind: MESSAGE_STRATEGIES[kind])
exchanges = st.tuples(st.sampled_from(["crc16", "stx", "open-driver"]), lines, st.integers(1, 30), messages)


def replies(message: codec.Message) -> st.SearchStrategy[bytes]:
    """Any reply `message` can have: a code word, or (a read) its data block — every byte 7Eh allowed."""
    codes = st.binary(min_size=2, max_size=2)
    return st.one_of(codes, st.binary(min_size=codec.reply_length(message),
                                      max_size=codec.reply_length(message))) if message.IS_READ else codes


@settings(max_examples=60)
@given(exchanges, st.data())
def test_no_reply_comes_later_than_its_deadline(exchange, data):
    framing, line, address, message = exchange
    no_reply_comes_later(framing, line, address, message, data.draw(replies(message)))


@pytest.mark.soak
@given(exchanges, st.data())
def test_no_reply_comes_later_than_its_deadline_soak(exchange, data):
    framing, line, address, message = exchange
    no_reply_comes_later(framing, line, address, message, data.draw(replies(message)))


def test_the_deadline_covers_the_exchange_priced_and_grows_with_the_turnaround():
    """Never below what the bus-time model prices an exchange at (the same frames, the longest reply),
    and a slower module is waited for as long as it is slower."""
    for framing in ("crc16", "stx", "open-driver"):
        for message in (READ_FOUR, codec.ReadSystem(), WRITE_ONE, codec.InitSystem()):
            quick, slow = LineCost.of(framing, L_8E1, 0.010, 0.020), LineCost.of(framing, L_8E1, 0.310, 0.020)
            assert quick.reply_deadline(3, message) > quick.message_time(3, message)
            assert slow.reply_deadline(3, message) == pytest.approx(quick.reply_deadline(3, message) + 0.300)


def test_a_link_waits_for_a_reply_as_long_as_the_line_takes():
    """The real emulator answering at 1200 baud 8E1 over TCP: a 52h of four programs takes 0.73 s on
    the line alone, more than the bus's 0.5 s `timeout` — which now only adds to the line's own time."""
    with Emulator({1: ModuleState.factory(1)}, line=L_8E1, line_speed=True) as emulator:
        host, tcp = emulator.listen()
        port = open_port(f"socket://{host}:{tcp}", L_8E1, bus="slow")
        try:
            link = Link(port, get_framing("crc16"), bus="slow", line=L_8E1, timeout=0.5, retries=3)
            assert isinstance(link.request(1, READ_FOUR), codec.ProgramsReply)
        finally:
            port.close()
    assert (link.exchanges, link.repeated) == (1, 0)


PLANT = """\
plant: slow-line
buses:
  - name: slow
    port: {port}
    framing: {framing}
    baud: {baud}
    parity: even
    modules:
      - address: 1
        name: left
        programs:
          1: {{position: 0.300, speed: 0.350}}
          2: {{position: 0.150, speed: 0.350}}
          3: {{position: 0.250, speed: 0.250}}
          4: {{position: 0.350, speed: 0.300}}
"""


#: The workflow's commands (README, docs/commands.md), in this order.
WORKFLOW = ("plan", "apply", "read", "import", "doctor")


def remarks(trace: Path) -> list[str]:
    """The trace's remarks (time-outs, retries, replies ignored) and discarded bytes: on a clean line,
    none."""
    return [line for line in trace.read_text().splitlines() if line.split("\t")[2] in ("!", "x")]


def readme_workflow(tmp_path: Path, capsys, *, baud: int, framing: str = "crc16",
                    commands: tuple[str, ...] = WORKFLOW) -> None:
    """`commands` of the workflow on one module of four programs behind a real `emulator serve
    --rfc2217 --line-speed BAUD` (8E1): each succeeds, no exchange is lost or repeated (the traces say
    no time-out, retry or discarded byte; no note says an exchange was made again), and doctor finds the
    line and counts every exchange answered."""
    options = ("--rfc2217", "--line-speed", str(baud), "--parity", "even", "--framing", framing, "--modules",
               "1",
               "--state", str(tmp_path / "state.json"))
    line = ("--framing", framing, "--baud", str(baud), "--parity", "even")
    traces = {command: tmp_path / f"{command}.trace" for command in commands if command != "doctor"}
    results = {}
    with serve(tmp_path, *options) as served:
        url = f"rfc2217://127.0.0.1:{served.port}"
        plant = tmp_path / "plant.yaml"
        plant.write_text(PLANT.format(port=url, framing=framing, baud=baud))
        arguments = {"plan": ("plan", plant), "apply": ("apply", plant, "--auto-approve"),
                     "read": ("read", plant),
                     "import": ("import", "--port", url, *line, "--modules", "1"),
                     "doctor": ("doctor", "--port", url, *line, "--modules", "1", "--exchanges", "3",
                                "--allow-unchecked-probes")}
        for command in commands:
            traced = ("--trace", traces[command]) if command in traces else ()
            results[command] = result = run_cli(capsys, *arguments[command], *traced)
            said = [line for line in result.err.splitlines() if not line.startswith("imported 1 "
                                                                                    "module from ")]
            # no note: no exchange made again, no line slower than its keys
            assert result.code == 0 and said == [], (command, result)
    for command, trace in traces.items():
        assert remarks(trace) == [], (command, remarks(trace))
    if "plan" in results:
        assert "1 of 1 module changes" in results["plan"].out
    if "read" in results:
        assert "0.350 m" in results["read"].out
    if "import" in results:
        assert results["import"].err == f"imported 1 module from {url}\n"
        assert "{position: 0.350, speed: 0.300}" in results["import"].out
    if "doctor" in results:
        out = results["doctor"].out
        keys = dict(entry.strip().split(": ", 1)
                    for entry in out.partition("The plant file's keys for this bus:\n")[2].splitlines())
        assert (keys["framing"], keys["baud"], keys["parity"]) == (framing, str(baud), "even")
        row = next(row for row in out.splitlines() if row.startswith("│") and "ms" in row)
        assert [cell.strip() for cell in row.split("│")[4:7]] == ["3/3", "0", "0"]  # answered, damaged, lost


def test_the_readme_workflow_at_1200_baud_loses_no_exchange(tmp_path, capsys):
    """plan, apply, read and doctor at 1200 baud 8E1 (import, which reads all 64 programs — 13 s at
    this speed — is the soak tier's)."""
    readme_workflow(tmp_path, capsys, baud=1200, commands=("plan", "apply", "read", "doctor"))


@pytest.mark.soak
@pytest.mark.parametrize(("baud", "framing", "commands"), [
    (1200, "crc16", WORKFLOW), (1200, "stx", WORKFLOW), (1200, "open-driver", WORKFLOW),
    (300, "crc16", ("plan", "apply", "read", "doctor")),  # import at 300 baud: 16 reads of 3.2 s
])
def test_the_readme_workflow_at_slow_speeds_loses_no_exchange(tmp_path, capsys, baud, framing, commands):
    readme_workflow(tmp_path, capsys, baud=baud, framing=framing, commands=commands)
