"""Good plant files: the examples, the contract's example, defaults, desired images, profile precedence."""

from __future__ import annotations

import hashlib
import textwrap
from decimal import Decimal
from pathlib import Path

import pytest
from pydantic import ValidationError

from prc3cfg.core.image import DEFAULT_SYSTEM, PROGRAM_COUNT, Program, default_program
from prc3cfg.core.line import LineSettings
from prc3cfg.plant import Bus, Module, Plant, PlantError, document
from prc3cfg.shell.plant_files import load_plant

ROOT = Path(__file__).parents[2]
PLANTS = sorted((ROOT / "plants").rglob("*.yaml"))


def load_text(tmp_path: Path, text: str) -> Plant:
    path = tmp_path / "plant.yaml"
    path.write_text(textwrap.dedent(text))
    return load_plant(path)


def one_module(tmp_path: Path, text: str) -> Module:
    """A plant of one bus whose modules section is `text` (YAML, indented as under `modules:`)."""
    plant = load_text(tmp_path, "plant: p\nbuses:\n  - name: a\n    port: emulator://a\n    modules:\n"
                      + textwrap.indent(textwrap.dedent(text), "      "))
    return plant.buses[0].modules[0]


def with_profiles(tmp_path: Path, profiles: str, module: str) -> Module:
    plant = load_text(tmp_path, "plant: p\nprofiles:\n" + textwrap.indent(textwrap.dedent(profiles), "  ")
                      + "buses:\n  - name: a\n    port: emulator://a\n    modules:\n"
                      + textwrap.indent(textwrap.dedent(module), "      "))
    return plant.buses[0].modules[0]


@pytest.mark.parametrize("path", PLANTS, ids=lambda p: p.name)
def test_every_plant_in_plants_validates(path: Path) -> None:
    plant = load_plant(path)
    assert plant.sha256 == hashlib.sha256(path.read_bytes()).hexdigest()
    assert plant.path == path
    for _, module in plant.modules():
        image = module.desired_image()
        assert image.address == module.address
        assert [n for n in range(1, PROGRAM_COUNT + 1)
                if image.program(n) is not None] == list(module.managed_programs())


SPANNED = """\
plant: p   # a comment
buses:
  - name: 'a'
    port: emulator://a
    modules: [{address: 1, name: "x y", programs: {1: {position: 0.100, speed: 0.050}}}]
    timeout: 1.0
"""


@pytest.mark.parametrize("text", [SPANNED, *(p.read_text() for p in PLANTS)],
                         ids=["quotes-flow", *(p.name for p in PLANTS)])
def test_the_spans_adopt_splices_are_the_data_the_loader_read(text: str) -> None:
    """One reader: `document.spans` has the keys, items and scalars of the data `parse_document`
    built from the same text, each scalar's span holding its text (quotes included)."""
    data = document.parse_document("p.yaml", text.encode()).data

    def same(span: document.Span, value: object) -> None:
        if isinstance(value, dict):
            assert list(span.keys) == list(span.children) == list(value)
            assert all(text[span.keys[k]:].startswith(str(k)) for k in value)
            for key, child in span.items():
                same(child, value[key])
        elif isinstance(value, list):
            assert isinstance(span.children, list) and len(span.children) == len(value)
            for (_, child), item in zip(span.items(), value):
                same(child, item)
        else:
            assert span.written is not None
            quote = "" if span.plain else text[span.start]
            assert text[span.start:span.end] == f"{quote}{span.written}{quote}"

    same(document.spans(text), data)

def test_demo_line() -> None:
    plant = load_plant(ROOT / "plants" / "demo-line.yaml")
    assert plant.name == "demo-line"
    assert [(b.name, b.port, b.framing, len(b.modules)) for b in plant.buses] == [
        ("booth-a", "emulator://demo-a", "crc16", 3), ("booth-b", "emulator://demo-b", "crc16", 3)]
    modules = {m.name: m for _, m in plant.modules()}
    top = modules["booth-a-top"].desired_image()
    assert top.system.S1 == 1800 and top.system.S4 == 500 and top.system.S5 == 20
    assert top.program(1) == Program(P=1750, V=350, T=5, A=2)            # module position, profile rest
    assert top.program(2).A == 1                                          # the loop
    assert top.program(3) == Program(P=1100, V=250, Vr=30, F1=1020, F2=50, A=10)  # next: 10
    assert top.program(11).A == 0 and top.program(4) is None
    pretreat = modules["booth-b-pretreat"]
    assert pretreat.unmanaged_programs == "reset"
    assert pretreat.managed_programs() == tuple(range(1, 65))
    image = pretreat.desired_image()
    assert image.program(64) == default_program(image.system) == Program(P=150, V=50)


def test_coating_line_has_thirty_modules_on_two_buses() -> None:
    plant = load_plant(ROOT / "plants" / "examples" / "coating-line.yaml")
    assert [len(bus.modules) for bus in plant.buses] == [15, 15]
    left = plant.buses[0]
    assert (left.framing, left.gateway.receive_db, left.gateway.identifier, left.zvz) == ("open-driver", 30,
                                                                                          1, 0.020)
    assert plant.buses[1].port.startswith("socket://")


def test_the_contract_example(tmp_path: Path) -> None:
    """The design's example plant file, with programs 10..12 listed (its chain names them); 1 is manual
    example 21h."""
    plant = load_text(tmp_path, """\
        plant: coating-line-1
        buses:
          - name: booth-a
            port: socket://127.0.0.1:7001
            framing: crc16
            baud: 9600
            parity: even
            data_bits: 8
            stop_bits: 1
            timeout: 0.5
            turnaround: 0.010
            zvz: 0.020
            gateway:
              receive_db: 30
              receive_dw: 1
              cpu: 0
              identifier: 1
            modules:
              - address: 1
                name: booth-a-left
                system:
                  upper_reversing_point: 1.800
                  reference_point: 0.050
                  increment_pulses: 754
                  max_speed: 0.600
                  min_speed: 0.010
                  acceleration: 1.500
                  circuit_gain: 1000
                  alarm: false
                  sync_increment: 583
                  sync_circuit_gain: 1100
                  sync_conveyor_sequence: 0.010
                programs:
                  1: {position: 1.050, speed: 0.300, relative_speed: 0.053, dwell: 2.0,
                      f1: {action: set, distance: 0.010}, f2: {action: reset, distance: 0.050}}
                  2: {position: 0.600, speed: 0.200}
                  10: {position: 1.000, speed: 0.300}
                  11: {position: 0.500, speed: 0.300}
                  12: {position: 0.200, speed: 0.300}
                chains:
                  - [1, 2]
                  - {programs: [10, 11, 12], loop: true}
                unmanaged_programs: keep
        """)
    module = plant.buses[0].modules[0]
    image = module.desired_image()
    assert image.system.values() == (1800, 50, 754, 600, 10, 1500, 1000, 0, 583, 1100, 10)
    assert image.program(1) == Program(P=1050, V=300, Vr=53, T=20, F1=1010, F2=50, A=2)
    assert image.program(2) == Program(P=600, V=200, A=0)
    assert [image.program(n).A for n in (10, 11, 12)] == [11, 12, 10]
    assert image.program(3) is None
    assert module.managed_programs() == (1, 2, 10, 11, 12)


def test_bus_defaults_and_line(tmp_path: Path) -> None:
    bus: Bus = load_text(tmp_path, """\
        plant: p
        buses:
          - {name: a, port: emulator://a, modules: [{address: 1, name: m}]}
        """).buses[0]
    assert (bus.framing, bus.baud, bus.parity, bus.data_bits, bus.stop_bits) == ("crc16", 9600, "even", 8, 1)
    assert (bus.timeout, bus.turnaround, bus.zvz, bus.gateway) == (0.5, 0.010, 0.020, None)
    assert all(isinstance(t, float) for t in (bus.timeout, bus.turnaround, bus.zvz))
    assert bus.line == LineSettings()
    module = bus.modules[0]
    assert module.desired_image().system == DEFAULT_SYSTEM
    assert module.managed_programs() == () and module.unmanaged_programs == "keep"


def test_numbers_are_exact_decimals(tmp_path: Path) -> None:
    module = one_module(tmp_path, """\
        - address: 1
          name: m
          system: {upper_reversing_point: 9.999, sync_conveyor_sequence: 0.045, min_speed: 0.001}
          programs:
            1: {position: 0.1, speed: 0.007, relative_speed: -0.001, dwell: 0.3}
            2: {position: 8.765, speed: 0.1, dwell: 59.9, f2: {action: set, distance: 0.999}}
        """)
    image = module.desired_image()
    assert (image.system.S1, image.system.S12) == (9999, 45)
    assert image.program(1).values()[:4] == (100, 7, -1, 3)
    assert image.program(2) == Program(P=8765, V=100, T=599, F2=1999)
    assert module.settings.programs[1]["position"].value == Decimal("0.1")


def test_the_module_and_the_objects_are_immutable(tmp_path: Path) -> None:
    module = one_module(tmp_path, "- {address: 1, name: m}\n")
    with pytest.raises(ValidationError, match="frozen"):
        module.name = "other"  # type: ignore[misc]


PROFILES = """\
    a:
      system: {upper_reversing_point: 2.000, max_speed: 0.500, min_speed: 0.020}
      programs:
        1: {position: 1.000, speed: 0.300, dwell: 1.0, f1: {action: set, distance: 0.010}}
        2: {position: 0.500, speed: 0.300}
      chains: [[1, 2]]
      unmanaged_programs: reset
    b:
      system: {upper_reversing_point: 2.200, acceleration: 1.100}
      programs:
        1: {speed: 0.400}
        3: {position: 0.800, speed: 0.200}
    """


def test_precedence_default_then_profiles_in_order_then_module(tmp_path: Path) -> None:
    module = with_profiles(tmp_path, PROFILES, """\
        - address: 1
          name: m
          profiles: [a, b]
          system: {acceleration: 1.300}
          programs:
            1: {position: 1.500}
        """)
    system = module.settings.system
    assert system["upper_reversing_point"].source == "profile b"   # b after a
    assert system["max_speed"].source == "profile a"
    assert system["acceleration"].source == "module"               # the module wins
    assert system["increment_pulses"].source == "default"
    p1 = module.settings.programs[1]
    assert {k: (v.value, v.source) for k, v in p1.items()
            if k in ("position", "speed", "dwell", "relative_speed")} == {
        "position": (Decimal("1.500"), "module"), "speed": (Decimal("0.400"), "profile b"),
        "dwell": (Decimal("1.0"), "profile a"), "relative_speed": (Decimal(0), "default")}
    image = module.desired_image()
    assert image.system.S1 == 2200 and image.system.S6 == 1300
    assert image.program(1) == Program(P=1500, V=400, T=10, F1=1010, A=2)  # chain from a
    assert image.program(3) == Program(P=800, V=200)                        # listed by b only
    assert module.unmanaged_programs == "reset"                              # from a


def test_profile_order_matters(tmp_path: Path) -> None:
    module = with_profiles(tmp_path, PROFILES, "- {address: 1, name: m, profiles: [b, a]}\n")
    assert module.desired_image().system.S1 == 2000
    assert module.settings.system["upper_reversing_point"].source == "profile a"
    assert module.settings.programs[1]["speed"].source == "profile a"


def test_a_single_profile_name_is_a_list_of_one(tmp_path: Path) -> None:
    module = with_profiles(tmp_path, PROFILES, "- {address: 1, name: m, profiles: a}\n")
    assert module.profiles == ("a",)
    assert module.desired_image().program(2) == Program(P=500, V=300)


def test_chains_are_replaced_whole_not_merged(tmp_path: Path) -> None:
    module = with_profiles(tmp_path, PROFILES, """\
        - address: 1
          name: m
          profiles: a
          programs:
            3: {position: 0.300, speed: 0.300}
          chains: [{programs: [2, 3], loop: true}]
        """)
    image = module.desired_image()
    assert [image.program(n).A for n in (1, 2, 3)] == [0, 3, 2]
    assert module.settings.chains.source == "module"


def test_an_empty_chains_list_drops_the_profiles_chains(tmp_path: Path) -> None:
    module = with_profiles(tmp_path, PROFILES, "- {address: 1, name: m, profiles: a, chains: []}\n")
    assert [module.desired_image().program(n).A for n in (1, 2)] == [0, 0]


def test_unmanaged_programs_last_layer_wins(tmp_path: Path) -> None:
    module = with_profiles(tmp_path, PROFILES,
                           "- {address: 1, name: m, profiles: a, unmanaged_programs: keep}\n")
    assert module.unmanaged_programs == "keep"
    assert module.managed_programs() == (1, 2)
    assert module.desired_image().program(5) is None


def test_reset_gives_factory_programs_for_the_desired_system(tmp_path: Path) -> None:
    module = one_module(tmp_path, """\
        - address: 7
          name: m
          unmanaged_programs: reset
          system: {upper_reversing_point: 0.120, reference_point: 0.060, min_speed: 0.060}
          programs:
            1: {position: 0.100, speed: 0.100}
        """)
    image = module.desired_image()
    assert image.program(2) == default_program(image.system) == Program(P=120, V=60)


def test_a_loop_of_one_program_jumps_to_itself(tmp_path: Path) -> None:
    module = one_module(tmp_path, """\
        - address: 1
          name: m
          programs:
            4: {position: 0.300, speed: 0.300}
          chains: [{programs: [4], loop: true}]
        """)
    assert module.desired_image().program(4).A == 4


def test_next_sets_a_jump_chains_cannot_say(tmp_path: Path) -> None:
    module = one_module(tmp_path, """\
        - address: 1
          name: m
          programs:
            1: {position: 0.300, speed: 0.300, next: 3}
            2: {position: 0.200, speed: 0.300, next: 3}
            3: {position: 0.100, speed: 0.300}
        """)
    assert [module.desired_image().program(n).A for n in (1, 2, 3)] == [3, 3, 0]


def test_modules_that_add_nothing_to_a_profile_take_its_settings_each_at_its_own_address(
    tmp_path: Path,
) -> None:
    plant = load_text(tmp_path, "plant: p\nprofiles:\n" + textwrap.indent(textwrap.dedent(PROFILES), "  ")
                      + textwrap.dedent("""\
        buses:
          - name: a
            port: emulator://a
            modules:
              - {address: 1, name: m, profiles: a}
              - {address: 2, name: "n", profiles: a}
              - {address: 3, name: o, profiles: [a, b]}
              - {address: 4, name: q, profiles: a, programs: {2: {position: 0.600}}}
        """))
    m, n, o, q = plant.buses[0].modules
    assert [x.desired_image().address for x in (m, n, o, q)] == [1, 2, 3, 4]
    assert n.desired_image().programs == m.desired_image().programs
    assert o.desired_image().program(1).V == 400 and m.desired_image().program(1).V == 300
    assert q.desired_image().program(2).P == 600 and m.desired_image().program(2).P == 500
    assert n.settings.programs[1]["position"].source == "profile a"


def test_a_profile_problem_is_said_once_in_the_names_of_every_module_that_takes_it(tmp_path: Path) -> None:
    """One mistake in a profile is one line naming the modules it reaches (issue 42: 130 lines for one
    mistake)."""
    with pytest.raises(PlantError) as raised:
        with_profiles(tmp_path, """\
            a:
              programs:
                1: {position: 0.300}
            """, """\
            - {address: 1, name: m, profiles: a}
            - {address: 2, name: "n", profiles: a}
            """)
    assert [line.partition(": ")[2] for line in raised.value.problems] == [
        "in modules m and n, program 1 has no speed — give speed: in the module or in one of its profiles"
    ]


def test_a_profile_problem_names_the_module_and_points_into_the_profile(tmp_path: Path) -> None:
    with pytest.raises(PlantError) as raised:
        with_profiles(tmp_path, PROFILES, """\
            - {address: 1, name: m, profiles: a}
            - {address: 2, name: "n", profiles: a, system: {upper_reversing_point: 0.900}}
            """)
    assert raised.value.problems == [
        f"{tmp_path / 'plant.yaml'}:6:21: in module n, position 1.000 m is above upper_reversing_point "
        "0.900 m (module) — a position must be at most the upper reversing point (P ≤ S1): lower it or "
        "raise upper_reversing_point"
    ]
