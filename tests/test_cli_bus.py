"""`prc3cfg scan`, `import` and `link init-db` against real emulators and plant files."""

from __future__ import annotations

import shlex
from dataclasses import replace

import pytest
from emulated import emulated_plant, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from prc3cfg.core.device import ModuleState
from prc3cfg.core.image import PROGRAM_COUNT, ModuleImage, Program, SystemParameters
from prc3cfg.shell.emulator.server import Emulator
from prc3cfg.shell.plant_files import load_plant

GATEWAY_PLANT = """\
plant: gateway-test
buses:
  - name: line-1
    port: /dev/ttyUSB0
    framing: open-driver
    baud: 9600
    parity: even
    data_bits: 8
    stop_bits: 1
    zvz: {zvz}
    gateway: {{receive_db: 30, receive_dw: 1, cpu: 0, identifier: 1}}
    modules:
      - {{address: 1, name: m1}}
"""


def test_init_db_reproduces_the_manuals_db189_example(tmp_path, capsys):
    plant = tmp_path / "plant.yaml"
    plant.write_text(GATEWAY_PLANT.format(zvz=0.220))
    result = run_cli(capsys, "link", "init-db", plant, "--bus", "line-1")
    assert result.code == 0, result.err
    rows = [line.split() for line in result.out.splitlines()[1:]]
    assert [" ".join(r[2:-1]) for r in rows] == [
        "KY = 030,001", "KY = 000,001", "KM = 00000000 00110100", "KM = 00000000 00000000",
        "KH = 0000", "KH = 0000", "KF = +220", "KH = 0000",
    ]
    assert [r[-1] for r in rows] == ["1E01h", "0001h", "0034h", "0000h", "0000h", "0000h", "00DCh", "0000h"]


def test_init_db_refuses_zvz_below_4_ms_naming_systat_8e(tmp_path, capsys):
    plant = tmp_path / "plant.yaml"
    plant.write_text(GATEWAY_PLANT.format(zvz=0.003))
    result = run_cli(capsys, "link", "init-db", plant, "--bus", "line-1")
    assert result.code == 1
    assert "SYSTAT 8Eh" in result.err and "Traceback" not in result.err


def test_init_db_needs_a_gateway(tmp_path, capsys):
    plant = tmp_path / "plant.yaml"
    plant.write_text(GATEWAY_PLANT.format(zvz=0.02).replace("    gateway: {receive_db: 30, receive_dw: 1, "
                                                            "cpu: 0, identifier: 1}\n", ""))
    result = run_cli(capsys, "link", "init-db", plant, "--bus", "line-1")
    assert result.code == 1 and "has no gateway block" in result.err


def test_scan_lists_the_answering_addresses(capsys):
    with Emulator({2: ModuleState.factory(2), 17: ModuleState.factory(17)}) as emulator:
        host, port = emulator.listen()
        result = run_cli(capsys, "scan", "--port", f"socket://{host}:{port}", "--timeout", "0.05",
                         "--retries", "0")
    assert result.code == 0, result.err
    assert "2 modules answered" in result.out
    assert " 17 " in result.out and "0.400 m" in result.out


def test_scan_of_a_silent_line_is_one_line(capsys):
    with Emulator({}) as emulator:
        host, port = emulator.listen()
        result = run_cli(capsys, "scan", "--port", f"socket://{host}:{port}", "--timeout", "0.02",
                         "--retries", "0")
    assert result.code == 1 and result.err.count("\n") == 1 and "no module answered" in result.err


@st.composite
def module_states(draw, address: int) -> ModuleState:
    s5 = draw(st.integers(1, 300))
    system = SystemParameters(
        S1=draw(st.integers(100, 9999)), S2=draw(st.integers(50, 500)), S3=draw(st.integers(1, 9999)),
        S4=draw(st.integers(s5, 600)), S5=s5, S6=draw(st.integers(1000, 1500)),
                              S7=draw(st.integers(800, 1500)),
        S8=draw(st.integers(0, 1)), S10=draw(st.integers(1, 9999)), S11=draw(st.integers(1, 1500)),
        S12=draw(st.integers(5, 50)),
    )
    base = ModuleImage.factory(address)
    programs = list(replace(base, system=system).programs)
    default = Program(P=min(system.S2 + 100, system.S1), V=min(max(50, system.S5), system.S4))
    programs = [default] * PROGRAM_COUNT
    for number in draw(st.lists(st.integers(1, PROGRAM_COUNT), max_size=12, unique=True)):
        f = st.integers(0, 1999)
        programs[number - 1] = Program(
            P=draw(st.integers(0, system.S1)), V=draw(st.integers(system.S5, system.S4)),
            Vr=draw(st.integers(-600, 600)), T=draw(st.integers(0, 600)), F1=draw(f), F2=draw(f),
            A=draw(st.sampled_from([0, 0, number % 64 + 1, draw(st.integers(1, 64))])),
        )
    for number in draw(st.lists(st.integers(1, PROGRAM_COUNT), max_size=6)):
        programs[number - 1] = replace(programs[number - 1], A=draw(st.integers(0, 64)))
    return ModuleState(ModuleImage(address, system, tuple(programs)))


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.tuples(module_states(3), module_states(9)))
def test_import_then_plan_is_empty(tmp_path_factory, capsys, states):
    directory = tmp_path_factory.mktemp("import")
    with Emulator({s.address: s for s in states}) as emulator:
        host, port = emulator.listen()
        url = f"socket://{host}:{port}"
        imported = run_cli(capsys, "import", "--port", url, "--modules", "3,9", "--timeout", "0.2")
        assert imported.code == 0, imported.err
        plant = directory / "imported.yaml"
        plant.write_text(imported.out)
        assert run_cli(capsys, "validate", plant).code == 0
        planned = run_cli(capsys, "plan", plant, "--detailed-exitcode")
        assert planned.code == 0, planned.out + planned.err


@st.composite
def alike_states(draw) -> list[ModuleState]:
    """Three modules made from one: a few system parameters and program fields changed in each."""
    base = draw(module_states(1))
    states = []
    for address in (4, 5, 6):
        image = replace(base.image, address=address)
        system = image.system
        if draw(st.booleans()):
            system = replace(system, S2=draw(st.integers(50, 500)), S7=draw(st.integers(800, 1500)))
        programs = list(image.programs)
        for number in draw(st.lists(st.integers(1, PROGRAM_COUNT), max_size=3, unique=True)):
            program = programs[number - 1]
            programs[number - 1] = replace(program, P=draw(st.integers(0, system.S1)),
                                           T=draw(st.integers(0, 600)))
        states.append(ModuleState(replace(image, system=system, programs=tuple(programs))))
    return states


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(alike_states())
def test_modules_alike_import_into_one_profile_and_plan_to_no_changes(tmp_path_factory, capsys, states):
    directory = tmp_path_factory.mktemp("import")
    with Emulator({s.address: s for s in states}) as emulator:
        host, port = emulator.listen()
        imported = run_cli(capsys, "import", "--port", f"socket://{host}:{port}", "--modules", "4-6",
                           "--timeout", "0.2")
        assert imported.code == 0, imported.err
        plant = directory / "imported.yaml"
        plant.write_text(imported.out)
        assert run_cli(capsys, "validate", plant).code == 0
        planned = run_cli(capsys, "plan", plant, "--detailed-exitcode")
        assert planned.code == 0, imported.out + planned.out + planned.err


def test_an_imported_plant_file_s_schema_line_is_told_how_to_be_met(tmp_path, capsys):
    """The plant file `import --out` writes names its JSON Schema beside it, for an editor: where that file is
    not there, the import says the command that writes it — run as printed, it is, and the next import says
    nothing of it."""
    with Emulator({1: ModuleState(ModuleImage.factory(1))}) as emulator:
        host, port = emulator.listen()
        plant = tmp_path / "Anlage Süd" / "plant.yaml"
        plant.parent.mkdir()

        def imported() -> list[str]:
            done = run_cli(capsys, "import", "--port", f"socket://{host}:{port}", "--modules", "1",
                           "--timeout", "0.2", "--out", plant)
            assert done.code == 0, done.err
            return done.err.splitlines()

        first = imported()
        assert first[:2] == [f"Written to {plant}", f"imported 1 module from socket://{host}:{port}"]
        said, _, command = first[2].partition(": ")
        assert said == "its first line names plant.schema.json beside it, for an editor — write that with"
        assert len(first) == 3 and shlex.split(command)[:3] == ["prc3cfg", "schema", "--out"]
        assert run_cli(capsys, *shlex.split(command)[1:]).code == 0
        written = (plant.parent / "plant.schema.json").read_text(encoding="utf-8")
        assert written == run_cli(capsys, "schema").out
        assert imported() == first[:2]


def test_three_identical_modules_are_one_profile_and_three_lines(tmp_path, capsys):
    image = ModuleImage.factory(1)
    programs = list(image.programs)
    programs[:3] = [Program(P=1500, V=200, T=5, A=2), Program(P=300, V=200, F1=1100, A=1),
                    Program(P=900, V=100)]
    image = replace(image, system=replace(image.system, S1=1800, S4=500), programs=tuple(programs))
    with Emulator({a: ModuleState(replace(image, address=a)) for a in (1, 2, 3)}) as emulator:
        host, port = emulator.listen()
        imported = run_cli(capsys, "import", "--port", f"socket://{host}:{port}", "--modules", "1-3",
                           "--timeout", "0.2")
        assert imported.code == 0, imported.err
        lines = imported.out.splitlines()
        assert lines[0] == "# yaml-language-server: $schema=plant.schema.json"
        assert lines[-3:] == ["  - {address: 1, name: bus-1-1, profiles: [common]}",
                              "  - {address: 2, name: bus-1-2, profiles: [common]}",
                              "  - {address: 3, name: bus-1-3, profiles: [common]}"]
        assert ("profiles:\n  common:\n    system: {upper_reversing_point: 1.800, "
                "max_speed: 0.500}\n") in imported.out
        assert len(lines) < 30, imported.out
        plant = tmp_path / "imported.yaml"
        plant.write_text(imported.out)
        assert run_cli(capsys, "validate", plant).code == 0
        assert run_cli(capsys, "plan", plant, "--detailed-exitcode").code == 0


@pytest.mark.parametrize("command", ["scan", "import"])
def test_an_absent_address_costs_one_short_try(capsys, tmp_path, command):
    """An empty line: one 50h per address, none asked again, and no warning lines."""
    trace = tmp_path / "trace.txt"
    with Emulator({5: ModuleState.factory(5)}) as emulator:
        host, port = emulator.listen()
        result = run_cli(capsys, command, "--port", f"socket://{host}:{port}", "--trace", trace, "--timeout",
                         "0.05")
    assert result.code == 0, result.err
    sent = [line for line in trace.read_text().splitlines() if "\t>\t" in line]
    assert len(sent) == 30 + (0 if command == "scan" else 1 + 16)  # import then reads module 5 whole
    assert "retrying" not in result.err and "warning" not in result.err.lower()


@pytest.mark.parametrize("command", [["validate"], ["link", "init-db", "--bus", "line-1"]])
def test_a_zvz_not_longer_than_one_character_is_refused_at_its_line(tmp_path, capsys, command):
    """1200 baud, 8E1: a character is 11 bits, 9.17 ms — with ZVZ 4 ms a CP 524 ends a frame after every
    byte."""
    plant = tmp_path / "plant.yaml"
    plant.write_text(GATEWAY_PLANT.format(zvz=0.004).replace("baud: 9600", "baud: 1200"))
    result = (run_cli(capsys, *command[:-2], plant, *command[-2:]) if len(command) > 1
              else run_cli(capsys, "validate", plant))
    assert result.code == 1
    assert result.problems == [
        f"error: {plant}:10:10: zvz 0.004 s is not longer than one character at 1200 baud, "
        "8E1 (11 bits: 9.17 ms), so the gateway would end a frame after every byte — the character delay "
        "time must be "
        "greater than the time between two characters (seed 004 §5.2.8; its guide at 1200 baud: 30..800 "
        "ms): raise zvz"]


def test_import_reads_every_line_given_into_one_plant_file_that_plans_to_no_changes(tmp_path, capsys):
    """A laptop's first day: both lines of the demo plant, commissioned, into one plant file — a bus each,
    named as asked, what every module of both holds alike once."""
    with emulated_plant(tmp_path) as emulated:
        assert run_cli(capsys, "apply", emulated.path, "--auto-approve", "--allow-axis-release").code == 0
        ports = [bus.port for bus in emulated.plant.buses]
        # the emulated plant's timeout: 27 absent addresses on each line are waited out
        imported = run_cli(capsys, "import", "--port", ports[0], "--port", ports[1], "--bus-name", "left",
                           "--bus-name", "right",
                           "--timeout", "0.1")
        assert imported.code == 0, imported.err
        assert imported.err.strip() == f"imported 6 modules from {ports[0]}, {ports[1]}"
        plant = tmp_path / "imported.yaml"
        plant.write_text(imported.out)
        loaded = load_plant(plant)
        assert [(b.name, b.port, [m.address for m in b.modules]) for b in loaded.buses] == [
            ("left", ports[0], [1, 2, 5]), ("right", ports[1], [1, 3, 4])]
        # alike: once, for both buses
        assert "profiles:\n  common:" in imported.out and imported.out.count("unmanaged_programs") == 1
        assert run_cli(capsys, "validate", plant).code == 0
        planned = run_cli(capsys, "plan", plant, "--detailed-exitcode")
        assert planned.code == 0, planned.out + planned.err
        twice = run_cli(capsys, "import", "--port", ports[0], "--port",
                        ports[0].replace("127.0.0.1", "localhost"), "--timeout", "0.2")
        assert twice.code == 1 and twice.err.startswith(f"error: --port {ports[0]} and --port ")
        assert "are one line" in twice.err
        unnamed = run_cli(capsys, "import", "--port", ports[0], "--port", ports[1], "--bus-name", "left")
        assert (unnamed.code == 1
                and unnamed.err.strip() == "error: 1 --bus-name for 2 --port: give one name per port, in "
                                           "their order (or none)")
