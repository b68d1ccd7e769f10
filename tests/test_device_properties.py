"""Properties of the device model: any bytes in any state — never an exception, a reply of the
right shape, a rejected message changes nothing, an accepted write keeps every invariant."""

from __future__ import annotations

from dataclasses import replace

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from prc3cfg.core import codec, device, error_codes
from prc3cfg.core.device import ModuleState
from prc3cfg.core.image import DEFAULT_SYSTEM, ModuleImage, Program, SystemParameters

#: The fast tier's count; `test_every_property_holds_in_many_more_cases` tries the soak profile's.
PROPERTY = settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large]
)

#: The fixed ranges of docs/protocol.md "Values" (P and V depend on S1, S4, S5).
SYSTEM_RANGES = {
    "S1": (100, 9999), "S2": (50, 500), "S3": (1, 9999), "S4": (1, 600), "S5": (1, 600), "S6": (1000, 1500),
    "S7": (800, 1500), "S8": (0, 1), "S10": (1, 9999), "S11": (1, 1500), "S12": (5, 50),
}
FIELD_RANGES = {"Vr": (-600, 600), "T": (0, 600), "F1": (0, 1999), "F2": (0, 1999), "A": (0, 64)}
READ_IDS = {0x50, 0x51, 0x52}

kf = st.integers(-0x8000, 0x7FFF)
byte = st.integers(0, 0xFF)
pn = st.integers(1, 64)


def in_range(low: int, high: int) -> st.SearchStrategy[int]:
    return st.one_of(st.sampled_from([low, high]), st.integers(low, high))


@st.composite
def valid_systems(draw) -> SystemParameters:
    values = {key: draw(in_range(*r)) for key, r in SYSTEM_RANGES.items()}
    values["S4"], values["S5"] = max(values["S4"], values["S5"]), min(values["S4"], values["S5"])
    return SystemParameters(**values)


def valid_programs(system: SystemParameters) -> st.SearchStrategy[Program]:
    return st.builds(
        Program,
        P=in_range(0, system.S1),
        V=in_range(system.S5, system.S4),
        **{field: in_range(*r) for field, r in FIELD_RANGES.items()},
    )


@st.composite
def states(draw) -> ModuleState:
    system = draw(st.one_of(st.just(DEFAULT_SYSTEM), valid_systems()))
    pool = draw(st.lists(valid_programs(system), min_size=1, max_size=4))
    programs = tuple(draw(st.sampled_from(pool)) for _ in range(64))
    return ModuleState(
        ModuleImage(draw(st.integers(1, 30)), system, programs),
        mode=draw(st.sampled_from(["stop", "stop", "stop", "run", "manual"])),
        active_program=draw(st.one_of(st.none(), pn)),
        fault=draw(st.one_of(st.none(), st.none(), st.none(), st.sampled_from(sorted(device.FAULT_CODES)))),
        referenced=draw(st.booleans()),
    )


def write_values(system: SystemParameters, wild: bool) -> dict[str, st.SearchStrategy[int]]:
    """Per kind: values the module takes on `system`, or (wild) any value the word can carry."""
    valid = {"P": (0, system.S1), "V": (system.S5, system.S4), **FIELD_RANGES}
    if wild:
        return {kind: st.one_of(in_range(*r), kf if kind != "A" else byte) for kind, r in valid.items()}
    return {kind: in_range(*r) for kind, r in valid.items()}


@st.composite
def messages_for(draw, state: ModuleState) -> bytes:
    """Bytes a master might send this module: real messages of every ID (values near the
    module's limits, a quarter of them with values anywhere), mutations of them, and noise."""
    wild = draw(st.sampled_from([False, False, False, True]))
    v = write_values(state.image.system, wild)
    item_pn = st.one_of(pn, byte) if wild else pn
    programs = st.builds(Program, **{k: v[k] for k in ("P", "V", "Vr", "T", "F1", "F2", "A")})
    any_system = st.builds(
        SystemParameters, **{k: st.one_of(in_range(*r), kf if k != "S8" else byte)
                             for k, r in SYSTEM_RANGES.items()}
    )
    first = draw(pn)
    last = draw(st.integers(first, 64))
    n = draw(st.integers(1, 15))
    field = draw(st.sampled_from(sorted(codec.FIELD_MESSAGES)))
    system = draw(any_system if wild else valid_systems())
    candidates = {
        "10h": lambda: codec.InitSystem(),
        "11h": lambda: codec.InitAllPrograms(),
        "12h": lambda: codec.InitProgram(first),
        "13h": lambda: codec.InitProgramsFrom(first),
        "14h": lambda: codec.InitPrograms(first, last),
        "20h": lambda: codec.WriteSystem(system),
        "21h": lambda: codec.WriteProgram(first, draw(programs)),
        "30h": lambda: codec.LinkPrograms(first, last),
        "31h": lambda: codec.UnlinkPrograms(first, last),
        "32h": lambda: codec.WritePartProgram(first, draw(v["P"]), draw(v["V"])),
        "33h": lambda: codec.WritePartPrograms(
            first, tuple((draw(v["P"]), draw(v["V"])) for _ in range(min(n, 65 - first)))
        ),
        "4xh": lambda: codec.FIELD_MESSAGES[field](tuple((draw(item_pn), draw(v[field])) for _ in range(n))),
        "46h": lambda: codec.WriteAddresses(tuple((draw(item_pn), draw(v["A"])) for _ in range(2 * n))),
        "50h": lambda: codec.ReadSystem(),
        "51h": lambda: codec.ReadProgram(first),
        "52h": lambda: codec.ReadPrograms(first, min(last, first + 3)),
    }
    kind = draw(st.sampled_from([*candidates, "noise", "mutated"]))
    if kind == "noise":
        return draw(st.binary(max_size=70))
    data = candidates[kind if kind != "mutated" else draw(st.sampled_from(sorted(candidates)))]().encode()
    if kind == "mutated":
        data = bytearray(data)
        data[draw(st.integers(0, len(data) - 1))] = draw(byte)
        data = bytes(data[: draw(st.integers(0, len(data) + 2))]) + draw(st.binary(max_size=2))
    return data


@st.composite
def cases(draw) -> tuple[ModuleState, bytes]:
    state = draw(states())
    return state, draw(messages_for(state))


def invariants_hold(state: ModuleState) -> bool:
    system = state.image.system
    return (
        all(low <= getattr(system, key) <= high for key, (low, high) in SYSTEM_RANGES.items())
        and system.S5 <= system.S4
        and all(
            0 <= p.P <= system.S1
            and system.S5 <= p.V <= system.S4
            and all(low <= getattr(p, f) <= high for f, (low, high) in FIELD_RANGES.items())
            for p in state.image.programs
        )
    )


def data_block_length(data: bytes) -> int:
    """The read reply's length, from the request's bytes (docs/protocol.md "Messages")."""
    if data[0] == 0x50:
        return 22
    if data[0] == 0x51:
        return 16
    return 16 * (data[3] - data[2] + 1)


@PROPERTY
@given(cases(), st.booleans())
def test_process_never_raises_and_replies_in_shape(case, broadcast):
    state, data = case
    outcome = device.process(state, data, broadcast=broadcast)
    assert isinstance(outcome.state, ModuleState)
    if state.mode == "manual" or broadcast:
        assert outcome.reply is None
        return
    reply = outcome.reply
    if len(reply) == 2:
        assert reply[1] == 0
        assert reply[0] == error_codes.ACCEPTED or reply[0] in error_codes.ERROR_CODES
        assert reply[0] != error_codes.ACCEPTED or data[0] not in READ_IDS
    else:
        assert data[0] in READ_IDS
        assert len(reply) == data_block_length(data)


@PROPERTY
@given(cases())
def test_a_broadcast_does_what_an_addressed_message_does(case):
    state, data = case
    assert device.process(state, data, broadcast=True).state == device.process(state, data).state


@PROPERTY
@given(cases())
def test_only_an_accepted_write_changes_the_state(case):
    state, data = case
    outcome = device.process(state, data)
    if outcome.reply != codec.encode_code(error_codes.ACCEPTED):
        assert outcome.state == state  # rejected, a read, or MANUAL's silence
    else:
        assert data[0] not in READ_IDS
        assert state.mode != "manual"


@PROPERTY
@given(cases())
def test_an_accepted_write_keeps_every_invariant(case):
    state, data = case
    assert invariants_hold(state)
    outcome = device.process(state, data)
    if outcome.reply != codec.encode_code(error_codes.ACCEPTED):
        return
    new = outcome.state
    assert invariants_hold(new)
    assert (new.address, new.mode, new.active_program) == (state.address, state.mode, state.active_program)
    if data[0] in (0x10, 0x20):
        assert new.referenced is False
        assert new.fault is None
    else:
        assert new.image.system == state.image.system
        assert (new.referenced, new.fault) == (state.referenced, state.fault)
        assert state.fault is None


@PROPERTY
@given(cases())
def test_in_run_the_active_program_is_never_written(case):
    state, data = case
    state = replace(state, mode="run", active_program=state.active_program or 1)
    outcome = device.process(state, data)
    number = state.active_program
    assert outcome.state.image.programs[number - 1] == state.image.programs[number - 1]
    assert outcome.state.image.system == state.image.system


@pytest.mark.soak
# the soak profile's count
@settings(suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(cases(), st.booleans())
def test_every_property_holds_in_many_more_cases(case, broadcast):
    test_process_never_raises_and_replies_in_shape.hypothesis.inner_test(case, broadcast)
    for check in (test_a_broadcast_does_what_an_addressed_message_does,
                  test_only_an_accepted_write_changes_the_state,
                  test_an_accepted_write_keeps_every_invariant,
                  test_in_run_the_active_program_is_never_written):
        check.hypothesis.inner_test(case)
